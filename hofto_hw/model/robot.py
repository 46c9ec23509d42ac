"""RobotModel: the arm's rigid-body dynamics (pinocchio underneath) plus rotor inertia and friction.

Equation (1) of the paper, joint side, SI units:

    M(q)·qdd + C(q, qd)·qd + g(q) + f(qd) = tau + tau_ext

``M`` includes the reflected rotor inertia on its diagonal (pinocchio's ``armature``).
``C`` is the Christoffel-consistent Coriolis matrix, so Mdot = C + Cᵀ (used by the momentum
observer). Every method returns a view of a preallocated buffer that stays valid until the
same method is called again, or writes into ``out=``; none allocates (the Jacobian and pose
helpers excepted, see their docstrings).

The identified model is data: :meth:`set_inertial_parameters`, :attr:`rotor_inertia` and
:attr:`friction` take identified values (see ``hofto_hw.model.parameters``); the URDF gives
kinematics and the nominal values.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from hofto_hw.config.models import RobotConfig
from hofto_hw.errors import ModelError
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
        self.pin_data = pin_model.createData()
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
        self._M = np.zeros((n, n))
        self._Mt = np.zeros((n, n))
        self._lower = np.tril(np.ones((n, n), dtype=bool), -1)
        self._C = np.zeros((n, n))
        self._Cqd = np.zeros(n)
        self._g = np.zeros(n)
        self._nle = np.zeros(n)
        self._f = np.zeros(n)
        self._tau_id = np.zeros(n)
        self._qdd = np.zeros(n)
        self._tau_total = np.zeros(n)

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
        return robot

    def copy(self) -> RobotModel:
        """An independent copy (own pinocchio model, data and buffers)."""
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

    # ------------------------------------------------------------------ dynamics

    def mass_matrix(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """M(q) [kg·m²], symmetric, shape (n, n), rotor inertia included."""
        pin.crba(self.pin_model, self.pin_data, q)
        M = self._M if out is None else out
        np.copyto(M, self.pin_data.M)
        np.copyto(self._Mt, M.T)
        np.copyto(M, self._Mt, where=self._lower)
        return M

    def coriolis_matrix(
        self, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """C(q, qd) [N·m·s/rad], shape (n, n), with Mdot = C + Cᵀ."""
        C = self._C if out is None else out
        np.copyto(C, pin.computeCoriolisMatrix(self.pin_model, self.pin_data, q, qd))
        return C

    def gravity(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """g(q) [N·m], shape (n,)."""
        g = self._g if out is None else out
        np.copyto(g, pin.computeGeneralizedGravity(self.pin_model, self.pin_data, q))
        return g

    def nonlinear_effects(
        self, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """C(q, qd)·qd + g(q) [N·m], shape (n,)."""
        h = self._nle if out is None else out
        np.copyto(h, pin.nonLinearEffects(self.pin_model, self.pin_data, q, qd))
        return h

    def coriolis(self, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """C(q, qd)·qd [N·m], shape (n,)."""
        c = self._Cqd if out is None else out
        h = pin.nonLinearEffects(self.pin_model, self.pin_data, q, qd)
        g = pin.computeGeneralizedGravity(self.pin_model, self.pin_data, q)
        np.subtract(h, g, out=c)
        return c

    def friction_torque(self, qd: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """f(qd) [N·m], shape (n,), eq. (12)."""
        return self.friction.torque(qd, self._f if out is None else out)

    def inverse_dynamics(
        self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """M·qdd + C·qd + g + f [N·m]: the motor torque that produces qdd with no contact."""
        tau = self._tau_id if out is None else out
        np.copyto(tau, pin.rnea(self.pin_model, self.pin_data, q, qd, qdd))
        np.add(tau, self.friction.torque(qd, self._f), out=tau)
        return tau

    def forward_dynamics(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        tau_ext: np.ndarray | None = None,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """qdd [rad/s²] = M⁻¹·(tau + tau_ext - C·qd - g - f), shape (n,) (ABA)."""
        total = self._tau_total
        np.subtract(tau, self.friction.torque(qd, self._f), out=total)
        if tau_ext is not None:
            np.add(total, tau_ext, out=total)
        qdd = self._qdd if out is None else out
        np.copyto(qdd, pin.aba(self.pin_model, self.pin_data, q, qd, total))
        return qdd

    # ------------------------------------------------------------------ kinematics

    def tool_jacobian(self, q: np.ndarray) -> np.ndarray:
        """Geometric Jacobian of the tool frame, shape (6, n), rows (v_x, v_y, v_z, w_x, w_y,
        w_z) in the world-aligned frame at the tool origin [m/rad, 1]. Allocates (pinocchio
        returns a new array)."""
        return pin.computeFrameJacobian(
            self.pin_model,
            self.pin_data,
            q,
            self.tool_frame_id,
            pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        )

    def frame_jacobian(self, q: np.ndarray, frame: str) -> np.ndarray:
        """Like :meth:`tool_jacobian` for any URDF frame; shape (6, n). Allocates."""
        if not self.pin_model.existFrame(frame):
            raise ModelError(f"{self.name}: frame {frame!r} is not in the URDF")
        return pin.computeFrameJacobian(
            self.pin_model,
            self.pin_data,
            q,
            self.pin_model.getFrameId(frame),
            pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        )

    def frame_position(self, q: np.ndarray, frame: str | None = None) -> np.ndarray:
        """World position [m] of ``frame`` (default: the tool), shape (3,). Allocates."""
        fid = self.tool_frame_id if frame is None else self.pin_model.getFrameId(frame)
        pin.forwardKinematics(self.pin_model, self.pin_data, q)
        return pin.updateFramePlacement(self.pin_model, self.pin_data, fid).translation.copy()

    def tool_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tool position [m], shape (3,), and rotation matrix, shape (3, 3). Allocates."""
        pin.forwardKinematics(self.pin_model, self.pin_data, q)
        placement = pin.updateFramePlacement(self.pin_model, self.pin_data, self.tool_frame_id)
        return placement.translation.copy(), placement.rotation.copy()


def _urdf_limits(model: pin.Model) -> JointLimits:
    n = model.nv
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    vel = np.array(model.velocityLimit, dtype=float)
    eff = np.array(model.effortLimit, dtype=float)
    vel[vel <= 0] = np.inf
    eff[eff <= 0] = np.inf
    return JointLimits(lower, upper, vel, np.full(n, np.inf), eff)
