"""The identified-parameters file: written by ``hofto-hw identify``, read by RobotModel.

Format (YAML, UTF-8; ``version`` 1). All values SI at the joint side.

.. code-block:: yaml

    format: hofto-hw/parameters
    version: 1
    robot: ur10e                 # must equal robot.name of the config that loads it
    urdf: ur10e.urdf             # file name, informational
    urdf_sha256: 3f9a...         # sha256 of the URDF bytes; a different URDF is refused
    joints: [shoulder_pan_joint, ...]         # n names, kinematic order
    gravity: [0.0, 0.0, -9.81]   # [m/s²] used during identification
    created: '2026-11-21T10:00:00+00:00'
    method: consistent           # ols | wls | consistent (physically consistent SDP)
    sources: [ur-20_02_10-30sec_12harm.csv]   # recordings it was fitted on
    model:                       # what the loop runs on (pinocchio + rotor + friction)
      inertial:                  # n rows of 10: m [kg], mx, my, mz [kg·m], Ixx, Ixy,
        - [m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]  # Iyy, Ixz, Iyz, Izz [kg·m²]
      rotor_inertia: [...]       # n values [kg·m²]
      friction:
        coulomb: [...]           # Fc [N·m]
        viscous: [...]           # Fv [N·m·s/rad]
        bias: [...]              # B [N·m]
        smooth_velocity: 0.02    # v_s [rad/s]: sign(qd) ~ tanh(qd / v_s); 0 = hard sign
        stribeck_static: [...]   # optional: Fs [N·m] (>= Fc), adds (Fs-Fc)·exp(-(qd/vs)²)·s(qd)
        stribeck_velocity: [...] # optional, with stribeck_static: vs [rad/s]
        held: [...]              # optional: Fh [N·m], friction with memory (model/friction.py)
        held_velocity: 0.005     # with held: band v_h [rad/s]
        held_passive: false      # optional: held term zero while qd·h < 0 (simulation form)
        quadratic: [...]         # optional: Fq [N·m·s²/rad²], adds Fq·qd·|qd|
    base:                        # eq. (14): mu = K·theta_s (the model above reproduces mu)
      count: 58
      parameters:
        - name: shoulder_pan_joint.Izz     # the standard parameter it is built on
          value: 1.23                      # identified mu_i (from the chosen method)
          std: 0.01                        # standard deviation (OLS/WLS), null if unknown
          relative_std_percent: 0.8
          definition: {shoulder_pan_joint.Izz: 1.0, shoulder_lift_joint.m: 0.031, ...}
    drive_gains:                 # optional: current -> joint torque [N·m/A] the model is on
      values: [...]              # replaces a current column map's current_to_torque wherever
      std: [...]                 # recordings are read for this model (replay, payload, tune)
      calibrated: [true, ...]    # per joint: calibrated with a known load, else as configured
      configured: [...]          # the column map's gains they replace
      known_loads: [{file: run.csv, mass: 2.805}]
    fit:                         # statistics on the identification data
      samples: 5000
      condition_number: 85.2
      rmse: [...]                # per joint [N·m]
      relative_rmse_percent: [...]   # 100·||e_j|| / ||tau_j||
      residual_std: [...]        # per joint [N·m] (WLS weights)

Standard parameter names are ``<joint>.<p>`` with p in m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz,
Izz, Ia, Fc, Fv, B and, with Stribeck friction, S = Fs − Fc, with held friction H = Fh, with
quadratic friction Q = Fq (see
``hofto_hw.identify.regressor``).

:func:`apply_parameters_file` checks robot name, joint names and URDF hash, sets the link
inertial parameters, rotor inertia and friction, and refuses (restoring the previous values) a
model whose M(q) is not symmetric positive definite over a sample of the workspace.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hofto_hw.config.loader import dump_yaml, excerpt, read_yaml
from hofto_hw.errors import ModelError
from hofto_hw.model.friction import FrictionParams
from hofto_hw.outputs import write_atomic

if TYPE_CHECKING:
    from hofto_hw.model.robot import RobotModel

FORMAT = "hofto-hw/parameters"
VERSION = 1
N_INERTIAL = 10


@dataclass
class BaseParameterEntry:
    """One base parameter: its name, value, std (None if unknown) and definition."""

    name: str
    value: float
    std: float | None
    definition: dict[str, float]

    @property
    def relative_std_percent(self) -> float | None:
        if self.std is None or self.value == 0.0:
            return None
        return 100.0 * self.std / abs(self.value)


@dataclass
class ParametersFile:
    """In-memory form of the file; arrays: inertial (n, 10), the rest (n,)."""

    robot: str
    joints: list[str]
    urdf_sha256: str
    inertial: np.ndarray
    rotor_inertia: np.ndarray
    coulomb: np.ndarray
    viscous: np.ndarray
    bias: np.ndarray
    smooth_velocity: float = 0.0
    stribeck_static: np.ndarray | None = None
    stribeck_velocity: np.ndarray | None = None
    held: np.ndarray | None = None
    held_velocity: float = 0.005
    quadratic: np.ndarray | None = None
    held_passive: bool = False
    urdf: str = ""
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    created: str = ""
    method: str = ""
    sources: list[str] = field(default_factory=list)
    base: list[BaseParameterEntry] = field(default_factory=list)
    fit: dict[str, Any] = field(default_factory=dict)
    drive_gains: np.ndarray | None = None
    drive_gains_info: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.joints)

    def friction(self) -> FrictionParams:
        """The friction model (with the Stribeck term when the file has one); its own copies
        of the arrays (FrictionParams copies what it is given)."""
        stribeck = (self.stribeck_static, self.stribeck_velocity)
        return FrictionParams(
            self.coulomb,
            self.viscous,
            self.bias,
            *stribeck,
            self.smooth_velocity,
            held=self.held,
            held_velocity=self.held_velocity,
            quadratic=self.quadratic,
            held_passive=self.held_passive,
        )

    def base_values(self) -> np.ndarray:
        """The identified base parameters mu, shape (p,)."""
        return np.array([b.value for b in self.base], dtype=float)


def urdf_sha256(path: str | Path) -> str:
    """sha256 (hex) of a URDF file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _floats(values: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=float).reshape(-1)]


