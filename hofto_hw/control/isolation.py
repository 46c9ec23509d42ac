"""Contact isolation from the estimated joint torques: tool or another link, and which.

Per tick (allocation-free, :meth:`ContactIsolation.check`): does tau_ext_hat look like a
hand at the tool? The tool hypothesis is a force f at the tool origin (plus a moment when
rotation is unlocked for dragging); its least-squares fit leaves the residual

    r = tau_ext_hat - Jᵀ·f,    mismatch = max_j |r_j|  [N·m].

A 6-joint arm with a full tool wrench (force + moment) explains *any* joint torque, so the
check is only informative with a force-only (or masked) tool hypothesis: 6 equations, 3
unknowns. A mismatch above the threshold means "a contact not at the tool". The threshold grows by
``force_ratio`` N·m per N of tool force let go of (the peak of the last ``hold_time`` minus
now): with model error the residual grows with the arm's deceleration after a hand lets go
(ER3A, 10 % model error: ~0.2 N·m at 20 N, ~0.5 at 80 N, up to 1.2 after an 80 N release),
while a contact adds to the fitted force and leaves the threshold where it is.

On the event tick only (:meth:`ContactIsolation.isolate`, allocates): name the link. The
hand's force at the tool cannot be told from a contact on links 1-3 in one sample: with the
tool on the wrist's last axis, a tool force along the wrist-centre-to-tool line loads joints
1-3 only. So isolation takes the hand's force as it was ``lookback`` matching ticks before
the mismatch (a hand changes slowly against a contact's onset, and the fit absorbs part of a
contact while it builds up) and isolates the rest,
tau_c = tau_ext_hat - Jᵀ·f_before. A contact on link k (the body moved by joint k) loads
joints 1..k only; for k = 1, 2, ... the hypothesis "a point force at the middle of link k"
is fitted to tau_c and the first k whose residual is below a tolerance (a quarter of the
threshold or 5 % of the largest torque) is the most likely link. Returns the 1-based link
number (n: the last link, e.g. a moment at the tool).

Why here and not in safety/: this is estimation (which body the estimate points at), like
the wrench; it decides nothing. The drag controller reports the mismatch as a stop
request and the service's stop controller latches and acts, with the link in the event.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dposv

from hofto_hw.control.wrench import ToolJacobian, norm3
from hofto_hw.model.robot import RobotModel


class ContactIsolation:
    """See the module docstring. ``threshold`` [N·m]; ``rotation``: the tool hypothesis
    includes a moment (rotation unlocked for dragging). After :meth:`check`: ``mismatch``
    [N·m], ``tool_force`` (3,) [N] of the tool-force fit, ``residual`` (n,) [N·m].
    ``lookback``: ticks of matching fits kept for :meth:`isolate`."""

    def __init__(
        self,
        model: RobotModel,
        jac: ToolJacobian,
        threshold: float,
        rotation: bool = False,
        lookback: int = 50,
        force_ratio: float = 0.0,
        hold_time: float = 0.3,
    ) -> None:
        self.model = model
        self.jac = jac
        self.threshold = float(threshold)
        #: the threshold grows by this per N of tool force let go of [N·m/N] (the fit's
        #: residual grows with the arm's deceleration after a release: model error)
        self.force_ratio = float(force_ratio)
        self.hold_time = float(hold_time)
        self.force_peak = 0.0  # |tool force| peak, decaying over hold_time [N]
        self.level = self.threshold  # this tick's threshold [N·m]
        self.k = 6 if rotation else 3
        n = model.n
        self._Jh = jac.J[: self.k]  # a view of the tool Jacobian's rows of the hypothesis
        self._A = np.zeros((self.k, self.k))
        self._b = np.zeros(self.k)
        self._A2 = np.zeros((self.k, self.k))
        self._b2 = np.zeros(self.k)
        self._fit = np.zeros(n)
        self.residual = np.zeros(n)
        self.tool_force = np.zeros(3)
        self._fit_b = np.zeros(self.k)
        #: the tool hypothesis's fit (force, and moment if rotation) isolation subtracts
        self.tool_force_before = np.zeros(self.k)
        self._ring = np.zeros((max(1, int(lookback)), self.k))
        self._head = 0
        self._filled = 0
        self.mismatch = 0.0
        self._data = model.pin_model.createData()  # event-time kinematics
        #: a link hypothesis "explains" tau_c when its residual is below this fraction of the
        #: detection threshold (or 5 % of the largest torque)
        self.explain_fraction = 0.25
        self.residuals = np.full(n, np.nan)

    def reset(self) -> None:
        """Forget the force peak (a new drag)."""
        self.force_peak = 0.0
        self.level = self.threshold

    def check(self, tau_ext: np.ndarray, dt: float = 0.001) -> bool:
        """True when tau_ext (n,) does not match a hand at the tool (``jac`` at this q);
        ``dt`` [s] since the last check (the force peak's decay)."""
        Jh, b = self._Jh, self._fit_tool(tau_ext, self._A, self._b)
        np.copyto(self.tool_force, b[:3])
        np.copyto(self._fit_b, b)
        np.matmul(Jh.T, b, out=self._fit)
        np.subtract(tau_ext, self._fit, out=self.residual)
        np.abs(self.residual, out=self._fit)
        self.mismatch = float(self._fit.max())
        norm = norm3(self.tool_force)
        peak = self.force_peak * math.exp(-dt / self.hold_time) if self.hold_time > 0.0 else 0.0
        self.force_peak = max(norm, peak)
        # raised by the force the hand has let go of: a contact adds to the fitted force
        # (no raise), a release takes it away while the arm decelerates (model error)
        self.level = self.threshold + self.force_ratio * (self.force_peak - norm)
        if self.mismatch > self.level:
            return True
        # keep the fits of matching ticks: isolation takes one from `lookback` ticks before
        # the mismatch, since the fit absorbs some of a contact while it builds up
        self._ring[self._head] = self._fit_b
        self._head = (self._head + 1) % self._ring.shape[0]
        self._filled = min(self._filled + 1, self._ring.shape[0])
        return False

    def tool_share(self, tau: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The part of ``tau`` (n,) [N·m] a hand at the tool explains, Jhᵀ·f with f the
        least-squares tool force (and moment if rotation) of ``tau``, into ``out`` (n,);
        ``jac`` at this q. Allocation-free; leaves :meth:`check`'s results alone."""
        np.matmul(self._Jh.T, self._fit_tool(tau, self._A2, self._b2), out=out)
        return out

    def _fit_tool(self, tau: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The least-squares tool force (and moment if rotation) f of ``tau`` (n,), from
        (Jh·Jhᵀ + 1e-9·I)·f = Jh·tau in the workspaces ``A`` (k, k) and ``b`` (k,); zeros when
        that does not factor. Returns ``b``."""
        Jh = self._Jh
        np.matmul(Jh, Jh.T, out=A)
        for i in range(self.k):
            A[i, i] += 1e-9
        np.matmul(Jh, tau, out=b)
        _, _, info = dposv(A.T, b, lower=0, overwrite_a=1, overwrite_b=1)
        if info != 0:
            b.fill(0.0)
        return b

    def isolate(self, q: np.ndarray, tau_ext: np.ndarray) -> int:
        """The most likely contact link (1-based; n = last link). Allocates."""
        pm, d = self.model.pin_model, self._data
        n = self.model.n
        pin.computeJointJacobians(pm, d, q)
        pin.framesForwardKinematics(pm, d, q)
        tool = pin.getFrameJacobian(pm, d, self.jac.frame_id, pin.LOCAL_WORLD_ALIGNED)[: self.k]
        if self._filled:
            # the oldest kept fit: `lookback` matching ticks before the mismatch
            oldest = (self._head - self._filled) % self._ring.shape[0]
            self.tool_force_before[:] = self._ring[oldest]
        tau = np.asarray(tau_ext, dtype=float) - tool.T @ self.tool_force_before
        self.residuals = np.full(n, np.nan)
        tol = max(self.explain_fraction * self.threshold, 0.05 * float(np.abs(tau).max()))
        for link in range(1, n):
            Jp = _point_jacobian(pm, d, link, link + 1)
            x, *_ = np.linalg.lstsq(Jp.T, tau, rcond=1e-6)
            self.residuals[link - 1] = np.abs(tau - Jp.T @ x).max()
            if self.residuals[link - 1] <= tol:
                return link
        return n


def _point_jacobian(pm: pin.Model, d: pin.Data, joint: int, next_joint: int) -> np.ndarray:
    """Positional Jacobian (3, n) of the midpoint between the origins of ``joint`` and
    ``next_joint`` (a point on link ``joint``), world-aligned."""
    J = pin.getJointJacobian(pm, d, joint, pin.LOCAL_WORLD_ALIGNED)
    o = d.oMi[joint].translation
    p = 0.5 * (o + d.oMi[next_joint].translation)
    r = p - o
    # v_p = v_o + w × r = v_o - r × w
    skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return J[:3] - skew @ J[3:]
