"""RobotModel: the arm's constant parameters (pinocchio Model, rotor inertia, friction, limits).

Equation (1) of the paper, joint side, SI units:

    M(q)·qdd + C(q, qd)·qd + g(q) + f(qd) = tau + tau_ext

``M`` includes the reflected rotor inertia on its diagonal (pinocchio's ``armature``).
``C`` is the Christoffel-consistent Coriolis matrix, so Mdot = C + Cᵀ (used by the momentum
observer). As pinocchio's Model/Data: the model holds no buffers; each consumer evaluates the
dynamics on its own workspace, ``data = model.create_data()`` (:class:`ModelData`).

The identified model is data: :meth:`set_inertial_parameters`, :attr:`rotor_inertia` and
:attr:`friction` take identified values (see ``hofto_hw.model.parameters``); the URDF gives
kinematics and the nominal values.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from hofto_hw.config.models import RobotConfig
from hofto_hw.errors import ModelError
from hofto_hw.model.data import ModelData
from hofto_hw.model.friction import FrictionParams

N_INERTIAL = (
    10  # pinocchio dynamic parameters per link: m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz
)


@dataclass
class JointLimits:
    """Per-joint limits, arrays of shape (n,): rad, rad/s, rad/s², N·m (inf = none given)."""

    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    torque: np.ndarray


class RobotModel:
    """Dynamics of an n-joint serial arm with revolute joints.

    Build with :meth:`from_config` or :meth:`from_urdf`. Arrays are float64, shape (n,) or
    (n, n); q [rad], qd [rad/s], qdd [rad/s²], torques [N·m].
    """

    def __init__(
        self,
        pin_model: pin.Model,
        joint_names: list[str],
        tool_frame: str,
        friction: FrictionParams | None = None,
        name: str = "robot",
        urdf_path: Path | None = None,
        limits: JointLimits | None = None,
        base_frame: str | None = None,
    ) -> None:
        if pin_model.nq != pin_model.nv:
            raise ModelError(
                f"{name}: only revolute/prismatic joints are supported (nq={pin_model.nq}, "
                f"nv={pin_model.nv}); declare continuous joints as revolute with limits"
            )
        self.name = name
        self.urdf_path = urdf_path
        self.pin_model = pin_model
        self.joint_names = list(joint_names)
        self.n = pin_model.nv
        if not pin_model.existFrame(tool_frame):
            raise ModelError(f"{name}: robot.tool_frame: frame {tool_frame!r} is not in the URDF")
        self.tool_frame = tool_frame
        self.tool_frame_id = pin_model.getFrameId(tool_frame)
        self.base_frame = base_frame
        self.friction = friction if friction is not None else FrictionParams.zeros(self.n)
        self.limits = limits if limits is not None else _urdf_limits(pin_model)
        n = self.n
        self.home = np.zeros(n)
        self.payload = None  # a Payload on the tool link (hofto_hw.model.payload), if any
        #: counts the parameter changes made through this class (and ``apply_payload``):
        #: native workspaces (hofto_hw.model.native) copy pinocchio's numbers and follow it
        self.revision = 0

    def mark_changed(self) -> None:
        """Say that ``pin_model``'s parameters were written directly (not through the setters
        here): workspaces that copy them (the native dynamics) copy them again."""
        self.revision += 1

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_urdf(
        cls,
        urdf: str | Path,
        joints: list[str],
        tool_frame: str,
        *,
        gravity: tuple[float, float, float] = (0.0, 0.0, -9.81),
        rotor_inertia: np.ndarray | list[float] | None = None,
        friction: FrictionParams | None = None,
        name: str | None = None,
        base_frame: str | None = None,
    ) -> RobotModel:
        """Load ``urdf``; joints not in ``joints`` are locked at zero (fixed)."""
        urdf = Path(urdf)
        if not urdf.is_file():
            raise ModelError(f"robot.urdf: file not found: {urdf}")
        try:
            full = pin.buildModelFromUrdf(str(urdf))
        except (RuntimeError, ValueError) as exc:
            raise ModelError(f"{urdf}: cannot parse URDF: {exc}") from None
        _check_link_inertias(urdf)
        present = [full.names[i] for i in range(1, full.njoints)]
        for i, j in enumerate(joints):
            if j not in present:
                raise ModelError(
                    f"robot.joints[{i}]: joint {j!r} is not in {urdf.name} "
                    f"(it has: {', '.join(present)})"
                )
        lock = [full.getJointId(j) for j in present if j not in joints]
        model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        order = [model.names[i] for i in range(1, model.njoints)]
        if order != list(joints):
            raise ModelError(
                f"robot.joints: must list the joints in kinematic order {order}, got {joints}"
            )
        model.gravity.linear = np.asarray(gravity, dtype=float)
        robot = cls(
            model,
            list(joints),
            tool_frame,
            friction=friction,
            name=name or urdf.stem,
            urdf_path=urdf,
            base_frame=base_frame,
        )
        if rotor_inertia is not None:
            robot.rotor_inertia = np.asarray(rotor_inertia, dtype=float)
        return robot

    @classmethod
    def from_config(cls, cfg: RobotConfig, *, apply_parameters: bool = True) -> RobotModel:
        """Build from a validated ``robot:`` section; applies ``cfg.parameters`` if given."""
        n = len(cfg.joints)
        robot = cls.from_urdf(
            cfg.urdf,
            cfg.joints,
            cfg.tool_frame,
            gravity=cfg.gravity,
            rotor_inertia=cfg.rotor_inertia,
            friction=FrictionParams.from_config(cfg.friction, n),
            name=cfg.name,
            base_frame=cfg.base_frame,
        )
        lim = robot.limits
        for field_name in (
            "position_lower",
            "position_upper",
            "velocity",
            "acceleration",
            "torque",
        ):
            override = getattr(cfg.limits, field_name)
            if override is not None:
                setattr(lim, field_name, np.asarray(override, dtype=float))
        robot.home = np.zeros(n) if cfg.home is None else np.asarray(cfg.home, dtype=float)
        if apply_parameters and cfg.parameters is not None:
            from hofto_hw.model.parameters import apply_parameters_file

            apply_parameters_file(robot, cfg.parameters)
        if cfg.payload is not None:
            from hofto_hw.model.payload import apply_payload, payload_from_config

            apply_payload(robot, payload_from_config(cfg.payload))
        return robot

    def copy(self) -> RobotModel:
        """An independent copy (own pinocchio model and parameters; workspaces are per caller)."""
        other = RobotModel(
            pin.Model(self.pin_model),
            self.joint_names,
            self.tool_frame,
            friction=self.friction.copy(),
            name=self.name,
            urdf_path=self.urdf_path,
            limits=JointLimits(**{k: v.copy() for k, v in vars(self.limits).items()}),
            base_frame=self.base_frame,
        )
        other.home = self.home.copy()
        other.payload = self.payload
        return other

    # ------------------------------------------------------------------ parameters

    @property
    def rotor_inertia(self) -> np.ndarray:
        """Reflected rotor inertia per joint [kg·m²], shape (n,) (a copy)."""
        return np.array(self.pin_model.armature, dtype=float)

    @rotor_inertia.setter
    def rotor_inertia(self, value: np.ndarray) -> None:
        value = np.asarray(value, dtype=float).reshape(-1)
        if value.shape != (self.n,) or np.any(value < 0) or not np.all(np.isfinite(value)):
            raise ModelError(f"{self.name}: rotor inertia must be {self.n} finite values >= 0")
        self.pin_model.armature = value.copy()
        self.revision += 1

    def inertial_parameters(self) -> np.ndarray:
        """Standard inertial parameters of all links, shape (10·n,), pinocchio order per link:
        m [kg], m·c [kg·m] (3), inertia about the joint frame origin Ixx, Ixy, Iyy, Ixz, Iyz,
        Izz [kg·m²]."""
        return np.concatenate(
            [self.pin_model.inertias[j].toDynamicParameters() for j in range(1, self.n + 1)]
        )

    def set_inertial_parameters(self, pi: np.ndarray) -> None:
        """Replace all link inertial parameters (shape (10·n,), order of
        :meth:`inertial_parameters`). Values need not be physically consistent; callers that
        load identified data check M(q) themselves (see hofto_hw.model.parameters)."""
        pi = np.asarray(pi, dtype=float).reshape(-1)
        if pi.shape != (N_INERTIAL * self.n,) or not np.all(np.isfinite(pi)):
            raise ModelError(
                f"{self.name}: expected {N_INERTIAL * self.n} finite inertial parameters, "
                f"got {pi.size}"
            )
        for j in range(self.n):
            self.pin_model.inertias[j + 1] = pin.Inertia.FromDynamicParameters(
                pi[N_INERTIAL * j : N_INERTIAL * (j + 1)]
            )
        self.revision += 1

    # ------------------------------------------------------------------ workspaces

    def create_data(
        self, backend: str = "python", hot: Mapping[str, np.ndarray] | None = None
    ) -> ModelData:
        """A new caller-owned workspace for this model's dynamics (pinocchio Data + buffers);
        ``backend`` "numba"/"auto": its inverse dynamics adds friction in one compiled call
        (:class:`~hofto_hw.model.data.ModelData`); ``hot``: its kernel workspace W given by the
        caller (``ModelData.hot_fields``)."""
        return ModelData(self, backend, hot=hot)


def _check_link_inertias(urdf: Path) -> None:
    """Refuse a link with a negative or non-finite mass or a non-physical rotational inertia
    (not positive semi-definite, or principal moments violating the triangle inequality)."""
    try:
        root = ElementTree.parse(urdf).getroot()
    except ElementTree.ParseError:
        return  # pinocchio parsed it; leave the XML details to it
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        name = link.get("name", "?")
        mass_el, inertia_el = inertial.find("mass"), inertial.find("inertia")
        try:
            mass = float(mass_el.get("value", "0")) if mass_el is not None else 0.0
            keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
            i = {k: float(inertia_el.get(k, "0")) if inertia_el is not None else 0.0 for k in keys}
        except ValueError as exc:
            raise ModelError(f"{urdf}: link {name!r}: {exc}") from None
        if not math.isfinite(mass) or mass < 0.0:
            raise ModelError(f"{urdf}: link {name!r}: mass {mass} kg must be finite and >= 0")
        inertia = np.array(
            [
                [i["ixx"], i["ixy"], i["ixz"]],
                [i["ixy"], i["iyy"], i["iyz"]],
                [i["ixz"], i["iyz"], i["izz"]],
            ]
        )
        values = ", ".join(f"{k}={i[k]:g}" for k in keys)
        if not np.all(np.isfinite(inertia)):
            raise ModelError(f"{urdf}: link {name!r}: inertia must be finite ({values})")
        moments = np.linalg.eigvalsh(inertia)
        tol = 1e-9 * max(1.0, float(np.abs(moments).max()))
        if moments[0] < -tol:
            raise ModelError(
                f"{urdf}: link {name!r}: inertia is not positive semi-definite ({values}; "
                f"principal moments {', '.join(f'{m:g}' for m in moments)} kg·m²)"
            )
        if moments[0] + moments[1] < moments[2] - tol:
            raise ModelError(
                f"{urdf}: link {name!r}: inertia violates the triangle inequality "
                f"({values}; principal moments {', '.join(f'{m:g}' for m in moments)} kg·m²: "
                "the two smaller must sum to at least the largest)"
            )


def _urdf_limits(model: pin.Model) -> JointLimits:
    n = model.nv
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    vel = np.array(model.velocityLimit, dtype=float)
    eff = np.array(model.effortLimit, dtype=float)
    vel[vel <= 0] = np.inf
    eff[eff <= 0] = np.inf
    return JointLimits(lower, upper, vel, np.full(n, np.inf), eff)
