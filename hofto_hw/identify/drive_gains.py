"""Drive torque-scale calibration with a known load: per-joint current-to-torque gains.

A drive reports current; joint torque is k_j·i_j with a gain k_j that a datasheet knows to
5-15 %. Without a reference, the arm's dynamics fit cannot see a common scale error (every
parameter scales with it). A load of known mass m fixes it: with torque measured on the
configured gains k0 (tau0 = k0·i) and s_j = k_j/k0_j the unknown scale of joint j,

    s_j·tau0_j(t) = H_b,j(t)·mu + Y_c,j(t)·h_f + m_f·Y_m,j(t)

on every sample t of every run, H_b the base regressor of the arm (identify/regressor.py),
Y_m and Y_c the columns of pinocchio's joint-torque regressor for the mass and first
moments of the link carrying the tool frame, h_f = m_f·c_f the unknown first moments of the
load of known-load run f (0 on the unloaded runs, each known-load run its own com: a load
may be mounted differently), m_f its known mass. Linear in (mu, h, s): one least-squares
problem, folded per joint into triangular factors like ``estimate.Accumulator`` (memory
O(n·q²)); OLS, then WLS with per-joint weights 1/sigma_j; covariance sigma²(AᵀA)⁻¹ gives the
gains' standard deviations. The load's inertia about its com is left out (a compact load's
moments, ~0.005 kg·m² for 2.5 kg, are below what these runs resolve: docs/replay.md).

A joint counts as excited by the load when the load's known torque m·Y_m on it stands above
the fit's residual noise (``MIN_LOAD_SNR``) and its gain comes out with a relative standard
deviation below ``MAX_RELATIVE_STD``; the others keep their configured gain (s_j = 1 fixed)
and the problem is solved again without them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.optimize

from hofto_hw.errors import UserError
from hofto_hw.identify.base_params import BaseParameters, find_base_parameters
from hofto_hw.identify.pipeline import Samples
from hofto_hw.identify.regressor import N_RIGID, Regressor, held_sign_series
from hofto_hw.identify.threads import one_blas_thread
from hofto_hw.model.robot import RobotModel

#: a gain counts as calibrated when its relative std dev is at most this
MAX_RELATIVE_STD = 0.01
#: ... and the known load's torque on the joint (RMS over the known-load runs) is at least
#: this many times the joint's residual std dev sigma_j
MIN_LOAD_SNR = 1.0
#: a fitted gain / configured gain outside this band is not a calibration but a gain the data
#: leave undetermined (datasheet torque constants are off by 5-15 %)
PLAUSIBLE_SCALE = (0.5, 2.0)


@dataclass
class KnownLoad:
    """A run with a load of known ``mass`` [kg] on the tool frame (torque on the configured
    gains, like every other run)."""

    samples: Samples
    mass: float


@dataclass
class DriveGains:
    """What :func:`estimate_drive_gains` found, all (n,) per joint.

    ``configured`` [N·m/A]: the gains the torque was read with; ``gains``: the result (the
    calibrated gain, or the configured one for a joint not calibrated); ``std``: std dev of
    the calibrated gains (of the free estimate for a joint not calibrated) [N·m/A];
    ``free``: the estimate with every gain free; ``calibrated``: which joints the load
    excites enough; ``load_snr``: RMS of the load's known torque / sigma_j; ``scale`` =
    gains/configured; ``sigma``: residual std dev per joint [N·m] (configured scale);
    ``load_com``: per known-load run, its com in the tool frame [m]; ``samples``.
    """

    configured: np.ndarray
    gains: np.ndarray
    std: np.ndarray
    free: np.ndarray
    calibrated: np.ndarray
    load_snr: np.ndarray
    sigma: np.ndarray
    load_com: list[np.ndarray] = field(default_factory=list)
    samples: int = 0

    @property
    def scale(self) -> np.ndarray:
        return self.gains / self.configured

    @property
    def relative_std(self) -> np.ndarray:
        return self.std / np.abs(self.free)

    def weak_joints(self, names: Sequence[str]) -> list[str]:
        """Names of the joints that keep their configured gain."""
        return [nm for nm, c in zip(names, self.calibrated, strict=True) if not c]


class _GainSystem:
    """Per-joint R factors of [H_b | Y_c (3 per known load) | -tau0 (n) | rhs]."""

    def __init__(
        self, reg: Regressor, base: BaseParameters, link: int, loads: int, chunk: int = 1000
    ):
        self.reg, self.base, self.chunk = reg, base, chunk
        self.n = reg.n
        self.p = base.p
        self.loads = loads
        self.q = self.p + 3 * loads + self.n  # unknowns
        self.R = np.zeros((self.n, self.q + 1, self.q + 1))
        self.samples = 0
        self.mass_col = N_RIGID * link
        self.com_cols = slice(N_RIGID * link + 1, N_RIGID * link + 4)
        # per known load and joint: Gram matrix of [Y_m, Y_c] over its samples
        self.load_gram = np.zeros((loads, self.n, 4, 4))
        self.load_samples = 0
        self.gain0 = self.p + 3 * loads

    def add(self, s: Samples, load: int | None = None, mass: float = 0.0) -> None:
        reg, n, p, q = self.reg, self.n, self.p, self.q
        held = None
        if reg.held_velocity is not None:
            held = held_sign_series(np.asarray(s.qd, dtype=float), reg.held_velocity)
        N = s.tau.shape[0]
        for start in range(0, N, self.chunk):
            sl = slice(start, start + self.chunk)
            m = s.tau[sl].shape[0]
            H = reg.stack(s.q[sl], s.qd[sl], s.qdd[sl], held=None if held is None else held[sl])
            H3 = H.reshape(m, n, -1)
            for j in range(n):
                A = np.zeros((self.q + 1 + m, self.q + 1))
                A[: q + 1] = self.R[j]
                rows = A[q + 1 :]
                rows[:, :p] = H3[:, j, self.base.columns]
                if load is not None:
                    rows[:, p + 3 * load : p + 3 * load + 3] = H3[:, j, self.com_cols]
                    rows[:, q] = -mass * H3[:, j, self.mass_col]
                    Y = H3[:, j, self.mass_col : self.mass_col + 4]
                    self.load_gram[load, j] += Y.T @ Y
                rows[:, self.gain0 + j] = -s.tau[sl, j]
                r = scipy.linalg.qr(A, mode="r", overwrite_a=True, check_finite=False)[0]
                k = min(r.shape[0], q + 1)
                self.R[j] = 0.0
                self.R[j, :k] = r[:k]
            self.samples += m
            if load is not None:
                self.load_samples += m

    def load_torque_rms(self, x: np.ndarray, masses: Sequence[float]) -> np.ndarray:
        """RMS over the known-load samples of the load's torque per joint (n,) [N·m], for the
        first moments in ``x`` and the known ``masses``."""
        total = np.zeros(self.n)
        for f, m in enumerate(masses):
            v = np.r_[m, x[self.p + 3 * f : self.p + 3 * f + 3]]
            total += np.einsum("a,jab,b->j", v, self.load_gram[f], v)
        return np.sqrt(total / max(self.load_samples, 1))

    def _projected(self, u: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For inverse scales u (n,): the best (mu, h) and the weighted residual (n·(q+1),)."""
        g0, q = self.gain0, self.q
        A = self.R[:, :, :g0] * (w * u)[:, None, None]
        cols = np.stack([self.R[j, :, g0 + j] for j in range(self.n)])  # (n, q+1)
        b = self.R[:, :, q] * (w * u)[:, None] - cols * w[:, None]
        A2, b2 = A.reshape(-1, g0), b.reshape(-1)
        z, *_ = scipy.linalg.lstsq(A2, b2, check_finite=False, lapack_driver="gelsy")
        return z, A2 @ z - b2, cols

    def solve(
        self, groups: np.ndarray, weights: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Least squares of the torque error in the measured (configured) scale,
        tau0_j − (H_b,j·mu + Y_c,j·h + m·Y_m,j)/s_j, with the gain scales s tied by
        ``groups`` (n,): joints with the same index >= 0 share one scale, -1 holds it at 1.
        Bilinear in (mu, h) and u = 1/s: variable projection over u (mu, h by linear least
        squares for each u). Returns x (q,) (mu, h, scales s per joint), per-joint residual
        norms (n,) [N·m·√samples] and the covariance (q, q) of x (zeros where held), scaled
        by the weighted residual variance."""
        n, q, g0 = self.n, self.q, self.gain0
        groups = np.asarray(groups)
        ids = sorted({int(g) for g in groups if g >= 0})
        w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)

        def expand(v: np.ndarray) -> np.ndarray:
            u = np.ones(n)
            for c, gid in enumerate(ids):
                u[groups == gid] = v[c]
            return u

        def resid(v: np.ndarray) -> np.ndarray:
            return self._projected(expand(v), w)[1]

        v = np.ones(len(ids))
        if ids:
            v = scipy.optimize.least_squares(resid, v, bounds=(1e-3, 1e3), x_scale=1.0).x
        u = expand(v)
        z, r, cols = self._projected(u, w)
        if np.linalg.matrix_rank(self.R[:, :, :g0].reshape(-1, g0)) < g0:
            raise UserError(
                "identify --drive-gains: the runs do not determine the arm's base parameters "
                "together with the gains: use richer excitation runs"
            )
        # Jacobian of the weighted residual in (z, v): d/dz = w u R[:, :, :g0];
        # d/du_j = w_j (R_j[:, :g0] z - R_j[:, q])
        J = np.zeros((n * (q + 1), g0 + len(ids)))
        J[:, :g0] = (self.R[:, :, :g0] * (w * u)[:, None, None]).reshape(-1, g0)
        du = (self.R[:, :, :g0] @ z - self.R[:, :, q]) * w[:, None]  # (n, q+1)
        for c, gid in enumerate(ids):
            for j in np.flatnonzero(groups == gid):
                J[j * (q + 1) : (j + 1) * (q + 1), g0 + c] = du[j]
        res = np.linalg.norm(r.reshape(n, q + 1), axis=1) / w
        k = J.shape[1]
        dof = max(self.samples * n - k, 1)
        s2 = float(r @ r) / dof
        cov_zv = s2 * np.linalg.pinv(J.T @ J)
        # x = (z, s) with s_j = 1/u_j: ds/du = -1/u²
        T = np.zeros((q, k))
        T[:g0, :g0] = np.eye(g0)
        for c, gid in enumerate(ids):
            for j in np.flatnonzero(groups == gid):
                T[g0 + j, g0 + c] = -1.0 / u[j] ** 2
        x = np.concatenate([z, 1.0 / u])
        return x, res, T @ cov_zv @ T.T


@one_blas_thread
def estimate_drive_gains(
    model: RobotModel,
    runs: Sequence[Samples],
    loads: Sequence[KnownLoad],
    configured: np.ndarray,
    *,
    smooth_velocity: float = 0.02,
    stribeck_velocity: np.ndarray | None = None,
    held_velocity: float | None = None,
    quadratic: bool = False,
    progress: Callable[[str], None] | None = None,
) -> DriveGains:
    """Calibrate the drive gains of ``model``'s joints (see the module notes).

    ``runs``: unloaded runs, ``loads``: runs with a known load, torque of both read with the
    ``configured`` gains (n,) [N·m/A]; friction structure as ``identify``'s. Raises
    UserError when no known-load run is given, a mass is not finite and > 0, or the load
    excites no joint enough to calibrate its gain (naming the files)."""
    say = progress or (lambda _msg: None)
    n = model.n
    configured = np.asarray(configured, dtype=float)
    if configured.shape != (n,) or not np.all(np.isfinite(configured) & (configured > 0)):
        raise UserError(f"identify --drive-gains: configured gains must be {n} finite values > 0")
    if not loads:
        raise UserError("identify --drive-gains: give at least one --known-load FILE:KG")
    for ld in loads:
        if not (np.isfinite(ld.mass) and ld.mass > 0):
            raise UserError(f"{ld.samples.source}: known-load mass must be > 0 kg, got {ld.mass}")
    reg = Regressor(model.pin_model, smooth_velocity, stribeck_velocity, held_velocity, quadratic)
    base = find_base_parameters(reg, model.joint_names)
    link = model.pin_model.frames[model.tool_frame_id].parentJoint - 1
    system = _GainSystem(reg, base, link, len(loads))
    for s in runs:
        system.add(s)
        say(f"{s.source}: {s.tau.shape[0]} samples")
    for f, ld in enumerate(loads):
        system.add(ld.samples, f, ld.mass)
        say(f"{ld.samples.source}: {ld.samples.tau.shape[0]} samples, known load {ld.mass} kg")
    if system.samples < 2 * system.q:
        raise UserError(
            f"identify --drive-gains: {system.samples} samples are too few for {system.q} unknowns"
        )
    dof = np.sqrt(max(system.samples - system.q / n, 1.0))
    _, res, _ = system.solve(np.full(n, -1))  # configured gains: the weights 1/sigma_j
    sigma = res / dof
    w = 1.0 / np.maximum(sigma, 1e-9 * max(float(sigma.max()), 1e-12))
    x, res, cov = system.solve(np.arange(n), w)
    say("gains fitted with every joint free")
    g0 = system.gain0
    free_scale = x[g0 : g0 + n]
    free_std = np.sqrt(np.maximum(np.diag(cov)[g0 : g0 + n], 0.0))
    masses = [ld.mass for ld in loads]
    calibrated = np.ones(n, dtype=bool)
    scale, std = free_scale.copy(), free_std.copy()
    # Hold the joints that fail at 1 and solve again until every free gain passes: a gain
    # held changes the others through the shared base parameters.
    for _ in range(n):
        sigma = res / dof
        snr = system.load_torque_rms(x, masses) / np.maximum(sigma, 1e-12)
        rel = std / np.maximum(np.abs(scale), 1e-12)
        ok = (
            (snr >= MIN_LOAD_SNR)
            & (rel <= MAX_RELATIVE_STD)
            & (scale >= PLAUSIBLE_SCALE[0])
            & (scale <= PLAUSIBLE_SCALE[1])
        )
        failed = calibrated & ~ok
        if not failed.any():
            break
        calibrated &= ok
        if not calibrated.any():
            names = ", ".join(ld.samples.source for ld in loads)
            raise UserError(
                f"{names}: the known load does not excite any joint enough to calibrate its "
                f"gain (load torque / noise per joint {' '.join(f'{v:.2g}' for v in snr)}, "
                f"need >= {MIN_LOAD_SNR:g}; gain rel. std "
                f"{' '.join(f'{100 * v:.2g}%' for v in rel)}, need <= "
                f"{100 * MAX_RELATIVE_STD:g}%): move the arm through its range with the load on"
            )
        x, res, cov = system.solve(np.where(calibrated, np.arange(n), -1), w)
        scale = np.where(calibrated, x[g0 : g0 + n], 1.0)
        std = np.where(calibrated, np.sqrt(np.maximum(np.diag(cov)[g0 : g0 + n], 0.0)), free_std)
    place = model.pin_model.frames[model.tool_frame_id].placement
    coms = []
    for f, ld in enumerate(loads):
        c_joint = x[system.p + 3 * f : system.p + 3 * f + 3] / ld.mass
        coms.append(place.rotation.T @ (c_joint - place.translation))
    return DriveGains(
        configured=configured.copy(),
        gains=configured * scale,
        std=configured * std,
        free=configured * free_scale,
        calibrated=calibrated,
        load_snr=snr,
        sigma=sigma,
        load_com=coms,
        samples=system.samples,
    )


def parse_known_load(spec: str) -> tuple[str, float]:
    """``FILE:KG`` (``FILE@A:B:KG`` with rows) -> (file spec, mass [kg]); UserError in one
    line for a malformed spec or a mass that is not a finite number > 0."""
    name, sep, kg = spec.rpartition(":")
    if not sep or not name or not kg:
        raise UserError(f"--known-load {spec!r}: expected FILE:KG (mass in kg), e.g. run.csv:2.805")
    try:
        mass = float(kg)
    except ValueError:
        raise UserError(f"--known-load {spec!r}: mass {kg!r} is not a number [kg]") from None
    if not (np.isfinite(mass) and mass > 0.0):
        raise UserError(f"--known-load {spec!r}: mass must be a finite number > 0 kg, got {kg}")
    return name, mass
