"""A straight tool line as a joint path (``Robot.move_linear``): the tool frame's origin
moves on the segment from where it is to the target position while its orientation turns
about one fixed axis (slerp), sampled every ``step`` metres / radians and solved for the
joints by damped least squares from the previous sample (so the arm stays on its branch).

A target the arm cannot follow is refused before anything moves (UserError, one line): a
sample not solved to ``tol`` (unreachable, through a singularity), a joint outside its
limits, or a joint jump between samples larger than ``max_joint_step`` (a configuration
flip). The joint path then gets the taught path's timing (``path_timing.replay_trajectory``:
jerk-limited within the ``motion:`` limits).

Pose: position [m] and rotation vector [rad] (axis · angle) of the tool frame in the base
frame, as ``[x, y, z, rx, ry, rz]``.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from hofto_hw.errors import UserError
from hofto_hw.model.data import ModelData


def pose_of(data: ModelData, q: np.ndarray) -> np.ndarray:
    """The tool pose at q as ``[x, y, z, rx, ry, rz]``."""
    p, r = data.tool_pose(q)
    return np.concatenate([p, pin.log3(r)])


def linear_joint_path(
    data: ModelData,
    q0: np.ndarray,
    target: np.ndarray,
    step: float = 0.002,
    tol: float = 1e-6,
    max_joint_step: float = 0.1,
) -> np.ndarray:
    """Joint samples (K, n) along the straight tool line from q0's pose to ``target``."""
    model = data.model
    target = np.asarray(target, dtype=float)
    if target.shape != (6,) or not np.all(np.isfinite(target)):
        raise UserError("move_linear: pose must be 6 finite numbers [x, y, z, rx, ry, rz]")
    p0, r0 = data.tool_pose(q0)
    p1, r1 = target[:3], pin.exp3(target[3:])
    d_rot = pin.log3(r0.T @ r1)  # in the start's tool frame
    dist = float(np.linalg.norm(p1 - p0))
    ang = float(np.linalg.norm(d_rot))
    k = max(2, math.ceil(max(dist / step, ang / (10.0 * step))) + 1)
    lo, hi = model.limits.position_lower, model.limits.position_upper
    q = np.array(q0, dtype=float)
    out = np.empty((k, model.n))
    out[0] = q
    for i in range(1, k):
        s = i / (k - 1)
        pt = p0 + s * (p1 - p0)
        rt = r0 @ pin.exp3(s * d_rot)
        for _ in range(50):
            p, r = data.tool_pose(q)
            err = np.concatenate([pt - p, r @ pin.log3(r.T @ rt)])  # world-aligned
            if float(np.linalg.norm(err)) < tol:
                break
            J = data.tool_jacobian(q)
            lam = 1e-4
            dq = J.T @ np.linalg.solve(J @ J.T + lam * np.eye(6), err)
            q = q + dq
        else:
            raise UserError(
                f"move_linear: the line leaves the arm's reach at {100.0 * s:.0f} % "
                f"(tool at {np.round(pt, 4).tolist()} m)"
            )
        if float(np.abs(q - out[i - 1]).max()) > max_joint_step:
            raise UserError(
                f"move_linear: the line needs a joint jump at {100.0 * s:.0f} % (a singularity "
                "or a flip of the arm's configuration); split the move or use move_joints"
            )
        for j in range(model.n):
            if not lo[j] <= q[j] <= hi[j]:
                raise UserError(
                    f"move_linear: {model.joint_names[j]} would reach {q[j]:.4f} rad at "
                    f"{100.0 * s:.0f} % of the line, outside [{lo[j]:.4f}, {hi[j]:.4f}] rad"
                )
        out[i] = q
    return out
