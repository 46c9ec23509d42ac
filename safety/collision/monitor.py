"""The collision monitor: levels × phases × observer rows, one implementation for the loop,
flight-log replay and recordings (see safety/collision/__init__.py for the rules)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np

from hofto_hw import jit
from safety.collision import params as P
from safety.collision.kernel import features_step, monitor_step, monitor_tick
from safety.collision.params import MonitorParams
from safety.collision.state import (
    COLLIDED,
    CONTACT,
    F_ACCEL,
    F_MOVING,
    F_REVERSAL,
    F_STILL,
    NONFINITE,
    MonitorState,
    flags_of,
)
from safety.stop import EventKind, Fault, StopController

Backend = Literal["python", "numba", "auto"]


class CollisionLevels:
    """Contact and collision levels (or one collision level) over k observer rows.

    Build with :meth:`from_config` (the loop's ``safety.collision``), :meth:`from_params`
    (e.g. :func:`safety.collision.params.from_thresholds`), or ``CollisionLevels(cfg, rows,
    model, backend=...)`` (= from_config). One implementation (safety/collision/kernel.py);
    ``backend`` says how it runs: ``numba`` compiled (RuntimeError when unavailable),
    ``python`` the kernel's own Python source run by the interpreter, ``auto`` compiled when
    available, else the Python source (``backend`` then says which runs).

    Public state after :meth:`step`/:meth:`update` (views, valid until the next call):
    ``collision`` / ``contact`` (bool), ``collision_joints`` / ``contact_joints`` (n,) bool
    over the deciding rows (the fused row for ``mean``), ``threshold`` (L, k, n) [N·m],
    ``ratios`` (L, k + 1, n) (row k: the fused mean), ``ratio`` (k, n) / ``contact_ratio``
    (k, n) the collision / contact level's row ratios, ``joints`` (L, k + 1, n) tripped
    joints per level and row, ``first_tick`` (k,) int64 first tick each row tripped the
    collision level (-1 = never), ``accel_phase`` (bool), ``nonfinite`` (n,) bool,
    ``fault_nonfinite`` (bool), ``accel``, ``moving``, ``reversal``, ``still`` (n,) features.
    """

    def __init__(
        self,
        cfg: object,
        rows: Sequence[str],
        model: object | None = None,
        backend: Backend = "auto",
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        p = P.from_levels_config(cfg, rows)
        self._build(p, model, cfg.tool_force, backend, hot)  # type: ignore[attr-defined]

    @staticmethod
    def hot_fields(cfg: object, rows: Sequence[str]) -> dict[str, np.dtype]:
        """The monitor's state (:meth:`MonitorState.hot_fields`) for this config, as fields of
        a caller-owned record (``hot=``)."""
        L, _, k, n = P.from_levels_config(cfg, rows).par.shape
        return MonitorState.hot_fields(L, k, n, P.N_SCAL)

    @classmethod
    def from_config(
        cls,
        cfg: object,
        rows: Sequence[str],
        model: object | None = None,
        backend: Backend = "auto",
    ) -> CollisionLevels:
        """From a CollisionLevelsConfig; ``model`` (RobotModel) only for ``tool_force``."""
        return cls(cfg, rows, model, backend)

    @classmethod
    def from_params(
        cls,
        p: MonitorParams,
        model: object | None = None,
        tool_force: float | None = None,
        backend: Backend = "auto",
    ) -> CollisionLevels:
        self = cls.__new__(cls)
        self._build(p, model, tool_force, backend)
        return self

    def _build(
        self,
        p: MonitorParams,
        model: object | None,
        tool_force: float | None,
        backend: Backend,
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        L, _, k, n = p.par.shape
        self.params = p
        self.levels, self.rows = p.levels, list(p.rows)
        self.L, self.k, self.n = L, k, n
        self.deciding = p.deciding
        self.logic = p.logic
        self.v_rev = float(p.scal[P.S_V_REV])
        self.state = s = MonitorState(L, k, n, P.N_SCAL, hot)
        np.copyto(s.par, p.par)
        np.copyto(s.scal, p.scal)
        np.copyto(s.deciding, p.deciding)
        self._par0 = p.par.copy()  # the configured thresholds (scale_thresholds' reference)
        self.threshold_scale = 1.0
        self.tool_force = tool_force
        self.tool_force_value = 0.0
        self._tool = None
        if tool_force is not None:
            if model is None:
                raise ValueError("safety.collision.tool_force needs the robot model")
            from safety.collision.tool_force import ToolForce

            self._tool = ToolForce(model, int(np.argmax(p.deciding)))
        # public views
        self.threshold = s.lev[:, 0, :k]
        self.ratios = s.lev[:, 1]
        self.ratio = s.lev[L - 1, 1, :k]
        self.contact_ratio = s.lev[0, 1, :k]
        self.thr_collision = s.lev[L - 1, 0, 0]
        self.thr_contact = s.lev[0, 0, 0]
        self.joints = s.joints
        self.collision_joints = s.level_joints[L - 1]
        self.contact_joints = s.level_joints[0]
        self.first_tick = s.first_tick
        self.nonfinite = s.bad[k + 2]
        self.accel = s.feat[F_ACCEL]
        self.moving = s.feat[F_MOVING]
        self.reversal = s.feat[F_REVERSAL]
        self.still = s.feat[F_STILL]
        self._hits = s.hits
        self._contact_level = 0 if L > 1 else -1
        self._was_contact = False
        self._zero_qdd = np.zeros(n)
        self._tick = 0
        self.backend = jit.ready(backend, self._warm)
        #: True exactly when the compiled kernel runs (the fused tick's condition)
        self._use_kernel = self.backend == "numba"
        self._features = jit.compiled_or_python(features_step, self.backend)
        self.reset()

    # ------------------------------------------------------------------ state

    @property
    def collision(self) -> bool:
        return bool(self._hits[self.L - 1])

    @property
    def contact(self) -> bool:
        return self._contact_level >= 0 and bool(self._hits[self._contact_level])

    @property
    def fault_nonfinite(self) -> bool:
        return bool(self._hits[self.L])

    @property
    def accel_phase(self) -> bool:
        return bool(self.state.sst[2])

    def reset(self, qd: np.ndarray | None = None) -> None:
        """Forget all state (after a reset of the stop controller); a finite ``qd`` (n,)
        [rad/s] seeds the acceleration estimate."""
        self.state.reset(self.params.par, qd, self.v_rev)
        self._was_contact = False
        self.tool_force_value = 0.0

    def features(self, qd: np.ndarray, dt: float) -> None:
        """Advance only the threshold features (accel, moving, reversal, still) by dt [s]
        (the tick's own :func:`~safety.collision.kernel.features_step`; calibration reads
        them)."""
        s = self.state
        self._features(s.feat, s.sst, s.bad[self.k + 1], s.scal, qd, dt)

    # ------------------------------------------------------------------ one tick

    def step(
        self, tau_ext: np.ndarray, qd: np.ndarray, qdd_ref: np.ndarray | None, dt: float, tick: int
    ) -> bool:
        """One tick without a stop controller: estimates (k, n) [N·m], velocity (n,) [rad/s],
        reference acceleration (n,) [rad/s²] (None: nominal phase), dt [s], the tick number
        recorded in ``first_tick``. Returns ``collision``."""
        qdd = self._zero_qdd if qdd_ref is None else qdd_ref
        self._run(tau_ext, qd, qdd, dt, tick)
        return bool(self._hits[self.L - 1])

    def update(
        self,
        stop: StopController,
        tau_ext: np.ndarray,
        q: np.ndarray,
        qd: np.ndarray,
        qdd_ref: np.ndarray | None,
        dt: float,
    ) -> int:
        """One loop tick: estimates (k, n) [N·m], measured q, qd, reference acceleration (n,)
        (None: nominal phase), dt [s]. Reports COLLISION (latched by ``stop``), NON_FINITE and
        CONTACT (rising edge) events; returns the tick's flags (safety.collision.state):
        ``COLLIDED`` (the collision level decided), ``CONTACT`` (the contact level decided),
        ``NONFINITE``; 0 on the common path. One compiled call with backend numba."""
        if qdd_ref is None:
            qdd_ref = self._zero_qdd
        f = self._run(tau_ext, qd, qdd_ref, dt, stop.tick)
        if f or self._was_contact:
            self._report(stop, f)
        if self._tool is not None:
            self.tool_force_value = self._tool.check(tau_ext, q)
            if self.tool_force_value > self.tool_force:  # type: ignore[operator]
                stop.report(Fault.COLLISION, -1, self.tool_force_value)
        return f

    def _run(self, tau: np.ndarray, qd: np.ndarray, qdd: np.ndarray, dt: float, tick: int) -> int:
        """The kernel's tick: compiled on the packed state (one call), or monitor_step's
        Python source on the state's own views (no view made per tick); returns the flags."""
        s = self.state
        if self._use_kernel:
            return monitor_tick(s.fbuf, s.bbuf, s.first_tick, tau, qd, qdd, dt, tick)
        _python_step(
            s.par, s.scal, s.deciding, s.feat, s.sst, s.lev, s.joints, s.bad, s.row_hit,
            s.level_joints, s.hits, s.first_tick, tau, qd, qdd, dt, tick,
        )  # fmt: skip
        return flags_of(s.hits)

    def _report(self, stop: StopController, flags: int) -> None:
        """Something happened (``flags`` of :meth:`update`): tell the stop controller
        (Python, off the common path)."""
        if flags & NONFINITE:
            j = int(np.argmax(self.nonfinite))
            stop.report(Fault.NON_FINITE, j, float("nan"))
        if flags & COLLIDED:
            j = int(np.argmax(self.collision_joints))
            stop.report(Fault.COLLISION, j, self._max_ratio(self.L - 1, j))
        if self._contact_level >= 0:
            contact = flags & CONTACT != 0
            if contact and not self._was_contact:
                j = int(np.argmax(self.contact_joints))
                stop.note(EventKind.CONTACT, j, self._max_ratio(0, j))
            self._was_contact = contact

    def _max_ratio(self, lv: int, j: int) -> float:
        r = self.state.lev[lv, 1]
        if self.logic == "mean":
            return float(r[self.k, j])
        best = 0.0
        for i in range(self.k):
            if self.deciding[i] and r[i, j] > best:
                best = float(r[i, j])
        return best

    def scale_thresholds(self, factor: float) -> None:
        """Every threshold term of every level, row and joint = the configured one ·
        ``factor`` (a safety profile; both paths, in place: no allocation, the arrays the
        fused tick addresses stay the same)."""
        np.multiply(self._par0, factor, out=self.params.par)
        np.copyto(self.state.par, self.params.par)
        self.threshold_scale = factor

    def _warm(self) -> None:
        """Compile the kernel on scratch state (the real state stays untouched)."""
        p = self.params
        L, _, k, n = p.par.shape
        s = MonitorState(L, k, n, P.N_SCAL)
        np.copyto(s.par, p.par)
        np.copyto(s.scal, p.scal)
        np.copyto(s.deciding, p.deciding)
        z = np.zeros(n)
        monitor_tick(s.fbuf, s.bbuf, s.first_tick, np.zeros((k, n)), z, z, 1e-3, 0)


_python_step = getattr(monitor_step, "py_func", monitor_step)
