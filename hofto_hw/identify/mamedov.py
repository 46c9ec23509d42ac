"""Read the UR10e dataset authors' identified parameters (Mamedov et al., 2020) into our
parameters-file form, so ``hofto-hw validate --compare`` can put both models side by side.

Their ordering (github.com/shamilmamedov/dynamic_calibration, energy-based regressor and
``frictionRegressor``): per link ``[Ixx, Ixy, Ixz, Iyy, Iyz, Izz, mx, my, mz, m]`` with the
inertia about the link frame origin (the URDF link frame, as pinocchio's); per joint friction
``[Fv, Fc, F0]`` with a hard sign(qd); rotor inertia ``pi_drvs`` per joint; joint torque
``drvGains·current``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hofto_hw.config.loader import read_bounded
from hofto_hw.errors import UserError
from hofto_hw.model.parameters import ParametersFile, urdf_sha256

if TYPE_CHECKING:
    from hofto_hw.model.robot import RobotModel

# their link order -> pinocchio's m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz
_TO_PIN = [9, 6, 7, 8, 0, 1, 3, 2, 4, 5]


def read_authors_file(path: str | Path) -> dict[str, np.ndarray]:
    """The vectors ``drvGains``, ``pi_drvs``, ``pi_frcn``, ``pi_rgd`` of their text file."""
    raw = read_bounded(path, "parameter file", 16 << 20, UserError)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise UserError(f"{path}: not UTF-8 text, not the authors' parameter file") from None
    out = {}
    for key in ("drvGains", "pi_drvs", "pi_frcn", "pi_rgd"):
        m = re.search(rf"{key}\s*=\s*\[([^\]]*)\]", text)
        if m is None:
            raise UserError(f"{path}: no '{key} = [...]' line")
        out[key] = np.array([float(v) for v in m.group(1).split()])
    return out


def authors_parameters(model: RobotModel, path: str | Path) -> ParametersFile:
    """The authors' model of the UR10e as a :class:`ParametersFile` for ``model``."""
    v = read_authors_file(path)
    n = model.n
    if v["pi_rgd"].size != 10 * n or v["pi_frcn"].size != 3 * n or v["pi_drvs"].size != n:
        raise UserError(f"{path}: expected {10 * n} rigid, {3 * n} friction, {n} rotor values")
    links = v["pi_rgd"].reshape(n, 10)[:, _TO_PIN]
    fr = v["pi_frcn"].reshape(n, 3)
    return ParametersFile(
        robot=model.name,
        joints=list(model.joint_names),
        urdf_sha256=urdf_sha256(model.urdf_path) if model.urdf_path else "",
        inertial=links,
        rotor_inertia=v["pi_drvs"],
        coulomb=fr[:, 1].copy(),
        viscous=fr[:, 0].copy(),
        bias=fr[:, 2].copy(),
        smooth_velocity=0.0,
        urdf=Path(model.urdf_path).name if model.urdf_path else "",
        method="authors (Mamedov et al. 2020)",
        sources=[Path(path).name],
        fit={"drive_gains": v["drvGains"]},
    )
