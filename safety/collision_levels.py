"""Two-level collision detection for the real-time loop (contact and collision).

Per joint j and observer row k, with r = |tau_ext_hat[k, j]| / thr_j:

    thr_j(level) = level.<phase>_j + velocity_gain_j·|qd_j|

``phase`` is ``acceleration`` while any joint's reference acceleration exceeds
``acceleration_phase`` (and ``phase_hold`` seconds after), else ``nominal`` (Franka's two
threshold sets). A level trips on a joint after r > 1 for ``debounce_time`` and releases
after r < ``release_ratio`` for ``release_time`` (hysteresis), so both levels clear
themselves; the StopController latches the collision stop.

Rows of the estimate array are observers (e.g. hofto, momentum). The ``deciding`` rows give
the decision (``any``: a row trips; ``all``: every deciding row trips). Every row keeps its
own first-crossing tick so detection delays can be compared side by side.

A NaN estimate never trips nor poisons state (no filters here; the limit monitor reports it
as NON_FINITE); an infinite one is above every threshold and trips. Allocation-free, except
the optional tool-force check (pinocchio Jacobian).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from safety.stop import EventKind, Fault, StopController


class CollisionLevels:
    """See the module docstring. ``cfg`` is a CollisionLevelsConfig; ``rows`` names the rows
    of the estimate array passed to :meth:`update`.

    Public state after :meth:`update`: ``collision`` / ``contact`` (bool), ``collision_joints``
    / ``contact_joints`` (n,) bool over the deciding rows, ``ratio`` (k, n) collision ratios,
    ``first_tick`` (k,) int64 first tick each row tripped the collision level (-1 = never),
    ``accel_phase`` (bool).
    """

    def __init__(self, cfg: object, rows: Sequence[str], model: object | None = None) -> None:
        c = cfg
        n = len(c.collision.nominal)  # type: ignore[attr-defined]
        k = len(rows)
        self.n, self.k = n, k
        self.rows = list(rows)
        choice = c.observer  # type: ignore[attr-defined]
        wanted = ["hofto", "momentum"] if choice == "both" else [choice]
        missing = [w for w in wanted if w not in self.rows]
        if missing:
            raise ValueError(f"safety.collision.observer needs estimates from {missing}")
        self.deciding = np.array([w in wanted for w in self.rows])
        self.require_all = c.logic == "all"  # type: ignore[attr-defined]
        self.levels = {
            "contact": (
                np.asarray(c.contact.nominal, float),  # type: ignore[attr-defined]
                np.asarray(c.contact.acceleration, float),  # type: ignore[attr-defined]
            ),
            "collision": (
                np.asarray(c.collision.nominal, float),  # type: ignore[attr-defined]
                np.asarray(c.collision.acceleration, float),  # type: ignore[attr-defined]
            ),
        }
        vg = c.velocity_gain  # type: ignore[attr-defined]
        self.kv = np.zeros(n) if vg is None else np.asarray(vg, float)
        self.accel_level = float(c.acceleration_phase)  # type: ignore[attr-defined]
        self.phase_hold = float(c.phase_hold)  # type: ignore[attr-defined]
        self.trip_after = max(c.debounce_time - 1e-9, 0.0)  # type: ignore[attr-defined]
        self.release_after = max(c.release_time - 1e-9, 1e-12)  # type: ignore[attr-defined]
        self.release_ratio = float(c.release_ratio)  # type: ignore[attr-defined]
        self.tool_force = c.tool_force  # type: ignore[attr-defined]
        self.data = model.create_data() if model is not None else None
        if self.tool_force is not None and model is None:
            raise ValueError("safety.collision.tool_force needs the robot model")
        self.thr_contact = np.zeros(n)
        self.thr_collision = np.zeros(n)
        self.ratio = np.zeros((k, n))
        self.contact_ratio = np.zeros((k, n))
        self._state = {name: _Level(k, n) for name in ("contact", "collision")}
        self.first_tick = np.full(k, -1, dtype=np.int64)
        self.collision = False
        self.contact = False
        self.collision_joints = np.zeros(n, dtype=bool)
        self.contact_joints = np.zeros(n, dtype=bool)
        self.accel_phase = False
        self.tool_force_value = 0.0
        self._phase_left = 0.0
        self._tmp = np.zeros(n)
        self._row = np.zeros(k, dtype=bool)
        self._was_contact = False

    def reset(self) -> None:
        """Forget all state (after a reset of the stop controller)."""
        for lv in self._state.values():
            lv.reset()
        self.first_tick.fill(-1)
        self.collision = self.contact = self._was_contact = False
        self.collision_joints.fill(False)
        self.contact_joints.fill(False)
        self._phase_left = 0.0

    def _thresholds(self, qd: np.ndarray) -> None:
        phase = 1 if self.accel_phase else 0
        np.abs(qd, out=self._tmp)
        self._tmp *= self.kv
        np.add(self.levels["contact"][phase], self._tmp, out=self.thr_contact)
        np.add(self.levels["collision"][phase], self._tmp, out=self.thr_collision)

    def update(
        self,
        stop: StopController,
        tau_ext: np.ndarray,
        q: np.ndarray,
        qd: np.ndarray,
        qdd_ref: np.ndarray,
        dt: float,
    ) -> bool:
        """One tick: estimates (k, n) [N·m], measured q, qd, reference acceleration (n,),
        dt [s]. Reports COLLISION (latched by ``stop``) and CONTACT events; returns
        ``collision``."""
        np.abs(qdd_ref, out=self._tmp)
        if self._tmp.max() > self.accel_level:
            self._phase_left = self.phase_hold
        else:
            self._phase_left -= dt
        self.accel_phase = self._phase_left > 0.0
        self._thresholds(qd)
        np.abs(tau_ext, out=self.ratio)
        np.copyto(self.contact_ratio, self.ratio)
        self.ratio /= self.thr_collision
        self.contact_ratio /= self.thr_contact
        col = self._state["collision"]
        col.step(self.ratio, self.trip_after, self.release_after, self.release_ratio, dt)
        con = self._state["contact"]
        con.step(self.contact_ratio, self.trip_after, self.release_after, self.release_ratio, dt)
        # first crossing per row (side-by-side delays), then the decision over deciding rows
        col.joints.any(axis=1, out=self._row)
        for r in range(self.k):
            if self._row[r] and self.first_tick[r] < 0:
                self.first_tick[r] = stop.tick
        self.collision = _decide(self._row, self.deciding, self.require_all)
        _rows_or(col.joints, self.deciding, self.collision_joints)
        if self.collision:
            j = int(np.argmax(self.collision_joints))
            stop.report(Fault.COLLISION, j, float(self._max_ratio(j)))
        con.joints.any(axis=1, out=self._row)
        self.contact = _decide(self._row, self.deciding, self.require_all)
        _rows_or(con.joints, self.deciding, self.contact_joints)
        if self.contact and not self._was_contact:
            j = int(np.argmax(self.contact_joints))
            stop.note(EventKind.CONTACT, j, float(self.contact_ratio[:, j].max()))
        self._was_contact = self.contact
        if self.tool_force is not None:
            self._check_tool_force(stop, tau_ext, q)
        return self.collision

    def _max_ratio(self, j: int) -> float:
        best = 0.0
        for r in range(self.k):
            if self.deciding[r] and self.ratio[r, j] > best:
                best = float(self.ratio[r, j])
        return best

    def _check_tool_force(self, stop: StopController, tau_ext: np.ndarray, q: np.ndarray) -> None:
        """|F| at the tool from F = (Jᵀ)⁺·tau_ext of the first deciding row (allocates)."""
        r = int(np.argmax(self.deciding))
        jac = self.data.tool_jacobian(q)[:3]  # type: ignore[union-attr]
        force = np.linalg.lstsq(jac.T, tau_ext[r], rcond=1e-3)[0]
        self.tool_force_value = float(np.linalg.norm(force))
        if self.tool_force_value > self.tool_force:
            stop.report(Fault.COLLISION, -1, self.tool_force_value)


class _Level:
    """Debounce and hysteresis state of one level, (k, n)."""

    def __init__(self, k: int, n: int) -> None:
        self.joints = np.zeros((k, n), dtype=bool)
        self.above = np.zeros((k, n))
        self.below = np.zeros((k, n))
        self._m = np.zeros((k, n), dtype=bool)

    def reset(self) -> None:
        self.joints.fill(False)
        self.above.fill(0.0)
        self.below.fill(0.0)

    def step(
        self, ratio: np.ndarray, trip_after: float, release_after: float, release: float, dt: float
    ) -> None:
        m = self._m
        np.greater(ratio, 1.0, out=m)
        self.above += dt
        self.above *= m
        np.less(ratio, release, out=m)
        self.below += dt
        self.below *= m
        np.greater(self.above, trip_after, out=m)  # dt > 0 so one tick above trips at 0
        np.logical_or(self.joints, m, out=self.joints)
        np.greater_equal(self.below, release_after, out=m)
        np.logical_not(m, out=m)
        np.logical_and(self.joints, m, out=self.joints)


def _decide(rows: np.ndarray, deciding: np.ndarray, require_all: bool) -> bool:
    hit = False
    for r in range(rows.shape[0]):
        if not deciding[r]:
            continue
        if rows[r]:
            hit = True
        elif require_all:
            return False
    return hit


def _rows_or(joints: np.ndarray, deciding: np.ndarray, out: np.ndarray) -> None:
    out.fill(False)
    for r in range(joints.shape[0]):
        if deciding[r]:
            np.logical_or(out, joints[r], out=out)