def to_dict(pf: ParametersFile) -> dict[str, Any]:
    """The YAML mapping of ``pf`` (plain Python types)."""
    base = []
    for b in pf.base:
        rel = b.relative_std_percent
        base.append(
            {
                "name": b.name,
                "value": float(b.value),
                "std": None if b.std is None else float(b.std),
                "relative_std_percent": None if rel is None else float(rel),
                "definition": {k: float(v) for k, v in b.definition.items()},
            }
        )
    friction: dict[str, Any] = {
        "coulomb": _floats(pf.coulomb),
        "viscous": _floats(pf.viscous),
        "bias": _floats(pf.bias),
        "smooth_velocity": float(pf.smooth_velocity),
    }
    if pf.stribeck_static is not None and pf.stribeck_velocity is not None:
        friction["stribeck_static"] = _floats(pf.stribeck_static)
        friction["stribeck_velocity"] = _floats(pf.stribeck_velocity)
    if pf.held is not None:
        friction["held"] = _floats(pf.held)
        friction["held_velocity"] = float(pf.held_velocity)
        if pf.held_passive:
            friction["held_passive"] = True
    if pf.quadratic is not None:
        friction["quadratic"] = _floats(pf.quadratic)
    return {
        "format": FORMAT,
        "version": VERSION,
        "robot": pf.robot,
        "urdf": pf.urdf,
        "urdf_sha256": pf.urdf_sha256,
        "joints": list(pf.joints),
        "gravity": [float(g) for g in pf.gravity],
        "created": pf.created,
        "method": pf.method,
        "sources": list(pf.sources),
        "model": {
            "inertial": [_floats(row) for row in pf.inertial],
            "rotor_inertia": _floats(pf.rotor_inertia),
            "friction": friction,
        },
        "base": {"count": len(base), "parameters": base},
        **(
            {"drive_gains": {"values": _floats(pf.drive_gains), **_plain(pf.drive_gains_info)}}
            if pf.drive_gains is not None
            else {}
        ),
        "fit": _plain(pf.fit),
    }


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.floating | np.integer):
        return obj.item()
    return obj


