"""Joint supervision on measured values: soft position limits, velocity, torque, following
error and position jumps between ticks (a non-finite value anywhere in the tick is section
4's own check, NON_FINITE: hofto_hw/runtime/fused.py).

What is judged on which sample: position and velocity always; motor torque while the drives
are powered and track the command (with the power stage off the brakes hold the arm); the
following error |q_cmd - q| only on a fresh sample while tracking (a stale sample is an old
position against a newer command: its lag is not the drive's, and a run of lost samples is
the bus-loss check's); a position jump only between fresh samples. A repeated torque is
still judged: it is the last torque the drive measured.

The checks are :mod:`safety.kernels`' (``limits_scan``, ``limits_commit``), called by the
tick's compiled section 4 (hofto_hw/runtime/fused.py), which reports what they find in a
fixed class order (:data:`LIMIT_FAULTS`). This monitor holds what they read and write: the
limits, the previous fresh sample, the scalars and the scan's report as the rows of one
float64 workspace (caller-owned when built on the tick's hot record), and
:meth:`LimitMonitor.reset`. Units: rad, rad/s, N·m. (The same checks as Python calls on a
monitor, for tests and the tick's Python reference: tests/support/reference_safety.py.)
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
    TORQUE,
    UPPER,
    VELOCITY,
    limits_commit,
    limits_scan,
)
from safety.stop import Fault

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
    ``velocity`` [rad/s], ``torque`` [N·m]; ``following_error`` and ``position_jump`` [rad].

    The workspace the kernels read and write (``_w``, rows :data:`safety.kernels.LOWER` ...)
    and the previous fresh position ``q_prev``; ``backend``: ``numba``/``auto`` compiles and
    warms the kernels (``_use_kernel``: the fused tick's condition), ``python`` does not."""

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
        self.backend = jit.ready(backend, self._warm)
        #: True exactly when the compiled kernels run (the fused tick's condition)
        self._use_kernel = self.backend == "numba"

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
        sample = np.zeros((3, self.n))
        w = self._w.copy()  # scratch: the commit writes Q_PREV and HAVE_PREV
        limits_scan(sample, self.q_prev, w, 3, 0.0)
        limits_commit(sample, w, 3)

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
