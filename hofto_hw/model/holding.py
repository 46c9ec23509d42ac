"""The static (holding) torque of the arm with a payload: at a pose, and the largest one its
joint limits allow.

The holding torque is the gravity torque g(q) (n,) [N·m]. It is linear in the inertial
parameters of the bodies, so with a payload on the tool link it is
``g_bare(q) + Y_tool(q) @ pi_payload``: the arm without the payload plus the tool link's
four gravity columns of the joint-torque regressor (mass and first moment) times the
payload's mass and first moment (hofto_hw.model.payload.payload_inertia). Both are sampled
once at a fixed set of poses inside the joint limits (:class:`HoldingTorque`), so a
payload's worst case is a (poses x n x 4) product and a short steepest ascent inside the
joint limits from the worst sample of each joint (the gravity's analytic derivatives):
milliseconds, in the control plane. The ascent finds a local maximum near the best sample:
the worst case it reports is the largest found, not a proof that none is larger (the best
sample alone was within 1.1 % of it on ur10e; 20,000 other random poses found none larger).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from hofto_hw.model.payload import Payload, bare_link, payload_inertia, tool_joint
from hofto_hw.model.robot import RobotModel

SAMPLES = 4096  # poses sampled inside the joint limits (seeded: the same every run)
ASCENT_STEPS = 8  # steepest-ascent steps from a joint's worst sample


@dataclass
class Holding:
    """Holding torques (n,) [N·m]: ``here`` at the pose asked, ``worst`` the largest
    magnitude within the joint limits per joint, reached at ``worst_q`` (n, n) [rad] (row j:
    the pose of joint j's worst case)."""

    here: np.ndarray
    worst: np.ndarray
    worst_q: np.ndarray


class HoldingTorque:
    """The holding torque of ``model``'s arm with any payload (see the module docstring).
    Built once (~0.1-0.3 s: the regressor at :data:`SAMPLES` poses) from the model's own
    inertias with its payload taken off (hofto_hw.model.payload.bare_link)."""

    def __init__(self, model: RobotModel, samples: int = SAMPLES) -> None:
        self.model = model
        pm = model.pin_model.copy()
        self.joint = tool_joint(model) + 1  # pinocchio's joint index of the tool link
        bare = bare_link(model)
        pm.inertias[self.joint] = pin.Inertia.FromDynamicParameters(bare)
        self._pm = pm
        self._data = pm.createData()
        self._bare = bare
        n = model.n
        lim = model.limits
        self.lower = np.maximum(lim.position_lower, -np.pi)  # a continuous joint: one turn
        self.upper = np.minimum(lim.position_upper, np.pi)
        u = np.random.default_rng(0).random((samples, n))  # (scipy.stats: seconds to import)
        poses = self.lower + u * (self.upper - self.lower)
        self.poses = np.vstack([poses, 0.5 * (self.lower + self.upper)])
        self._g_bare = np.zeros((self.poses.shape[0], n))
        self._y = np.zeros((self.poses.shape[0], n, 4))
        cols = slice(10 * (self.joint - 1), 10 * (self.joint - 1) + 4)
        zero = np.zeros(n)
        for i, q in enumerate(self.poses):
            self._g_bare[i] = pin.computeGeneralizedGravity(pm, self._data, q)
            Y = pin.computeJointTorqueRegressor(pm, self._data, q, zero, zero)
            self._y[i] = Y[:, cols]

    def _payload_params(self, payload: Payload) -> np.ndarray:
        """mass [kg] and first moment (3) [kg·m] of the payload in the tool joint's frame."""
        return np.asarray(payload_inertia(self.model, payload).toDynamicParameters())[:4]

    def at(self, q: np.ndarray, payload: Payload) -> np.ndarray:
        """Holding torque (n,) [N·m] at ``q`` (n,) [rad] with ``payload``."""
        self._set(payload)
        return np.array(pin.computeGeneralizedGravity(self._pm, self._data, np.asarray(q)))

    def _set(self, payload: Payload) -> None:
        pi = self._bare + payload_inertia(self.model, payload).toDynamicParameters()
        self._pm.inertias[self.joint] = pin.Inertia.FromDynamicParameters(pi)

    def check(self, q: np.ndarray, payload: Payload) -> Holding:
        """The holding torque at ``q`` and the worst case within the joint limits."""
        here = self.at(q, payload)  # (sets the payload into the private model)
        g = self._g_bare + self._y @ self._payload_params(payload)  # (poses, n)
        n = self.model.n
        worst = np.zeros(n)
        worst_q = np.zeros((n, n))
        for j in range(n):
            i = int(np.argmax(np.abs(g[:, j])))
            worst_q[j], worst[j] = self._ascend(j, self.poses[i].copy())
        return Holding(here, worst, worst_q)

    def _ascend(self, j: int, q: np.ndarray) -> tuple[np.ndarray, float]:
        """Steepest ascent of |g_j| from ``q`` inside the limits (gravity's analytic
        derivatives; steps from 0.2 rad halved until one gains): 1.4 ms for all joints, where
        scipy's L-BFGS-B took ~40 ms a joint for maxima 0.1 % higher at most (er3a, ur10e)."""
        pm, data = self._pm, self._data
        lo, hi = self.lower, self.upper
        tau = float(pin.computeGeneralizedGravity(pm, data, q)[j])
        sign = 1.0 if tau >= 0.0 else -1.0
        best = sign * tau
        for _ in range(ASCENT_STEPS):
            d = sign * np.asarray(pin.computeGeneralizedGravityDerivatives(pm, data, q)[j])
            d[((q <= lo) & (d < 0.0)) | ((q >= hi) & (d > 0.0))] = 0.0  # against a limit
            norm = float(np.linalg.norm(d))
            if norm == 0.0:
                break
            d /= norm
            step = 0.2
            while step > 1e-3:
                trial = np.clip(q + step * d, lo, hi)
                t = sign * float(pin.computeGeneralizedGravity(pm, data, trial)[j])
                if t > best:
                    q, best = trial, t
                    break
                step *= 0.5
            else:
                break
        return q, best

    def refusal(self, q: np.ndarray, payload: Payload, fraction: float = 1.0) -> str:
        """Why ``payload`` does not fit (one line naming the joint, its holding torque and
        the limit), "" when it does: its holding torque must stay within ``fraction`` of
        each joint's torque limit (model.limits.torque) at ``q`` (the current pose) and at
        the worst pose the joint limits allow, since the arm may be moved anywhere in them
        with it (the current pose is named first: it is where the arm holds it now)."""
        h = self.check(q, payload)
        limit = self.model.limits.torque
        names = self.model.joint_names
        share = "" if fraction == 1.0 else f"{fraction:g} x "
        for j in range(self.model.n):
            lim = fraction * float(limit[j])
            tail = f"more than {share}its torque limit {float(limit[j]):g} N·m"
            if abs(float(h.here[j])) > lim:
                return (
                    f"{names[j]} would hold {abs(float(h.here[j])):.1f} N·m at the current pose, "
                    f"{tail}"
                )
        for j in range(self.model.n):
            if float(h.worst[j]) > fraction * float(limit[j]):
                pose = ", ".join(f"{v:.2f}" for v in h.worst_q[j])
                return (
                    f"{names[j]} would hold {float(h.worst[j]):.1f} N·m at a pose within the "
                    f"joint limits (q = [{pose}] rad), more than {share}its torque limit "
                    f"{float(limit[j]):g} N·m"
                )
        return ""
