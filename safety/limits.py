"""Joint supervision on measured values: soft position limits, velocity, torque, following
error, position jumps between ticks and non-finite values anywhere in the tick.

Each check reports the first offending joint and its value to the
:class:`~safety.stop.StopController`; the controller latches and decides. Allocation-free
(a preallocated workspace the kernels write in place). Units: rad, rad/s, N·m.

The checks are :mod:`safety.kernels`' (``limits_scan``, ``limits_commit``, one call on a
quiet tick: ``limits_quiet``): ``backend`` ``numba``/``auto`` (the observers' conventions)
runs them compiled, ``numpy`` runs the same kernels' Python source; what they find is
reported here, in Python, in a fixed class order. The limits, the previous sample, the
scalars and the scan's report are the rows of one float64 workspace and the measured q, qd,
tau are passed as one (3, n) block (the drive group's rows, found once), so the scan takes
five arguments instead of fifteen (each costs ~0.1 µs per call).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hofto_hw import jit
from hofto_hw.jit import Backend
from safety.kernels import (
    FOLLOWING_ERROR,
    HAVE_PREV,
    LIM_ROWS,
    LOWER,
    N_REPORTS,
    PARAMS,
    POSITION_JUMP,
    Q_PREV,
    REPORT_JOINT,
    REPORT_VALUE,
    TORQUE,
    UPPER,
    VELOCITY,
    limits_commit,
    limits_quiet,
)
from safety.stop import Fault, StopController

#: the fault of each report column of the scan (safety.kernels REP_*), in report order
LIMIT_FAULTS = (
    Fault.POSITION_LIMIT,
    Fault.VELOCITY_LIMIT,
    Fault.TORQUE_LIMIT,
    Fault.FOLLOWING_ERROR,
    Fault.POSITION_JUMP,
)


def monitored_limits(
    cfg: object, limits: object
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(lower, upper, velocity, torque) limits the monitor trips at, each (n,) [rad, rad/s,
    N·m], from ``safety.limits`` (LimitsSafetyConfig) and the model's JointLimits: the
    position range shrunk by ``position_margin``, the velocity and torque limits scaled (or
    overridden per joint). Also what a planned motion is checked against before it runs."""
    margin = cfg.position_margin  # type: ignore[attr-defined]
    vel = np.asarray(limits.velocity, dtype=float) * cfg.velocity_scale  # type: ignore[attr-defined]
    tau = np.asarray(limits.torque, dtype=float) * cfg.torque_scale  # type: ignore[attr-defined]
    if cfg.velocity is not None:  # type: ignore[attr-defined]
        vel = np.asarray(cfg.velocity, dtype=float)  # type: ignore[attr-defined]
    if cfg.torque is not None:  # type: ignore[attr-defined]
        tau = np.asarray(cfg.torque, dtype=float)  # type: ignore[attr-defined]
    lower = np.asarray(limits.position_lower, dtype=float) + margin  # type: ignore[attr-defined]
    upper = np.asarray(limits.position_upper, dtype=float) - margin  # type: ignore[attr-defined]
    return lower, upper, vel, tau


