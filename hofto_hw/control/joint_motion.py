"""Joint-space motion for the real-time loop: hold, a smooth demo path, a ramp to standstill.

:class:`DemoPath` gives q_ref(t) = q0 + A·sin(2π·t/T + φ)·s(t) - A·sin(φ)·s(t), with s a
quintic fade-in over ``ramp`` seconds, so the path starts at rest at q0 and moves smoothly.
:class:`JointMotion` is the controller's motion generator: ``hold`` (command a fixed position),
``move`` (follow the demo path from where the arm is), ``play`` (a precomputed jerk-limited
trajectory: a taught-path replay or a move to a joint target, planned outside the tick by
hofto_hw.control.path_timing), and a ramp to standstill at the acceleration limits (used for
mode changes to hold and for stop category 2), or at a starved streamed plan's own limits.

Units rad, rad/s, rad/s², s; arrays (n,). Allocation-free per tick. ``JointMotion.version``
changes whenever the reference (q, qd, qdd) may have changed: the tick's feed-forward, a
function of the reference alone, is reused while it stays the same (a hold). The path and
the ramp are the kernels of :mod:`hofto_hw.control.kernels` (their one place), called with
the observers' ``backend`` conventions: ``numba`` (``auto`` where numba works) runs them
compiled, ``python`` runs the kernels' own source in the interpreter (same bits).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from hofto_hw import jit
from hofto_hw.control.kernels import PATH_ROWS, path_eval, path_workspace, ramp_step
from hofto_hw.jit import Backend

if TYPE_CHECKING:
    from hofto_hw.control.path_timing import TrajectoryPlayer

HOLD, MOVE, RAMP_DOWN, DRAG, REPLAY, MOVE_TO = 0, 1, 2, 3, 4, 5
#: DRAG: the reference comes from hofto_hw.control.drag.DragController (the tick copies it);
#: REPLAY (taught path) and MOVE_TO (joint target): a TrajectoryPlayer, one row per tick
MODE_NAMES = {
    HOLD: "hold",
    MOVE: "move",
    RAMP_DOWN: "stopping",
    DRAG: "drag",
    REPLAY: "replay",
    MOVE_TO: "move_to",
}
PLAYING = (REPLAY, MOVE_TO)


#: fade_in at and after the ramp: s, s', s'' as its formula gives them at x = 1
FADED_IN = (1.0, 0.0, -0.0)


def fade_in(t: float, ramp: float, two: float = 2.0) -> tuple[float, float, float]:
    """The quintic fade-in s(t/ramp) and its time derivatives s', s'' [1/s, 1/s²] at ``t`` [s]
    (``ramp`` > 0). At and after the ramp the constants its formula gives there (1, +0, -0:
    every tick of a long run, without the arithmetic). ``two``: the exponent of (1 - x)²,
    libm's pow (the tick's fused call compiles this function and passes it from memory)."""
    if t >= ramp:
        return FADED_IN
    x = min(max(t / ramp, 0.0), 1.0)
    b = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)
    bd = 30.0 * x * x * math.pow(1.0 - x, two) / ramp
    bdd = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / (ramp * ramp)
    return b, bd, bdd


class DemoPath:
    """Smooth periodic joint motion about a start pose (see module docstring)."""

    def __init__(
        self,
        amplitude: np.ndarray,
        period: np.ndarray,
        phase: np.ndarray | None = None,
        ramp: float = 1.0,
        backend: Backend = "python",
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        self.a = np.asarray(amplitude, dtype=float).copy()
        self.w = 2.0 * math.pi / np.asarray(period, dtype=float)
        self.phi = np.zeros_like(self.a) if phase is None else np.asarray(phase, float).copy()
        self.offset = self.a * np.sin(self.phi)
        self.ramp = float(ramp)
        k = path_workspace(self.a, self.w, self.phi, self.offset)  # the kernel's rows
        self._k = k if hot is None else hot["k"]
        if hot is not None:
            np.copyto(self._k, k)
        self.backend = jit.ready(backend, self._warm)
        #: True exactly when the compiled kernel runs (the tick's fused call reads it)
        self._use_kernel = self.backend == "numba"
        #: the kernel this path calls: path_eval compiled, or its source (backend python)
        self._eval = jit.compiled_or_python(path_eval, self.backend)

    @staticmethod
    def hot_fields(n: int) -> dict[str, np.dtype]:
        """The kernel's rows as a field of a caller-owned record (``hot=``: the constructor
        writes them there instead of keeping its own)."""
        return {"k": np.dtype((np.float64, (PATH_ROWS, n)))}

    def _warm(self) -> None:
        z = np.zeros(self.a.shape[0])
        path_eval(self._k.copy(), 0.5, 0.5, 0.5, 0.5, z, z.copy(), z.copy(), z.copy())

    def evaluate(
        self, t: float, q0: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
    ) -> None:
        """Reference at time ``t`` [s] since the start into q, qd, qdd (n,)."""
        b, bd, bdd = fade_in(t, self.ramp)
        self._eval(self._k, t, b, bd, bdd, q0, q, qd, qdd)


class JointMotion:
    """Reference generator: ``q``, ``qd``, ``qdd`` (n,) after :meth:`update`; ``mode``.

    ``version`` (int) is bumped by every method that writes q, qd or qdd (a hold writes
    them once, on its first update): an unchanged ``version`` means q, qd, qdd hold the same
    bits as when it was read. Write them through these methods only (:meth:`follow` for a
    reference computed elsewhere)."""

    def __init__(
        self,
        n: int,
        accel_limit: np.ndarray,
        path: DemoPath | None,
        backend: Backend = "python",
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        self.n = n
        self.accel = np.asarray(accel_limit, dtype=float).copy()
        self.path = path
        #: the reference q, qd, qdd and the path's start pose q0 (n,) as one record (the
        #: tick's compiled call takes it as one argument); the attributes are its fields
        self.state = np.zeros(1, self.hot_fields(n)["state"]) if hot is None else hot["state"]
        self.q, self.qd, self.qdd, self.q0 = (self.state[f][0] for f in ("q", "qd", "qdd", "q0"))
        self.mode = HOLD
        self.t0 = 0.0
        self.player: TrajectoryPlayer | None = None
        #: the deceleration [rad/s²] (n,) of the ramp to standstill (see ramp_down)
        self.ramp_accel = self.accel.copy()
        self._play_accel = self.accel.copy()  # the playing plan's limits (see play)
        #: bumped whenever q, qd or qdd may have changed (see the class docstring)
        self.version = 0
        self._still = True  # qd and qdd hold +0.0: a hold's update has nothing to write
        self.backend = jit.ready(backend, self._warm)
        self._use_kernel = self.backend == "numba"  # True exactly when ramp_step is compiled
        self._ramp_step = jit.compiled_or_python(ramp_step, self.backend)

    @staticmethod
    def hot_fields(n: int) -> dict[str, np.dtype]:
        """The reference q, qd, qdd and q0 (n,) as one record, a field of a caller-owned
        record (``hot=``: the constructor takes it, zeroed, instead of allocating)."""
        return {"state": np.dtype([(f, np.float64, (n,)) for f in ("q", "qd", "qdd", "q0")])}

    def _warm(self) -> None:
        z = np.zeros(self.n)
        ramp_step(self.accel, 1e-3, z, z.copy(), z.copy())

    def start(self, q: np.ndarray) -> None:
        """Hold the measured position ``q``."""
        np.copyto(self.q, q)
        self.qd.fill(0.0)
        self.qdd.fill(0.0)
        self.mode = HOLD
        self.version += 1
        self._still = True

    def follow(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> None:
        """Take a reference computed elsewhere (the drag controller's) for this tick."""
        np.copyto(self.q, q)
        np.copyto(self.qd, qd)
        np.copyto(self.qdd, qdd)
        self.version += 1
        self._still = False

    def move(self, t: float) -> bool:
        """Follow the demo path from the current command (only from standstill)."""
        if self.path is None or self.mode == MOVE or self.qd.any():
            return False
        np.copyto(self.q0, self.q)
        self.t0 = t
        self.mode = MOVE
        return True

    def play(self, player: TrajectoryPlayer, mode: int = REPLAY) -> bool:
        """Play ``player`` (REPLAY or MOVE_TO) from the next update; only from HOLD. The
        trajectory must start at the held position (the caller checks)."""
        if self.mode != HOLD or mode not in PLAYING:
            return False
        self.player = player
        self.mode = mode
        acc = getattr(player, "accel", None)  # a streamed plan's own acceleration limits
        np.copyto(self._play_accel, self.accel if acc is None else acc)
        return True

    def ramp_down(self, accel: np.ndarray | None = None) -> None:
        """Decelerate to standstill, then hold: at the acceleration limits (a mode change,
        stop category 2), or at ``accel`` [rad/s²] (n,) where lower (a starved plan: its own
        limits, which its motion was planned within)."""
        if self.mode == HOLD:
            return
        if accel is None:
            np.copyto(self.ramp_accel, self.accel)
        else:
            np.fmin(accel, self.accel, out=self.ramp_accel)  # fmin: a NaN is no limit
        self.mode = RAMP_DOWN

    def update(self, t: float, dt: float) -> None:
        """Advance the reference to time ``t`` [s] (``dt`` [s] since the last update)."""
        if self.mode == HOLD:
            if not self._still:  # the first tick of a hold: zero qd, qdd once
                self.qd.fill(0.0)
                self.qdd.fill(0.0)
                self.version += 1
                self._still = True
            return
        self.version += 1
        self._still = False
        if self.mode == MOVE:
            assert self.path is not None
            self.path.evaluate(t - self.t0, self.q0, self.q, self.qd, self.qdd)
        elif self.mode == REPLAY or self.mode == MOVE_TO:
            assert self.player is not None
            r = self.player.step(self.q, self.qd, self.qdd)
            if r == 2:  # a streamed plan's next row is not there yet: decelerate, hold
                self.ramp_down(self._play_accel)
                self._ramp(dt)  # from this tick on: a reference standing still for a tick
                # at speed is a following error the position loop answers with a torque kick
            elif r:
                self.mode = HOLD  # the last sample is at rest: hold it
        elif self.mode == RAMP_DOWN:
            self._ramp(dt)
        else:  # DRAG: the reference is the drag controller's (see follow)
            self.qd.fill(0.0)
            self.qdd.fill(0.0)

    def _ramp(self, dt: float) -> None:
        """One tick of the ramp to standstill at ``ramp_accel``; then hold."""
        if self._ramp_step(self.ramp_accel, dt, self.q, self.qd, self.qdd):
            self.mode = HOLD
