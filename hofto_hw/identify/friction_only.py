"""Per-day friction refresh: re-fit only the friction of an identified model from a short run.

Viscous friction of the UR10e differs by ~25 % between recording days (temperature, wear)
while the rigid-body parameters do not change: ``refresh_friction`` keeps the link inertias
and rotor inertias of a parameters file and fits, per joint, Fc, Fv, B (+ held Fh, quadratic
Fq) to tau − (M·qdd + C·qd + g) by bounded least squares (Fc, Fv, Fh >= 0).
"""

from __future__ import annotations

import copy
import datetime as _dt
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import scipy.optimize

from hofto_hw.errors import UserError
from hofto_hw.identify.pipeline import Samples
from hofto_hw.model.friction import FEATURES, FrictionParams
from hofto_hw.model.parameters import ParametersFile, apply_parameters
from hofto_hw.model.robot import RobotModel


def refresh_friction(
    model: RobotModel,
    pf: ParametersFile,
    recordings: Sequence[Samples],
    *,
    smooth_velocity: float | None = None,
    held_velocity: float | None = None,
    quadratic: bool | None = None,
) -> ParametersFile:
    """A copy of ``pf`` whose friction is re-fitted on ``recordings`` (rigid body kept).

    Options left None keep the structure of ``pf`` (its v_s, whether it has held / quadratic
    friction and their v_h). Raises UserError when the runs hold too few moving samples.
    """
    work = model.copy()
    apply_parameters(work, pf, "parameters")
    n = work.n
    work.friction = FrictionParams.zeros(n)
    data = work.create_data()
    v_s = pf.smooth_velocity if smooth_velocity is None else smooth_velocity
    if held_velocity is None and pf.held is not None:
        held_velocity = pf.held_velocity
    if quadratic is None:
        quadratic = pf.quadratic is not None
    structure = FrictionParams.structure(n, v_s, None, held_velocity, bool(quadratic))
    names = ["coulomb", "viscous", "bias"]
    names += (["held"] if held_velocity is not None else []) + (["quadratic"] if quadratic else [])
    columns = [FEATURES.index(name) for name in names]
    cols: list[list[np.ndarray]] = [[] for _ in range(n)]
    rhs: list[list[np.ndarray]] = [[] for _ in range(n)]
    moving = 0
    for rec in recordings:
        tau_rigid = np.empty_like(rec.tau)
        for k in range(tau_rigid.shape[0]):
            data.inverse_dynamics(rec.q[k], rec.qd[k], rec.qdd[k], out=tau_rigid[k])
        phi = structure.features(rec.qd)[:, :, columns]  # eq. (12)'s terms, held from 0
        moving += int(np.sum(np.abs(rec.qd).max(axis=1) > 0.05))
        for j in range(n):
            cols[j].append(np.ascontiguousarray(phi[:, j]))  # the solver sees C order
            rhs[j].append(rec.tau[:, j] - tau_rigid[:, j])
    if moving < 50:
        raise UserError(
            f"identify --friction-only: only {moving} moving samples (|qd| > 0.05 rad/s); "
            "the run must move every joint"
        )
    k = len(names)
    lower = np.full(k, -np.inf)
    lower[[0, 1]] = 0.0
    if held_velocity is not None:
        lower[3] = 0.0
    x = np.zeros((n, k))
    for j in range(n):
        A, b = np.vstack(cols[j]), np.concatenate(rhs[j])
        x[j] = scipy.optimize.lsq_linear(A, b, bounds=(lower, np.inf)).x
    out = copy.deepcopy(pf)
    out.coulomb, out.viscous, out.bias = x[:, 0].copy(), x[:, 1].copy(), x[:, 2].copy()
    out.smooth_velocity = v_s
    out.stribeck_static = out.stribeck_velocity = None
    out.held = x[:, 3].copy() if held_velocity is not None else None
    out.held_velocity = held_velocity if held_velocity is not None else pf.held_velocity
    out.quadratic = x[:, -1].copy() if quadratic else None
    out.created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out.method = f"{pf.method}+friction-only"
    out.sources = list(pf.sources) + [f"friction: {Path(r.source).name}" for r in recordings]
    out.fit = dict(pf.fit, friction_refresh_samples=int(sum(r.q.shape[0] for r in recordings)))
    return out