class LimitMonitor:
    """Limits per joint, arrays of shape (n,): ``lower``/``upper`` [rad] (soft limits),
    ``velocity`` [rad/s], ``torque`` [N·m]; ``following_error`` and ``position_jump`` [rad]."""

    def __init__(
        self,
        lower: np.ndarray,
        upper: np.ndarray,
        velocity: np.ndarray,
        torque: np.ndarray,
        following_error: float,
        position_jump: float,
        backend: Backend = "python",
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        n = len(lower)
        self.n = n
        # the limits, the previous sample and the scalars as rows of one workspace (the
        # compiled scan's one argument); the attributes are views of its rows
        self._w = np.zeros((LIM_ROWS, max(n, N_REPORTS))) if hot is None else hot["w"]
        self.lower = self._w[LOWER, :n]
        self.upper = self._w[UPPER, :n]
        self.velocity = self._w[VELOCITY, :n]
        self.torque = self._w[TORQUE, :n]
        self.q_prev = self._w[Q_PREV, :n]
        for row, x in zip(self._w[: TORQUE + 1], (lower, upper, velocity, torque), strict=True):
            row[:n] = np.asarray(x, dtype=float)
        self._w[PARAMS, FOLLOWING_ERROR] = float(following_error)
        self._w[PARAMS, POSITION_JUMP] = float(position_jump)
        # the measured sample as one (3, n) block: the caller's q, qd, tau when they are
        # consecutive rows of one array (the drive group's), else a copy into this scratch
        self._sample = np.zeros((3, n))
        self._q_in = self._qd_in = self._tau_in = self._sample  # the arrays _block views
        self._block = self._sample
        self._fin = np.zeros(n, dtype=bool)
        self.backend = jit.ready(backend, self._warm)
        #: True exactly when the compiled kernels run (the fused tick's condition)
        self._use_kernel = self.backend == "numba"
        self._quiet = jit.compiled_or_python(limits_quiet, self.backend)
        self._commit = jit.compiled_or_python(limits_commit, self.backend)

    @property
    def following_error(self) -> float:
        """Following-error bound [rad]."""
        return float(self._w[PARAMS, FOLLOWING_ERROR])

    @property
    def position_jump(self) -> float:
        """Bound on the position change between consecutive fresh samples [rad]."""
        return float(self._w[PARAMS, POSITION_JUMP])

    @property
    def _have_prev(self) -> bool:
        return bool(self._w[PARAMS, HAVE_PREV])

    @_have_prev.setter
    def _have_prev(self, on: bool) -> None:
        self._w[PARAMS, HAVE_PREV] = 1.0 if on else 0.0

    def _warm(self) -> None:
        w = self._w.copy()  # scratch: the scan writes Q_PREV and HAVE_PREV
        limits_quiet(self._sample, self.q_prev, w, 3, 0.0)
        limits_commit(self._sample, w, 3)

    def _sample_block(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """q, qd, tau as the rows of one (3, n) float64 block: a view when they are
        consecutive rows of one C-contiguous 2-D array (kept while the caller passes the same
        arrays: :meth:`check` tests that itself), else this monitor's copy of them."""
        block = _rows_of_one_block(q, qd, tau)
        if block is None:
            np.copyto(self._sample[0], q)
            np.copyto(self._sample[1], qd)
            np.copyto(self._sample[2], tau)
            self._q_in = self._qd_in = self._tau_in = self._sample  # never the caller's
            return self._sample
        self._q_in, self._qd_in, self._tau_in = q, qd, tau
        self._block = block
        return block

    @classmethod
    def from_config(
        cls,
        cfg: object,
        limits: object,
        backend: Backend = "python",
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> LimitMonitor:
        """From ``safety.limits`` (LimitsSafetyConfig) and the model's JointLimits."""
        return cls(
            *monitored_limits(cfg, limits),
            cfg.following_error,  # type: ignore[attr-defined]
            cfg.position_jump,  # type: ignore[attr-defined]
            backend,
            hot,
        )

    @staticmethod
    def hot_fields(n: int) -> dict[str, np.dtype]:
        """The workspace as a field of a caller-owned record (``hot=``: the constructor takes
        it, zeroed, instead of allocating)."""
        return {"w": np.dtype((np.float64, (LIM_ROWS, max(n, N_REPORTS))))}

    def reset(self, q: np.ndarray) -> None:
        """Start from the measured position ``q`` (no jump is seen against it)."""
        np.copyto(self.q_prev, q)
        self._have_prev = True

    def finite(self, stop: StopController, x: np.ndarray) -> bool:
        """Report NON_FINITE (on the first bad joint) unless every entry of ``x`` (n,) is
        finite; returns whether all were."""
        if self._all_finite(x):
            return True
        j = int(np.argmin(self._fin))
        stop.report(Fault.NON_FINITE, j, float(x[j]))
        return False

    def _all_finite(self, x: np.ndarray) -> bool:
        np.isfinite(x, out=self._fin)
        return bool(self._fin.all())

    def check(
        self,
        stop: StopController,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        q_cmd: np.ndarray,
        fresh: bool,
        tracking: bool,
        gap: float = 0.0,
    ) -> None:
        """One tick of limit checks on measured q, qd, tau and last tick's command q_cmd.

        ``fresh``: the sample is new this tick (jumps are only checked on fresh data);
        ``gap`` [s]: time between the previous fresh sample and this one beyond one bus
        cycle (a stale exchange or a stalled loop in between): the jump allowance grows by
        what each joint's velocity limit covers in it (``position_jump`` stays the bound for
        consecutive samples);
        ``tracking``: the drives are powered and follow q_cmd (following error and motor
        torque are checked only then: with the power stage off the brakes hold the arm).
        """
        if q is self._q_in and qd is self._qd_in and tau is self._tau_in:
            block = self._block  # the caller's rows, as last time
        else:
            block = self._sample_block(q, qd, tau)
        how = fresh + 2 * tracking
        w = self._w
        if self._quiet(block, q_cmd, w, how, gap):
            return
        for c in range(N_REPORTS):  # rare: something to report, in class order
            j = int(w[REPORT_JOINT, c])
            if j >= 0:
                stop.report(LIMIT_FAULTS[c], j, float(w[REPORT_VALUE, c]))
        self._commit(block, w, how)


def _rows_of_one_block(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray | None:
    """The (3, n) view of the 2-D float64 array whose consecutive rows q, qd, tau are, or
    None when they are not such rows."""
    base = q.base
    if (
        not isinstance(base, np.ndarray)
        or qd.base is not base
        or tau.base is not base
        or base.ndim != 2
        or base.dtype != np.float64
        or not base.flags.c_contiguous
        or q.shape != (base.shape[1],)
    ):
        return None
    stride = base.strides[0]
    start = q.ctypes.data - base.ctypes.data
    if start % stride or qd.ctypes.data != q.ctypes.data + stride:
        return None
    if tau.ctypes.data != q.ctypes.data + 2 * stride:
        return None
    r = start // stride
    return base[r : r + 3]