def write_parameters(path: str | Path, pf: ParametersFile) -> None:
    """Write ``pf`` as YAML to ``path`` (atomically; UserError naming the file on failure)."""
    text = "# Identified dynamic parameters; format: hofto_hw/model/parameters.py\n"
    text += dump_yaml(to_dict(pf), sort_keys=False, default_flow_style=None, width=100)
    write_atomic(path, text, "parameters file")


class _Reader:
    """Pulls typed fields out of the parsed mapping with errors that name file and field."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, msg: str) -> ModelError:
        return ModelError(f"{self.source}: {where}: {msg}")

    def get(self, d: Any, key: str, where: str) -> Any:
        if not isinstance(d, dict) or key not in d:
            return self._missing(f"{where}{key}")
        return d[key]

    def _missing(self, where: str) -> Any:
        raise self.fail(where, "missing")

    def number(self, value: Any, where: str) -> float:
        """``value`` as a finite float, or ModelError naming ``where`` and the value."""
        return float(self.array(value, where, ()))

    def array(self, value: Any, where: str, shape: tuple[int, ...]) -> np.ndarray:
        try:
            arr = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise self.fail(where, f"expected numbers, got {value!r:.60}") from None
        if arr.shape != shape:
            raise self.fail(where, f"expected shape {shape}, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise self.fail(where, f"contains NaN or inf (got {value!r:.60})")
        return arr


def read_parameters(path: str | Path) -> ParametersFile:
    """Read and check a parameters file. Raises ModelError naming the file and field."""
    path = Path(path)
    src = str(path)
    data = read_yaml(path, "parameters file", ModelError)
    r = _Reader(src)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ModelError(f"{src}: not a hofto-hw parameters file (format: {FORMAT} missing)")
    version = data.get("version")
    if version != VERSION:
        raise ModelError(
            f"{src}: version: {excerpt(version, 40)} is not supported (expected {VERSION})"
        )
    joints = r.get(data, "joints", "")
    if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
        raise r.fail("joints", "expected a list of joint names")
    n = len(joints)
    model = r.get(data, "model", "")
    fr = r.get(model, "friction", "model.")
    gravity = r.array(data.get("gravity", [0.0, 0.0, -9.81]), "gravity", (3,))
    base_entries = []
    base = data.get("base") or {}
    for i, b in enumerate(base.get("parameters") or []):
        where = f"base.parameters[{i}]"
        if not isinstance(b, dict) or "name" not in b or "value" not in b:
            raise r.fail(where, "expected a mapping with name and value")
        definition = b.get("definition") or {}
        if not isinstance(definition, dict):
            raise r.fail(f"{where}.definition", "expected a mapping name -> coefficient")
        std = b.get("std")
        base_entries.append(
            BaseParameterEntry(
                str(b["name"]),
                r.number(b["value"], f"{where}.value"),
                None if std is None else r.number(std, f"{where}.std"),
                {str(k): r.number(v, f"{where}.definition.{k}") for k, v in definition.items()},
            )
        )
    if ("stribeck_static" in fr) != ("stribeck_velocity" in fr):
        raise r.fail("model.friction", "give both stribeck_static and stribeck_velocity")
    stribeck = (
        (
            r.array(fr["stribeck_static"], "model.friction.stribeck_static", (n,)),
            r.array(fr["stribeck_velocity"], "model.friction.stribeck_velocity", (n,)),
        )
        if "stribeck_static" in fr
        else (None, None)
    )
    if stribeck[1] is not None and np.any(stribeck[1] <= 0.0):
        raise r.fail("model.friction.stribeck_velocity", "values must be > 0 [rad/s]")
    held = r.array(fr["held"], "model.friction.held", (n,)) if "held" in fr else None
    held_velocity = r.number(fr.get("held_velocity", 0.005), "model.friction.held_velocity")
    if held_velocity <= 0.0:
        raise r.fail("model.friction.held_velocity", f"must be > 0 [rad/s], got {held_velocity}")
    quadratic = (
        r.array(fr["quadratic"], "model.friction.quadratic", (n,)) if "quadratic" in fr else None
    )
    gains, gains_info = None, {}
    if data.get("drive_gains") is not None:
        block = data["drive_gains"]
        if not isinstance(block, dict) or "values" not in block:
            raise r.fail("drive_gains", "expected a mapping with values: [n gains N·m/A]")
        gains = r.array(block["values"], "drive_gains.values", (n,))
        if np.any(gains <= 0.0):
            raise r.fail("drive_gains.values", f"gains must be > 0 N·m/A, got {gains.tolist()}")
        gains_info = {k: v for k, v in block.items() if k != "values"}
    robot = r.get(data, "robot", "")
    sha = r.get(data, "urdf_sha256", "")
    smooth_velocity = r.number(fr.get("smooth_velocity") or 0.0, "model.friction.smooth_velocity")
    pf = ParametersFile(
        robot=str(robot),
        joints=[str(j) for j in joints],
        urdf_sha256=str(sha),
        inertial=r.array(r.get(model, "inertial", "model."), "model.inertial", (n, N_INERTIAL)),
        rotor_inertia=r.array(r.get(model, "rotor_inertia", "model."), "model.rotor_inertia", (n,)),
        coulomb=r.array(r.get(fr, "coulomb", "model.friction."), "model.friction.coulomb", (n,)),
        viscous=r.array(r.get(fr, "viscous", "model.friction."), "model.friction.viscous", (n,)),
        bias=r.array(r.get(fr, "bias", "model.friction."), "model.friction.bias", (n,)),
        smooth_velocity=smooth_velocity,
        stribeck_static=stribeck[0],
        stribeck_velocity=stribeck[1],
        held=held,
        held_velocity=held_velocity,
        quadratic=quadratic,
        held_passive=bool(fr.get("held_passive", False)),
        urdf=str(data.get("urdf", "")),
        gravity=(float(gravity[0]), float(gravity[1]), float(gravity[2])),
        created=str(data.get("created", "")),
        method=str(data.get("method", "")),
        sources=[str(s) for s in data.get("sources") or []],
        base=base_entries,
        fit=dict(data.get("fit") or {}),
        drive_gains=gains,
        drive_gains_info=gains_info,
    )
    check_physical(pf, src)
    return pf


#: (field, unit) of the values that must not be negative in a physical model
NON_NEGATIVE = (
    ("model.rotor_inertia", "kg·m²"),
    ("model.friction.coulomb", "N·m"),
    ("model.friction.viscous", "N·m·s/rad"),
)


def check_physical(pf: ParametersFile, source: str) -> None:
    """Raise ModelError naming file, field, joint and value for a non-physical value: a
    negative link mass, rotor inertia, Coulomb or viscous friction (friction that feeds
    energy in), a negative smoothing velocity, or a Stribeck static friction below Coulomb."""
    values = {
        "model.rotor_inertia": pf.rotor_inertia,
        "model.friction.coulomb": pf.coulomb,
        "model.friction.viscous": pf.viscous,
    }
    checks = [(f, u, values[f]) for f, u in NON_NEGATIVE]
    checks.append(("model.inertial[:, 0] (link mass)", "kg", pf.inertial[:, 0]))
    for where, unit, arr in checks:
        bad = np.flatnonzero(np.asarray(arr) < 0.0)
        if bad.size:
            j = int(bad[0])
            raise ModelError(
                f"{source}: {where}: joint {j + 1} ({pf.joints[j]}): {float(arr[j]):.6g} {unit} "
                "is negative, which is not physical (identify with --method consistent)"
            )
    if not (math.isfinite(pf.smooth_velocity) and pf.smooth_velocity >= 0.0):
        raise ModelError(
            f"{source}: model.friction.smooth_velocity: {pf.smooth_velocity!r} must be a "
            "finite number >= 0 [rad/s]"
        )
    if pf.stribeck_static is not None:
        bad = np.flatnonzero(pf.stribeck_static < pf.coulomb)
        if bad.size:
            j = int(bad[0])
            raise ModelError(
                f"{source}: model.friction.stribeck_static: joint {j + 1} ({pf.joints[j]}): "
                f"{float(pf.stribeck_static[j]):.6g} N·m is below the Coulomb friction "
                f"{float(pf.coulomb[j]):.6g} N·m (Fs >= Fc)"
            )


def workspace_samples(model: RobotModel, n_samples: int, seed: int = 0) -> np.ndarray:
    """Random configurations inside the joint limits (infinite limits -> ±pi), (N, n) [rad]."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(np.asarray(model.limits.position_lower, dtype=float), -np.pi)
    hi = np.minimum(np.asarray(model.limits.position_upper, dtype=float), np.pi)
    bad = ~(hi > lo)
    lo[bad], hi[bad] = -np.pi, np.pi
    return rng.uniform(lo, hi, (n_samples, model.n))


