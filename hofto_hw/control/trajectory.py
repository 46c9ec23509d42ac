"""Joint trajectories from a Cartesian path through waypoints (the paper's Fig. 3 task).

The tool follows a closed periodic cubic spline through Cartesian waypoints; joint positions
come from Jacobian-based inverse kinematics (damped least squares on the tool position, with a
null-space pull towards a posture), solved at ``ik_rate`` Hz and interpolated by a cubic spline
in joint space, which also gives velocity and acceleration. Position-only IK with the posture
pull leaves the wrist roll (joint 4) almost still, the hard case the paper points out.
Units: s, m, rad, rad/s, rad/s². Offline (allocates freely); not for the tick.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from hofto_hw.control.joint_motion import fade_in
from hofto_hw.errors import ModelError
from hofto_hw.model.robot import RobotModel


@dataclass
class JointTrajectory:
    """Sampled joint trajectory: t (N,), q, qd, qdd (N, n); tool path (N, 3)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tool: np.ndarray


def cartesian_loop(
    model: RobotModel,
    q_start: np.ndarray,
    offsets: np.ndarray,
    period: float,
    duration: float,
    rate: float,
    ik_rate: float = 200.0,
    posture_gain: float = 0.05,
    damping: float = 1e-6,
    ramp: float = 1.0,
    frozen: tuple[int, ...] = (),
) -> JointTrajectory:
    """Tool loop through ``start + offsets`` (K, 3) [m] every ``period`` s, for ``duration`` s.

    The path fades in over ``ramp`` s (the demo path's quintic fade-in) so the arm starts at
    rest at q_start.
    Joints listed in ``frozen`` (0-based) take no part in the IK and stay at q_start.
    Raises ModelError when IK leaves the workspace (residual > 1 mm).
    """
    data = model.create_data()
    p0, _ = data.tool_pose(q_start)
    pts = np.vstack([np.zeros(3), offsets, np.zeros(3)])
    knots = np.linspace(0.0, period, pts.shape[0])
    loop = CubicSpline(knots, pts, bc_type="periodic", axis=0)
    t_ik = np.arange(0.0, duration + 1.0 / ik_rate, 1.0 / ik_rate)
    targets = p0 + _fade_in(t_ik, ramp)[:, None] * loop(t_ik % period)
    q = np.array(q_start, dtype=float)
    qs = np.zeros((t_ik.size, model.n))
    for k, target in enumerate(targets):
        for _ in range(20):
            pos, _ = data.tool_pose(q)
            J = data.tool_jacobian(q)[:3].copy()
            J[:, list(frozen)] = 0.0
            JJt = J @ J.T + damping * np.eye(3)
            J_pinv = J.T @ np.linalg.solve(JJt, np.eye(3))
            null = np.eye(model.n) - J_pinv @ J
            null[list(frozen)] = 0.0
            q = q + J_pinv @ (target - pos) + null @ (posture_gain * (q_start - q))
        residual = np.linalg.norm(data.tool_pose(q)[0] - target)
        if residual > 1e-3:
            raise ModelError(f"trajectory leaves the workspace at t = {t_ik[k]:.2f} s")
        qs[k] = q
    spline = CubicSpline(t_ik, qs, axis=0)
    t = np.arange(0.0, duration, 1.0 / rate)
    tool = p0 + _fade_in(t, ramp)[:, None] * loop(t % period)
    return JointTrajectory(t, spline(t), spline(t, 1), spline(t, 2), tool)


def _fade_in(t: np.ndarray, ramp: float) -> np.ndarray:
    """The demo path's quintic fade-in (:func:`hofto_hw.control.joint_motion.fade_in`) at
    times ``t`` (N,) [s]: the IK targets and the tool path fade in alike."""
    return np.array([fade_in(float(x), ramp)[0] for x in t])
