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
  sampled at the loop period; :class:`TrajectoryPlayer` plays samples per tick.

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

    spline = make_lsq_spline(tp, qp, knots, k=k, axis=0)
    # exact rest at both ends: with clamped knots, q', q'' at an end depend only on the first
    # (last) three coefficients; equal coefficients make them zero (the padding is at rest,
    # so this moves the fit by far less than the noise)
    c = spline.c
    c[0], c[-1] = q[0], q[-1]
    c[1] = c[2] = c[0]
    c[-2] = c[-3] = c[-1]
    return spline, tp[0], tp[-1]


def time_scale_path(
    t: np.ndarray,
    q: np.ndarray,
    limits: Limits,
    dt: float,
    knot_spacing: float = 0.05,
    pad: float = 0.3,
) -> Sampled:
    """The taught path (t (N,) [s], q (N, n) [rad]) slowed uniformly into ``limits``."""
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
    tr = np.arange(0.0, (t1 - t0) * c + 0.5 * dt, dt)
    s = t0 + tr / c
    s = np.minimum(s, t1)
    return Sampled(dt, spline(s), spline(s, 1) / c, spline(s, 2) / (c * c), [0], scale=c)


def replay_trajectory(
    q_now: np.ndarray, t: np.ndarray, q: np.ndarray, limits: Limits, dt: float
) -> Sampled:
    """Move to the path's start (ruckig), then the time-scaled path; sampled at ``dt``."""
    path = time_scale_path(t, q, limits, dt)
    move = jerk_limited_move(q_now, path.q[0], limits, dt)
    return Sampled(
        dt,
        np.vstack([move.q, path.q]),
        np.vstack([move.qd, path.qd]),
        np.vstack([move.qdd, path.qdd]),
        [0, move.q.shape[0]],
        scale=path.scale,
    )


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
