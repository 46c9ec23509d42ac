"""Jerk-limited joint motion: point-to-point moves (ruckig) and taught-path replay.

- :func:`jerk_limited_move`: a time-optimal jerk-limited move between two rest states, one
  ruckig trajectory (community version, offline calculation; no intermediate waypoints).
- :func:`time_scale_path`: a taught path as a smooth function of time and one uniform time
  scale c >= 1 that puts it within the velocity, acceleration and jerk limits:
  q_r(t) = p(t / c), so qd = p'/c, qdd = p''/c², qddd = p'''/c³. The path p is a least-squares
  quintic B-spline (scipy) through the recorded samples (knots every ``knot_spacing``
  seconds), padded at rest at both ends and starting and ending exactly at rest (velocity and
  acceleration zero, so it joins the ruckig move without a jump); its jerk is continuous and
  bounded and the recorded encoder noise is not differentiated three times. The replayed
  geometry is the taught one (the spline's fit residual, ~0.1 mm, is the only path error it adds).
- :func:`replay_trajectory`: the move to the path's start followed by the scaled path,
  sampled at the loop period (:func:`replay_plan`: the same rows, evaluated a piece at a
  time, for a planner that streams them); :class:`TrajectoryPlayer` plays samples per tick.

Why not ruckig segment by segment or toppra for the path: ruckig's community version plans
one segment between two states; chained through waypoints it leaves the taught geometry
between them (it is time-optimal per segment, not path-following). toppra is time-optimal
along the path but limits only velocity and acceleration (second order), not jerk. A taught
path is slow (hand speed, <= 0.25 m/s) and its limits are the replay's own, so the one
uniform scale of a smooth fit meets all three limits exactly on the taught geometry; the
figures are in docs/drag.md. Units rad, rad/s, rad/s², rad/s³, s. Offline except the player.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Trajectory

from hofto_hw.errors import UserError


@dataclass
class Limits:
    """Per-joint limits, arrays (n,): velocity, acceleration, jerk."""

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray


@dataclass
class Sampled:
    """A trajectory sampled every ``dt`` [s]: q, qd, qdd (K, n); ``segments``: start index of
    each part (move to start, path)."""

    dt: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    segments: list[int]
    scale: float = 1.0

    @property
    def duration(self) -> float:
        return self.q.shape[0] * self.dt

    @property
    def n_rows(self) -> int:
        return self.q.shape[0]

    def rows(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, qd, qdd of rows i0 .. i1 - 1 (views; :class:`ReplayPlan`'s interface)."""
        return self.q[i0:i1], self.qd[i0:i1], self.qdd[i0:i1]


def jerk_limited_move(q0: np.ndarray, q1: np.ndarray, limits: Limits, dt: float) -> Sampled:
    """Rest-to-rest move from ``q0`` to ``q1`` (n,) [rad] within ``limits``, sampled at
    ``dt`` (ruckig, time-optimal, all joints finishing together)."""
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    n = q0.shape[0]
    if not (np.all(np.isfinite(q0)) and np.all(np.isfinite(q1))):
        raise UserError("move: non-finite joint position")
    inp = InputParameter(n)
    inp.current_position = q0.tolist()
    inp.current_velocity = [0.0] * n
    inp.current_acceleration = [0.0] * n
    inp.target_position = q1.tolist()
    inp.target_velocity = [0.0] * n
    inp.target_acceleration = [0.0] * n
    inp.max_velocity = limits.velocity.tolist()
    inp.max_acceleration = limits.acceleration.tolist()
    inp.max_jerk = limits.jerk.tolist()
    traj = Trajectory(n)
    result = Ruckig(n).calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):
        raise UserError(f"move: ruckig cannot plan the move ({result.name})")
    k = max(1, int(np.ceil(traj.duration / dt)) + 1)
    q = np.zeros((k, n))
    qd = np.zeros((k, n))
    qdd = np.zeros((k, n))
    for i in range(k):
        p, v, a = traj.at_time(min(i * dt, traj.duration))
        q[i], qd[i], qdd[i] = p, v, a
    return Sampled(dt, q, qd, qdd, [0])


def _fit(t: np.ndarray, q: np.ndarray, knot_spacing: float, pad: float):
    """Least-squares quintic B-spline of q(t) (N, n), padded at rest by ``pad`` s each end."""
    dt = float(np.median(np.diff(t)))
    m = max(1, round(pad / dt))
    tp = np.concatenate([t[0] - dt * np.arange(m, 0, -1), t, t[-1] + dt * np.arange(1, m + 1)])
    qp = np.vstack([np.repeat(q[:1], m, axis=0), q, np.repeat(q[-1:], m, axis=0)])
    k = 5
    inner = np.arange(tp[0] + knot_spacing, tp[-1] - 0.5 * knot_spacing, knot_spacing)
    knots = np.concatenate([[tp[0]] * (k + 1), inner, [tp[-1]] * (k + 1)])
    from scipy.interpolate import make_lsq_spline  # here: seconds of imports at every start

    try:  # the banded normal equations: a 300 s path in ~1 s; scipy >= 1.13's default QR
        # takes ~40 s of CPU for the same coefficients (8e-14 apart on a 300 s path)
        spline = make_lsq_spline(tp, qp, knots, k=k, axis=0, method="norm-eq")
    except TypeError:  # scipy < 1.13: the normal equations are its only method
        spline = make_lsq_spline(tp, qp, knots, k=k, axis=0)
    # exact rest at both ends: with clamped knots, q', q'' at an end depend only on the first
    # (last) three coefficients; equal coefficients make them zero (the padding is at rest,
    # so this moves the fit by far less than the noise)
    c = spline.c
    c[0], c[-1] = q[0], q[-1]
    c[1] = c[2] = c[0]
    c[-2] = c[-3] = c[-1]
    return spline, tp[0], tp[-1]


