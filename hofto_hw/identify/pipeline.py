"""From conditioned recordings to a parameters file: regressor, base set, fit, standard set.

``identify(model, recordings, method)``:
1. H_s per sample (regressor.py), base set from random samples (base_params.py);
2. OLS, then WLS with per-joint weights (estimate.py): the reported std devs;
3. ``method``: ``ols`` / ``wls`` keep that estimate, the standard set reproducing it takes
   the URDF values for the unidentifiable parameters; ``consistent`` fits a physically
   consistent standard set (consistent.py) through the WLS factor;
4. a :class:`ParametersFile` with the standard set, the base definition and fit statistics.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hofto_hw.errors import UserError
from hofto_hw.identify.base_params import BaseParameters, find_base_parameters
from hofto_hw.identify.consistent import consistent_fit
from hofto_hw.identify.estimate import Accumulator, Estimate, least_squares
from hofto_hw.identify.regressor import Regressor, split_optional, standard_parameters
from hofto_hw.identify.threads import one_blas_thread
from hofto_hw.model.parameters import BaseParameterEntry, ParametersFile, urdf_sha256

if TYPE_CHECKING:
    from hofto_hw.model.robot import RobotModel

METHODS = ("ols", "wls", "consistent")


@dataclass
class Samples:
    """Conditioned samples of one recording: q, qd, qdd [rad, rad/s, rad/s²], tau [N·m],
    each (N, n); ``source`` names where they came from."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    source: str = ""


@dataclass
class Identification:
    """What :func:`identify` found: the file content plus the estimates behind it."""

    parameters: ParametersFile
    base: BaseParameters
    ols: Estimate
    wls: Estimate
    theta: np.ndarray  # the standard set (14·n,) the model runs on
    mu: np.ndarray  # base parameters of that set (p,)


def nominal_theta(
    model: RobotModel, stribeck: bool = False, held: bool = False, quadratic: bool = False
) -> np.ndarray:
    """The model's current standard parameters (14·n,; +n per optional block): URDF links,
    rotor, friction (Stribeck gap Fs − Fc, held Fh, quadratic Fq; 0 when the model has none)."""
    f = model.friction
    n = model.n
    gap = None
    if stribeck:
        gap = np.zeros(n) if f.stribeck_static is None else f.stribeck_static - f.coulomb
    theta = standard_parameters(
        model.inertial_parameters(), model.rotor_inertia, f.coulomb, f.viscous, f.bias, gap
    )
    if held:
        theta = np.concatenate([theta, np.zeros(n) if f.held is None else f.held])
    if quadratic:
        theta = np.concatenate([theta, np.zeros(n) if f.quadratic is None else f.quadratic])
    return theta


@one_blas_thread
def identify(
    model: RobotModel,
    recordings: Sequence[Samples],
    method: str = "consistent",
    smooth_velocity: float = 0.02,
    progress: Callable[[str], None] | None = None,
    stribeck_velocity: np.ndarray | None = None,
    held_velocity: float | None = None,
    quadratic: bool = False,
    held_passive: bool = False,
) -> Identification:
    """Identify ``model``'s parameters from ``recordings`` (see the module docstring).

    ``smooth_velocity`` [rad/s]: tanh width of the Coulomb sign; ``stribeck_velocity`` (n,)
    [rad/s]: identify a Stribeck gap Fs − Fc with these fixed Stribeck velocities;
    ``held_velocity`` v_h [rad/s]: identify held friction (memory at rest) with this band;
    ``quadratic``: identify Fq of Fq·qd·|qd|; ``held_passive``: the passive held term of the
    simulated plant (see ``hofto_hw.model.friction``; the real UR10e fits the default better).
    """
    if method not in METHODS:
        raise UserError(f"identify: --method must be one of {', '.join(METHODS)}, got {method!r}")
    if not recordings:
        raise UserError("identify: no recordings given")
    say = progress or (lambda _msg: None)
    n = model.n
    reg = Regressor(
        model.pin_model, smooth_velocity, stribeck_velocity, held_velocity, quadratic, held_passive
    )
    stribeck = reg.stribeck_velocity is not None
    held = reg.held_velocity is not None
    base = find_base_parameters(reg, model.joint_names)
    say(f"{base.p} base parameters out of {reg.n_std} standard ones")
    acc = Accumulator(reg, base)
    for rec in recordings:
        if rec.q.shape[1] != n:
            raise UserError(
                f"{rec.source}: {rec.q.shape[1]} joints, the model {model.name} has {n}"
            )
        acc.add(rec.q, rec.qd, rec.qdd, rec.tau)
        say(f"{rec.source}: {rec.q.shape[0]} samples")
    ols = least_squares(acc)
    wls = least_squares(acc, weighted=True)
    say(f"least squares done (condition number {ols.condition_number:.4g})")
    prior = nominal_theta(model, stribeck, held, reg.quadratic)
    if method == "consistent":
        w = 1.0 / np.maximum(ols.residual_std, 1e-9)
        theta = consistent_fit(acc.combined(w), base, prior, n)
        say("physically consistent fit done")
    else:
        chosen = ols if method == "ols" else wls
        theta = base.to_standard(chosen.mu, prior)
    mu = base.from_standard(theta)
    res = acc.joint_residuals(mu)
    N = acc.samples
    fit = {
        "samples": N,
        "condition_number": ols.condition_number,
        "rmse": res / np.sqrt(N),
        "relative_rmse_percent": 100.0 * res / np.sqrt(np.maximum(acc.tau_sq, 1e-300)),
        "residual_std": wls.residual_std,
        "ols_rmse": ols.rmse,
    }
    parts = split_optional(theta, n, reg.optional)
    entries = [
        BaseParameterEntry(
            base.names[i],
            float(mu[i]),
            float(wls.std[i]),
            {nm: c for nm, c in base.expressions()[i]},
        )
        for i in range(base.p)
    ]
    urdf = Path(model.urdf_path) if model.urdf_path is not None else None
    pf = ParametersFile(
        robot=model.name,
        joints=list(model.joint_names),
        urdf_sha256=urdf_sha256(urdf) if urdf is not None else "",
        inertial=parts["inertial"].reshape(n, -1),
        rotor_inertia=parts["rotor_inertia"],
        coulomb=parts["coulomb"],
        viscous=parts["viscous"],
        bias=parts["bias"],
        smooth_velocity=smooth_velocity,
        stribeck_static=parts["coulomb"] + parts["stribeck_gap"] if stribeck else None,
        stribeck_velocity=reg.stribeck_velocity.copy() if stribeck else None,  # type: ignore[union-attr]
        held=parts.get("held"),
        held_velocity=reg.held_velocity if held else 0.005,  # type: ignore[arg-type]
        quadratic=parts.get("quadratic"),
        held_passive=held_passive,
        urdf=urdf.name if urdf is not None else "",
        gravity=tuple(float(g) for g in model.pin_model.gravity.linear),  # type: ignore[arg-type]
        created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        method=method,
        sources=[Path(r.source).name for r in recordings],
        base=entries,
        fit=fit,
    )
    return Identification(pf, base, ols, wls, theta, mu)
