"""One control tick, top to bottom (hot path: no allocation, no formatting, no I/O):

exchange -> joint state (SI) -> dynamics snapshot -> observers -> safety -> controller ->
command -> record.

The dynamics snapshot (:class:`~hofto_hw.model.snapshot.DynamicsSnapshot`, built by the
composition root for the union of the observers' ``needs``) is computed once per tick; the
observers read it through one :class:`~hofto_hw.observers.bank.ObserverBank` (one compiled
call for every observer it can fuse, each estimate written into its row of ``tau_ext``; the
same numbers as each observer's own ``update``, which replay and the demo use).

Sections 1-3 (the read, the snapshot and the observers, a lost sample or a stall included)
and section 4 (the safety checks, the collision monitor, the friction learning) run as ONE
compiled call on every tick (:mod:`hofto_hw.runtime.fused`: the one place their arithmetic
and their order live); the checks report into a fault array that :meth:`Tick._report_faults`
turns into the stop controller's reports in the order they ran. The steps before section 4
that have no compiled form (the drag's front, a homing step, the tool force) run between
section 3 and a second compiled call of section 4; the drive scan's finding is named in
Python (STO, brake) and section 4 resumes. Sections 5-7 (the demo path, the feed-forward,
the command, the record fill) are sequenced once too (``fused.section57``): on a quiet tick
(nothing rare can happen: :attr:`Tick.busy` is 0 and no request, fault or bad status came
in) on which section 4 found nothing the fused call goes on into them. When it stops early
it answers a stage and the methods below finish the same tick from there: they handle what
is rare (reports, events, stop decisions, requests, reset, mode changes, enabling, brake
release, drag, homing, teach; :meth:`Tick._decide` writes the motion's reference and says
which steps of sections 5-7 the tick takes), then the tick calls ``fused.section57``
itself. A configuration the compiled call cannot run is refused when the tick is built, in
one line. The Python reference that runs every stage on every tick is
tests/support/reference_tick.py; tests/hofto_hw/runtime/test_fused.py checks both tick by
tick, bit for bit.

The :class:`Tick` owns every buffer it writes; the loop (hofto_hw/runtime/loop.py) calls
:meth:`Tick.step` once per cycle with the real dt. Requests from other threads (stop, reset,
mode) are plain attributes the tick reads: one writer each, no locks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import State
from hofto_hw import jit
from hofto_hw.control.drag import DragController
from hofto_hw.control.enabling import EnableInput
from hofto_hw.control.joint_motion import DRAG, HOLD, JointMotion
from hofto_hw.errors import ConfigError
from hofto_hw.jit import Backend
from hofto_hw.model.data import ModelData
from hofto_hw.model.snapshot import DynamicsSnapshot
from hofto_hw.observers.bank import ObserverBank
from hofto_hw.observers.base import Observer
from hofto_hw.recording.record import (
    DIAG_DTYPE,
    EVENT_DTYPE,
    RecordSink,
    new_record,
    tick_dtype,
)
from hofto_hw.runtime.fused import (
    BUS,
    DONE,
    HOLD_STILL,
    K_MONITOR,
    K_TOOL,
    MOVE_PATH,
    OTHER,
    S_FF,
    S_OFF,
    S_PATH,
    SAFETY,
    FusedTick,
    fused_tick,
    section4,
    section57,
    tick_state_dtype,
)
from hofto_hw.runtime.tick_events import MAX_STOPS, STANDSTILL, TickEvents
from safety.bus_health import BusHealth
from safety.collision import CollisionLevels
from safety.limits import LimitMonitor
from safety.stop import NO_CATEGORY, Fault, StopController

__all__ = ["STANDSTILL", "Tick"]

_OE = int(State.OPERATION_ENABLED)
_QSA = int(State.QUICK_STOP_ACTIVE)
_FRA = int(State.FAULT_REACTION_ACTIVE)

#: :attr:`Tick.busy` bits: a rare state that keeps the next tick off the quiet path (the
#: compiled call stops after section 3 and the stages finish the tick). Computed in one place
#: (:meth:`Tick._busy`) whenever the stages ran or something changed between ticks
BUSY_STOP = 1  # a fault latched, a stop category commanded, or the stop being measured
BUSY_ENABLING = 2  # enabling (the brake release check included) or fault-reset edges
BUSY_HOMING = 4  # a homing run by the loop
BUSY_DRAG = 8  # drag mode, its stop reason to report or its wrench to clear
BUSY_TEACH = 16  # a recording or a playback
BUSY_NONFINITE = 32  # the last sample was not finite
BUSY_REFERENCE = 64  # the feed-forward to evaluate again (a new reference or a new model)
BUSY_TOOL_FORCE = 128  # the collision monitor's tool-force check (no compiled form)
#: the rare states whose steps come before section 4 and are Python's (Tick._pre_safety)
_PRE = BUSY_HOMING | BUSY_DRAG | BUSY_TOOL_FORCE


class Tick(TickEvents):
    """See the module docstring. ``observers`` are evaluated in order; their estimates are
    rows of ``tau_ext`` (k, n) and of the tick record. ``snapshot`` is computed for at least
    every observer's ``needs`` (:func:`hofto_hw.runtime.compose.shared_snapshot`)."""

    def __init__(
        self,
        group: DriveGroup,
        observers: Sequence[Observer],
        snapshot: DynamicsSnapshot,
        stop: StopController,
        limits: LimitMonitor,
        bus: BusHealth,
        collision: CollisionLevels | None,
        motion: JointMotion,
        feedforward: ModelData,
        sink: RecordSink,
        overrun_limit: int = 20,
        drag: DragController | None = None,
        enable_input: EnableInput | None = None,
        drag_row: int = 0,
        period: float = 0.0,
        backend: Backend = "auto",
        hot: np.ndarray | None = None,
    ) -> None:
        n = group.n
        self.n = n
        self.group = group
        self.observers = list(observers)
        self.names = [o.name for o in self.observers]
        missing = [o.name for o in self.observers if o.needs & ~snapshot.needs]
        if missing:
            raise ValueError(f"the tick's snapshot lacks terms observers {missing} need")
        self.snapshot = snapshot
        self.stop = stop
        self.limits = limits
        self.bus = bus
        self.collision = collision
        self.motion = motion
        self.feedforward = feedforward
        self.sink = sink
        self.overrun_limit = int(overrun_limit)
        #: ticks the collision monitor stays blind after a (re)start of the observers or an
        #: enable (safety.collision.settle_time); the tick it judges again
        self.settle_ticks = 0
        self._judge_from = 0
        self.tick = 0
        self.t = 0.0
        #: nominal cycle [s] (0: unknown, every dt taken as one cycle). After a stall the
        #: observers integrate the gap in steps of one cycle (:meth:`_observe`), the setpoint
        #: time advances one cycle per tick (an interpolator that missed cycles is late, it
        #: does not jump), and the jump check allows for the gap
        self.period = float(period)
        self._stall_dt = 1.5 * self.period if self.period > 0.0 else math.inf  # see gap_steps
        #: the hot record the parts were built on (fused.hot_record, by runtime.compose.build;
        #: None: the compiled call refuses the tick)
        self.hot = hot
        #: the tick's state (fused.tick_state_dtype): the scalars both paths read and write
        #: (``st["t_cmd"]``, ``st["sample_dt"]``, ...) and the arrays below, as one record
        rows = max(1, len(self.observers))
        self.state = np.zeros(1, tick_state_dtype(n, rows)) if hot is None else hot["tick_state"]
        self.st = self.state[0]  # its fields by name (a view)
        self.st["stall"], self.st["two"] = self._stall_dt, 2.0
        self.st["period"] = self.period
        self._prev = self.state["prev"][0]  # last tick's q, qd, tau (interpolation start)
        self.tau_ext = self.state["tau_ext"][0]
        self._bank = ObserverBank(self.observers, snapshot, self.tau_ext)  # row i: observer i
        self.tau_ff = self.state["tau_ff"][0]
        self._tau_off = self.state["tau_off"][0]  # the hand's torque (dragging) [N·m]
        #: the motion's version that tau_ff was evaluated for (-1: evaluate on the next tick),
        #: and the model's revision, friction and payload objects it was evaluated with
        self._ff_version = -1
        m = feedforward.model
        self._ff_model = (m.revision, m.friction, m.payload)
        self.q_sent = self.state["q_sent"][0]  # position target of the last command [rad]
        self.err_codes = group.transport.tx["error_code"]
        self._transport = group.transport  # its sample_dt (DriveGroup.sample_dt forwards it)
        self.controlword = group.transport.rx["controlword"]
        self.expect_enabled = False
        self.enabling = False
        #: the brake release check the loop repeats on every re-enable (set by compose;
        #: None: no braked axis); its progress; ticks spent enabling; STO scratch
        self.release_check: Any = None
        #: the reset refusal of an arm whose brake the master opens by 0x60FE (compose; ""
        #: none): the tick cannot set that bit again, so no reset powers such an arm up
        self.reenable_refused = ""
        self._released = True
        self._release_running = 0
        self._enable_ticks = 0
        self._sto_seen = np.zeros(n, dtype=bool)
        self.overrun_streak = 0
        self.overruns = 0
        # requests from other threads (one writer each)
        self.stop_requested = False  # operator stop or SIGTERM: a STOP_REQUEST fault
        self.log_failure = False  # the flight recorder is failing (runtime/log_watch.py)
        self.log_failure_value = 0.0  # records dropped + lost so far
        self.exit_requested = False  # SIGTERM/SIGINT: the process ends once stopped
        self.reset_requested = False
        self.reset_result = ""
        self.mode_request = -1
        #: homing run by the loop (hofto_hw/runtime/homing_run.py), set by the control plane's
        #: port through start_homing, None when none runs
        self.homing: Any = None
        self._fault_resetting = 0
        self._edges_tried = False
        # stop episodes: first tick, time and distance to standstill
        self.stop_tick = np.full(MAX_STOPS, -1, dtype=np.int64)
        self.stop_time = np.full(MAX_STOPS, np.nan)
        self.stop_distance = np.full(MAX_STOPS, np.nan)
        self.n_stops = 0
        self._measuring = False
        self._t_detect = 0.0
        self._q_detect = np.zeros(n)
        self._d = np.zeros(n)
        self._cw = np.zeros(n, dtype=np.uint16)
        # records (preallocated; field views fetched once)
        self.tick_rec = new_record(tick_dtype(n, len(self.observers)))
        self.event_rec = new_record(EVENT_DTYPE)
        self.diag_rec = new_record(DIAG_DTYPE)
        self.diag_every = 100  # ticks between diagnostics records (10 Hz at 1 kHz)
        #: percentiles for the diagnostics record, written by a slow-path thread (µs)
        self.wakeup_p99_us = 0.0
        self.compute_p99_us = 0.0
        r = self.tick_rec
        r["wrench"][...] = np.nan
        self._events_pushed = 0
        self._events = stop.events  # the stop controller's event log (never replaced)
        self._rec1 = r.reshape(1)  # the same memory as a one-element array, for the kernel
        # drag (hand guiding): controller, enabling input, the observer row that drives it
        self.drag = drag
        self.enable_input = enable_input if enable_input is not None else EnableInput()
        self._din = group.transport.tx["digital_inputs"]
        self.drag_row = int(drag_row)
        #: the drag's friction learning outside drag mode (None: no drag or no learning)
        self._learn = drag.learn if drag is not None else None
        self.drag_reason = 0
        self.mode_result = ""  # answer to the last mode request (constant strings)
        # teach and play (hofto_hw/runtime/teach.py; planned and saved off the tick): the
        # control thread sets a request before mode_request, the tick takes it on entry
        self.record_request = None  # Recording for the next drag request (or None)
        self.recording = None  # the Recording of the drag mode entered with it
        self.play_request = None  # Playback for the next REPLAY/MOVE_TO request
        self.playback = None  # the last Playback started (the summary's replay figures)
        self.script = None  # simulation script: .step(tick) at the start of every tick
        self._tau_mon = self.state["tau_mon"][0]  # the collision monitor's input (dragging)
        self._wrench = r["wrench"]
        self._wrench_set = False  # the record's wrench holds a drag estimate (else all NaN)
        #: the kernels' backend (the compiled calls below compile and warm every kernel;
        #: python: the tick is refused)
        self.backend = jit.resolve(backend)
        #: first collision-level crossing per observer row over the whole run (the monitor's
        #: own first_tick is cleared by a reset) [tick, -1 = none]
        self.first_detect = np.full(len(self.observers), -1, dtype=np.int64)
        # sections 1-4 of every tick, and the rest of a quiet one, as one compiled call
        # (fused.py) on the hot record the parts were built on; a configuration it cannot run
        # is refused here, in one line
        self.busy = 0  # BUSY_* bits: the rare states now (0: the next tick may be quiet)
        self._fz_kind = OTHER
        self.fused_ticks = 0  # ticks the fused call finished
        self._fz_call = fused_tick
        self._s4_call = section4  # section 4 alone (after a pre-safety step, the scan's find)
        self._s57_call = section57  # sections 5-7 after the Python stages (not quiet)
        self._fz = FusedTick(self)
        if not self._fz.ok:
            raise ConfigError(f"the tick cannot run compiled: {self._fz.why}")
        self._fz_args: tuple[Any, ...] = self._fz.args()
        self._slow: tuple[Any, ...] = ()  # the state's slow scalars as _sync_slow last wrote them

    # --------------------------------------------------------------- start-up

    def start(self) -> None:
        """After the drives are enabled: hold the measured position, reset every estimator."""
        g = self.group
        g.cycle()
        self.motion.start(g.q)
        np.copyto(self.q_sent, g.q)
        self.snapshot.reset_memory()
        np.copyto(self._prev, g.sample)  # the interpolation start of a first stall
        for obs in self.observers:
            obs.reset(g.q, g.qd)
        self._check_bank()
        self.limits.reset(g.q)
        if self.collision is not None:
            self.collision.reset()
        self.expect_enabled = g.all_in(State.OPERATION_ENABLED)
        self._judge_from = self.tick + 1 + self.settle_ticks
        self._refresh()

    # ------------------------------------------------------------------ the tick

    def step(self, t: float, dt: float, wakeup_us: float, missed: int, compute_us: float) -> None:
        """One cycle at loop time ``t`` [s], ``dt`` [s] since the last tick (the real one after a
        stall), ``missed`` deadlines before this tick, timings of the loop [µs].

        Sections 1-4 run as one compiled call (:mod:`hofto_hw.runtime.fused`), and on a quiet
        tick 5-7 too (the same kernels in the same order); it answers the stage where these
        methods take over for the rest of the tick (what is rare)."""
        stop = self.stop
        self.tick += 1
        self.t = t
        stop.begin_tick(self.tick)
        if self.script is not None:
            self.script.step(self)  # may change anything: the rare states again
            self._refresh(rebuild=False)
        if self._model_moved():
            self._follow_model()  # rare: the native models and the call's arguments first

        # 1. exchange
        status = self.group.exchange()
        # missed deadlines keep a tick quiet while the overrun streak stays short of its fault
        # (counted in _requests, or after the call on a finished tick)
        quiet = self.busy == 0 and not (
            status or stop.active or self.stop_requested or self.log_failure
            or self.reset_requested or self.mode_request >= 0
            or self.overrun_streak + missed >= self.overrun_limit
        )  # fmt: skip
        if quiet:
            self.bus.streak = 0  # good data (what BusHealth.count does on it)
        else:
            self._inputs(status)  # what section 4 reads of the Python state
        # 2. joint state, 3. snapshot and observers, 4. safety (unless a pre-safety step is
        # Python's); on a quiet tick 5-7 (fused.py). It keeps t_cmd, sample_dt, since_fresh
        # and the sample's finiteness in the tick's state; its other scalars _refresh keeps
        stage = self._fz_call(
            *self._fz_args, self.t, dt, self._transport.sample_dt, self.tick, wakeup_us,
            compute_us, quiet,
        )  # fmt: skip
        if stage == DONE:  # the quiet tick: its few attribute updates inline (it is hot)
            if self._fz_kind == MOVE_PATH:  # the path wrote the reference
                motion = self.motion
                motion.version += 1
                self._ff_version = motion.version
            self.fused_ticks += 1
            if missed or self.overrun_streak:
                self._overrun(missed)  # counted only: the streak stays short of its fault
            self._push()  # 7. the record (filled by the fused call) into the sink
            return
        self.snapshot.finite = bool(self.st["finite"])
        if stage == SAFETY:
            stage = self._pre_safety(dt)  # 3b. drag, homing, tool force; then 4. (compiled)
        while stage == BUS:
            self._bus_found()  # the axis the drive scan found: its fault named, then 4. on
            stage = self._s4_call(self._fz_args[0], self._rec1, self.tick, dt, True)
        self._report_faults()  # 4. what the checks found, as reports, in their order
        self._requests(missed)  # 4 (end): overruns, requests, reset, stop measurement
        what = self._decide()  # 5-6: what is rare (the stop category's commands, ...)
        # 5-7 compiled: the demo path, the feed-forward, the command, the record's fill
        self._s57_call(
            self._fz_args[0], self._fz_args[3], self._rec1, self.t, self.tick, what,
            self.motion.mode, self.stop.latched, int(status), float(wakeup_us),
            float(compute_us),
        )  # fmt: skip
        self._push()  # 7. the record into the sink
        self._refresh()

    # ------------------------------------------------------------ the tick's stages

    def _drag_front(self) -> None:
        """Section 3b, drag: wrench estimate, enabling input, off-tool check (its stop
        requests are safety's to latch below); the reference it integrates is used in
        section 5."""
        if self.motion.mode == DRAG:
            g = self.group
            self._drag_observe(g.q, g.qd, float(self.st["cmd_dt"]))
        elif self._wrench_set:
            self._wrench.fill(np.nan)
            self._wrench_set = False

    def _inputs(self, status: int) -> None:
        """A tick that is not quiet, before the compiled call: what section 4 reads of the
        Python state (:data:`~hofto_hw.runtime.fused.tick_state_dtype`'s inputs): the bus's
        good data and loss streak (counted here, once per tick), whether a pre-safety step
        runs, and :meth:`_state_in`."""
        st = self.st
        good = status == 0 and self.group.fresh
        st["good"], st["status"] = good, status
        st["bus_loss"] = self.bus.count(good)
        st["pre"] = self.busy & _PRE != 0
        self._state_in()

    def _state_in(self) -> None:
        """The stop's state (latched, active, category: section 4 keeps its copies as its
        findings change them) and the tick's that section 4 reads; again after a pre-safety
        step or a report Python made (the drive scan's)."""
        st, stop = self.st, self.stop
        st["s_latched"], st["s_active"], st["s_cat"] = stop.latched, stop.active, stop.category
        st["enabling"], st["homing"] = self.enabling, self.homing is not None
        self._sync_slow()

    def _pre_safety(self, dt: float) -> int:
        """Section 3b and the steps before section 4 that have no compiled form (rare): the
        drag's front, a homing run's step (before the limit checks), the monitor's input while
        dragging and the tool-force check; then section 4 as the second compiled call."""
        self._drag_front()
        self._homing_step()
        st, c = self.st, self.collision
        est = self._monitored(True) if self.motion.mode == DRAG else self.tau_ext
        st["use_mon"] = est is not self.tau_ext  # then it is _tau_mon (tau_mon's field)
        if c is not None and c._tool is not None:
            st["tool_value"] = c._tool.check(est, self.group.q)
        self._state_in()
        return self._s4_call(self._fz_args[0], self._rec1, self.tick, dt, False)

    def _homing_step(self) -> None:
        """A homing run's step, before the limit checks; its end restarts the estimates."""
        if self.homing is not None and self.homing.step(self):
            self.homing = None
            self.restart_estimates()

    def _bus_found(self) -> None:
        """The drive scan found an axis faulted (j < n) or out of Operation enabled: its fault
        named by the bus (STO, brake fault: the drive layer's readings) and reported."""
        self.bus.report_found(self.stop, int(self.st["scan_j"]), self.err_codes, self.group.states)
        self._state_in()

    def _report_faults(self) -> None:
        """Section 4's fault array as stop.report calls, in the order the checks ran (the
        events, latch ticks and categories the checks' own reports would give)."""
        st, stop = self.st, self.stop
        for i in range(int(st["nf"])):
            kind, j, v = int(st["fk"][i]), int(st["fj"][i]), float(st["fv"][i])
            if kind == K_MONITOR:
                self.collision._report(stop, j)  # type: ignore[union-attr]
            elif kind == K_TOOL:
                c = self.collision
                c.tool_force_value = v  # type: ignore[union-attr]
                if v > c.tool_force:  # type: ignore[union-attr,operator]
                    stop.report(Fault.COLLISION, -1, v)
            else:
                stop.report(kind, j, v)
        st["nf"] = 0

    def _requests(self, missed: int) -> None:
        """The end of section 4: overruns, requests from other threads, the stop's timing."""
        stop = self.stop
        if missed or self.overrun_streak:
            self._overrun(missed)
        if self.stop_requested:
            stop.report(Fault.STOP_REQUEST)
        if self.log_failure:
            stop.report(Fault.LOG_FAILURE, -1, self.log_failure_value)
        if self.drag_reason:
            self._drag_report()
        if self.reset_requested:
            self._reset()
        if self._measuring or stop.first_tick == self.tick:
            self._measure_stop(self.group.q, self.group.qd)

    def _decide(self) -> int:
        """Sections 5 (controller) and 6 (command, acting the stop category): what is rare,
        in Python (the stop category's drive commands, mode changes, enabling, the drag's
        follow, playback, the ramp, teach recording), writing the motion's reference; returns
        the steps of sections 5-7 (:func:`~hofto_hw.runtime.fused.section57`'s ``what``: the
        demo path, the feed-forward, the hand's torque) that this tick takes. The tick runs
        them compiled; tests/support/reference_tick.py runs them in Python."""
        g, stop, motion = self.group, self.stop, self.motion
        q, qd = g.q, g.qd
        what = 0
        cat = stop.category
        if cat == 0 or cat == 1:
            self.expect_enabled = False
            self.enabling = False
            if cat == 0:
                g.command_disable_voltage()
            else:
                g.command_quick_stop()
            if self._fault_resetting > 0:
                self._fault_reset_edge()
            motion.start(q)  # targets follow the arm: bumpless when enabled again
            if self.mode_request >= 0:
                self._refuse_mode()
        else:
            if cat == 2:
                motion.ramp_down()
                if self.mode_request >= 0:
                    self._refuse_mode()
            elif self.mode_request >= 0:
                self._change_mode(qd)
            if self.enabling:
                self._enable_step()
            if motion.mode == DRAG:
                d = self.drag
                motion.follow(d.q_cmd, d.qd_cmd, d.qdd_cmd)
            elif self._fz.moves(motion):
                motion.version += 1  # JointMotion.update's, the path in the compiled call
                motion._still = False
                self.st["t0"] = motion.t0  # a move started this tick: _refresh has not
                what = S_PATH
            else:
                motion.update(float(self.st["t_cmd"]), float(self.st["cmd_dt"]))
        if self.recording is not None or self.playback is not None:
            self._teach_record(q)
        # the feed-forward is a function of the reference (and the model): a hold reuses it
        if self._ff_model_changed():
            self._follow_model()  # its native model synced, the call's handle with it
            what |= S_FF
        elif motion.version != self._ff_version:
            what |= S_FF
        self._ff_version = motion.version
        if motion.mode == DRAG:
            np.copyto(self._tau_off, self.drag.tau_offset)  # the hand's torque, added to it
            what |= S_OFF
            self._ff_version = -1  # tau_ff holds the hand's torque: evaluate it again
        return what

    # ----------------------------------------------------------- the fused call

    def _follow_model(self) -> None:
        """The model changed since tau_ff was evaluated (rare): the snapshot's and the
        feed-forward's workspaces follow it now, before the compiled call reads them, and the
        call gets the native handles they hold now. The tick is not quiet (BUSY_REFERENCE):
        its stages evaluate tau_ff."""
        self.snapshot.follow_model()
        self.feedforward.follow_model()
        self._refresh()

    def _refresh(self, rebuild: bool = True) -> None:
        """After a tick the stages finished, at start, after a model change and a script's
        step: the rare states (:attr:`busy`), the call's arguments when something they are
        made of changed (:meth:`FusedTick.stale`; not looked at after a script's step,
        ``rebuild`` False) and the state's slow scalars (off the common path)."""
        fz = self._fz
        new_bank = self._fz_args[1] is not self._bank.args  # a reset built one: checked again
        why = "a part replaced its hot record's array" if not fz.bound() else ""
        why = why or (fz._check(self) if new_bank else "")
        if why:
            raise RuntimeError(f"the tick's compiled call cannot take its parts: {why}")
        if new_bank or (rebuild and fz.stale()):  # a drag tick: every tick, rarely stale
            self._fz_args = fz.args()
        self.busy = self._busy()
        m = self.motion
        if m.mode == HOLD and m._still:
            kind = HOLD_STILL
        elif fz.moves(m):
            kind = MOVE_PATH
        else:
            kind = OTHER
        self._fz_kind = kind
        self._sync_slow()

    def _sync_slow(self) -> None:
        """The state's slow scalars (the motion's update, its start [s] and mode, the drives
        expected enabled, the monitor's first judged tick, its contact) into the tick's state
        when one changed since they were written (numpy scalar writes, ~0.3 µs each)."""
        m, c = self.motion, self.collision
        was_contact = c is not None and c._was_contact
        slow = (self._fz_kind, m.t0, m.mode, self.expect_enabled, self._judge_from, was_contact)
        if slow != self._slow:
            self._slow = slow
            st = self.st
            st["kind"], st["t0"], st["mode"] = slow[0], slow[1], slow[2]
            st["expect"], st["judge_from"], st["was_contact"] = slow[3], slow[4], slow[5]

    def _busy(self) -> int:
        """The rare states now, as BUSY_* bits (0: nothing keeps the next tick off the quiet
        path; requests from other threads and this tick's status are checked per tick)."""
        stop, m = self.stop, self.motion
        b = 0
        if stop.latched or stop.category != NO_CATEGORY or self._measuring:
            b |= BUSY_STOP
        if self.enabling or self._fault_resetting:
            b |= BUSY_ENABLING
        if self.homing is not None:
            b |= BUSY_HOMING
        if m.mode == DRAG or self.drag_reason or self._wrench_set:
            b |= BUSY_DRAG
        if self.recording is not None or self.playback is not None:
            b |= BUSY_TEACH
        if not self.snapshot.finite:
            b |= BUSY_NONFINITE
        if m.version != self._ff_version or self._model_moved():
            b |= BUSY_REFERENCE
        if self.collision is not None and self.collision._tool is not None:
            b |= BUSY_TOOL_FORCE
        return b

    # ------------------------------------------------------------- tick helpers

    def _check_bank(self) -> None:
        """After the observers' reset (start-up, a reset: never in a running tick): the bank
        addresses its owners' arrays, so an owner that rebound one gets a new bank rather
        than a bank that goes on integrating the arrays it dropped."""
        if not self._bank.bound():
            self._bank = ObserverBank(self.observers, self.snapshot, self.tau_ext)

    def _model_moved(self) -> bool:
        """The model is not the one tau_ff was evaluated with (``_ff_model``): its parameters
        (``RobotModel.revision``: identified parameters, rotor inertia, payload) changed or its
        friction or payload object was replaced."""
        m = self.feedforward.model
        rev, fr, pl = self._ff_model
        return m.revision != rev or m.friction is not fr or m.payload is not pl

    def _ff_model_changed(self) -> bool:
        """True (once) when :meth:`_model_moved`: the model now is the one tau_ff is
        evaluated with."""
        if not self._model_moved():
            return False
        m = self.feedforward.model
        self._ff_model = (m.revision, m.friction, m.payload)
        return True

    def _overrun(self, missed: int) -> None:
        if missed > 0:
            self.overruns += missed
            self.overrun_streak += missed
        else:
            self.overrun_streak = 0
        if self.overrun_streak >= self.overrun_limit:
            self.stop.report(Fault.OVERRUN, -1, float(self.overrun_streak))

    def _push(self) -> None:
        """The filled tick record into the sink, with the new events (and every
        ``diag_every`` ticks the diagnostics)."""
        self.sink.push_tick(self.tick_rec)
        ev = self._events
        while self._events_pushed < ev.count:  # one integer compare on a tick without events
            ev.copy(self._events_pushed, self.event_rec, self.t)
            self.sink.push_event(self.event_rec)
            self._events_pushed += 1
        if self.tick % self.diag_every == 0:
            self._diag()

    def _diag(self) -> None:
        d = self.diag_rec
        d["t"] = self.t
        d["ticks"] = self.tick
        d["overruns"] = self.overruns
        d["wakeup_p99_us"] = self.wakeup_p99_us
        d["compute_p99_us"] = self.compute_p99_us
        d["bus_errors"] = self.bus.lost_total
        d["dropped_records"] = self.sink.dropped
        self.sink.push_diag(d)

    # ------------------------------------------------------------------- queries

    def stopped_and_off(self) -> bool:
        """True when a category 0/1 stop has taken every drive out of its powered states."""
        if self.stop.category not in (0, 1):
            return False
        for s in self.group.states:
            if s == _OE or s == _QSA or s == _FRA:
                return False
        return True

    def category(self) -> int:
        return int(self.stop.category) if self.stop.category != NO_CATEGORY else -1