class ScaledPath:
    """A path p(s) (a scipy BSpline of s [s], values (n,)) on [s0, s1] played uniformly
    slower by ``scale`` c >= 1, sampled every ``dt``: row i is t = i·dt, s = min(s0 + t/c,
    s1); q = p(s), qd = p'(s)/c, qdd = p''(s)/c². Rows are evaluated on demand
    (:meth:`rows`), a piece at a time, so a long path streams without being sampled whole."""

    def __init__(self, spline, s0: float, s1: float, scale: float, dt: float) -> None:
        self.spline, self.s0, self.s1, self.scale, self.dt = spline, s0, s1, scale, dt
        # as np.arange(0, (s1 - s0)·c + dt/2, dt) would: ceil((stop - start) / step)
        self.n_rows = max(1, int(np.ceil(((s1 - s0) * scale + 0.5 * dt) / dt)))

    def rows(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, qd, qdd (i1 - i0, n) of rows i0 .. i1 - 1."""
        c = self.scale
        s = np.minimum(self.s0 + np.arange(i0, i1) * self.dt / c, self.s1)
        sp = self.spline
        return sp(s), sp(s, 1) / c, sp(s, 2) / (c * c)


def scaled_path(
    t: np.ndarray,
    q: np.ndarray,
    limits: Limits,
    dt: float,
    knot_spacing: float = 0.05,
    pad: float = 0.3,
) -> ScaledPath:
    """The taught path (t (N,) [s], q (N, n) [rad]) slowed uniformly into ``limits``: the
    fit and its scale (the whole path: the scale is uniform), the rows left to be sampled."""
    if t.shape[0] < 10:
        raise UserError(f"replay: the taught path has {t.shape[0]} samples, too short to replay")
    spline, t0, t1 = _fit(t, q, knot_spacing, pad)
    grid = np.arange(t0, t1, min(dt, 1e-3))
    peaks = [np.abs(spline(grid, d)).max(axis=0) for d in (1, 2, 3)]
    c = max(
        1.0,
        float((peaks[0] / limits.velocity).max()),
        float(np.sqrt((peaks[1] / limits.acceleration).max())),
        float(np.cbrt((peaks[2] / limits.jerk).max())),
    )
    return ScaledPath(spline, t0, t1, c, dt)


def time_scale_path(
    t: np.ndarray,
    q: np.ndarray,
    limits: Limits,
    dt: float,
    knot_spacing: float = 0.05,
    pad: float = 0.3,
) -> Sampled:
    """The taught path (t (N,) [s], q (N, n) [rad]) slowed uniformly into ``limits``."""
    path = scaled_path(t, q, limits, dt, knot_spacing, pad)
    qs, qd, qdd = path.rows(0, path.n_rows)
    return Sampled(dt, qs, qd, qdd, [0], scale=path.scale)


class ReplayPlan:
    """The move to the path's start (sampled: a few seconds at most) followed by the scaled
    path (sampled on demand): ``n_rows`` rows, :meth:`rows` any piece of them."""

    def __init__(self, move: Sampled, path: ScaledPath) -> None:
        self.move, self.path = move, path
        self.dt = path.dt
        self.scale = path.scale
        self.segments = [0, move.q.shape[0]]
        self.n_rows = move.q.shape[0] + path.n_rows

    def rows(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, qd, qdd (i1 - i0, n) of rows i0 .. i1 - 1 (0 <= i0 <= i1 <= n_rows)."""
        m = self.move.q.shape[0]
        parts = []
        if i0 < m:
            e = min(i1, m)
            parts.append((self.move.q[i0:e], self.move.qd[i0:e], self.move.qdd[i0:e]))
        if i1 > m:
            parts.append(self.path.rows(max(i0, m) - m, i1 - m))
        if len(parts) == 1:
            return parts[0]
        return tuple(np.vstack([a, b]) for a, b in zip(*parts, strict=True))  # type: ignore[return-value]

    def sampled(self) -> Sampled:
        q, qd, qdd = self.rows(0, self.n_rows)
        return Sampled(self.dt, q, qd, qdd, list(self.segments), scale=self.scale)


def replay_plan(
    q_now: np.ndarray, t: np.ndarray, q: np.ndarray, limits: Limits, dt: float
) -> ReplayPlan:
    """Move to the path's start (ruckig), then the time-scaled path, rows on demand."""
    path = scaled_path(t, q, limits, dt)
    start = path.rows(0, 1)[0][0]
    return ReplayPlan(jerk_limited_move(q_now, start, limits, dt), path)


def replay_trajectory(
    q_now: np.ndarray, t: np.ndarray, q: np.ndarray, limits: Limits, dt: float
) -> Sampled:
    """Move to the path's start (ruckig), then the time-scaled path; sampled at ``dt``."""
    return replay_plan(q_now, t, q, limits, dt).sampled()


class TrajectoryPlayer:
    """Plays a :class:`Sampled` trajectory one row per tick (allocation-free); holds the
    last sample when done."""

    def __init__(self, traj: Sampled) -> None:
        self.traj = traj
        self.k = 0

    @property
    def done(self) -> bool:
        return self.k >= self.traj.q.shape[0] - 1

    def step(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> bool:
        """Write this tick's reference into q, qd, qdd (n,); returns True when finished."""
        tr = self.traj
        k = min(self.k, tr.q.shape[0] - 1)
        np.copyto(q, tr.q[k])
        if self.k >= tr.q.shape[0] - 1:
            qd.fill(0.0)
            qdd.fill(0.0)
            return True
        np.copyto(qd, tr.qd[k])
        np.copyto(qdd, tr.qdd[k])
        self.k += 1
        return False