def check_mass_matrix(model: RobotModel, n_samples: int = 200, seed: int = 0) -> None:
    """Raise ModelError unless M(q) is symmetric positive definite at ``n_samples`` random
    configurations of the workspace."""
    data = model.create_data()
    for q in workspace_samples(model, n_samples, seed):
        M = np.array(data.mass_matrix(q))
        if not np.all(np.isfinite(M)) or not np.allclose(M, M.T, rtol=1e-9, atol=1e-12):
            raise ModelError(f"{model.name}: M(q) is not symmetric at q = {np.round(q, 3)}")
        eig = np.linalg.eigvalsh(M)
        if eig[0] <= 1e-9 * max(eig[-1], 1e-12):
            raise ModelError(
                f"{model.name}: M(q) is not positive definite at q = {np.round(q, 3).tolist()} "
                f"(smallest eigenvalue {eig[0]:.3g}); the parameters are not physical"
            )


def check_compatible(pf: ParametersFile, model: RobotModel, source: str) -> None:
    """Raise ModelError if ``pf`` was identified for another robot, joint set or URDF."""
    if pf.robot != model.name:
        raise ModelError(
            f"{source}: parameters are for robot {excerpt(pf.robot, 60)}, but the model is "
            f"{model.name!r}"
        )
    if list(pf.joints) != list(model.joint_names):
        raise ModelError(
            f"{source}: joints {pf.joints} do not match the model's {model.joint_names}"
        )
    urdf_path = getattr(model, "urdf_path", None)
    if urdf_path is not None and pf.urdf_sha256:
        actual = urdf_sha256(urdf_path)
        if actual != pf.urdf_sha256:
            raise ModelError(
                f"{source}: identified for a different URDF (urdf_sha256 {pf.urdf_sha256[:12]}…, "
                f"but {Path(urdf_path).name} hashes to {actual[:12]}…); re-identify for this URDF"
            )


def apply_parameters(model: RobotModel, pf: ParametersFile, source: str = "<parameters>") -> None:
    """Put ``pf`` into ``model`` (a RobotModel); on a failed M(q) check restore the old values."""
    check_compatible(pf, model, source)
    check_physical(pf, source)
    old = (model.inertial_parameters(), model.rotor_inertia, model.friction)
    try:
        model.set_inertial_parameters(pf.inertial.reshape(-1))
        payload = getattr(model, "payload", None)
        if payload is not None:  # the arm's links come from the file, the load stays on
            from hofto_hw.model.payload import apply_payload

            apply_payload(model, payload)
        model.rotor_inertia = pf.rotor_inertia
        model.friction = pf.friction()
        check_mass_matrix(model)
    except ModelError as exc:
        model.set_inertial_parameters(old[0])
        model.rotor_inertia = old[1]
        model.friction = old[2]
        raise ModelError(f"{source}: {exc}") from None


def apply_parameters_file(model: RobotModel, path: str | Path) -> ParametersFile:
    """Read ``path`` and apply it to ``model``; returns the file's content."""
    pf = read_parameters(path)
    apply_parameters(model, pf, str(path))
    return pf
