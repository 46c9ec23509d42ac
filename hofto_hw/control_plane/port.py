"""The loop's side of the control channel: :meth:`LoopPort.poll`, once per tick, between
ticks (``Loop.run`` calls it after ``Tick.step``), never waits and allocates no array.

Per poll, in this order: the stop words (the control socket's and the stop socket's, an
operator stop is handled before anything else); the enabling lease
(``drag.enable_input.source: socket``: the input is pressed while the lease the control
plane renews has not expired; expiry is a release, category 2); the state
slot (the tick record and the extra words; STO and brake per axis every 8th tick); new
stop-controller events; the answer of the request in progress, or the next request record.
Homing (REQ_HOME) is checked here and then run by the tick (``Tick.start_homing``,
hofto_hw/runtime/homing_run.py); a new zero offset (REQ_ZERO) is checked and taken here,
between two ticks (``Tick.rezero``); the config file is the control plane's. The tick itself
still reads its request attributes (``stop_requested``, ``reset_requested``,
``mode_request``, ``record_request``, ``play_request``, ``enable_input``), each written here
only.

Plans arrive as rows in the channel's plan ring (:class:`StreamPlayer` reads one per tick);
a taught path leaves through the taught ring (:class:`StreamRecording`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from hofto_hw.control.joint_motion import DRAG, HOLD, MODE_NAMES, MOVE, MOVE_TO, REPLAY
from hofto_hw.control_plane import channel as ch
from hofto_hw.runtime.axes import AxesState
from hofto_hw.runtime.homing_run import LoopHoming, homing_plans, write_homing_objects
from hofto_hw.runtime.teach import RECORDING
from hofto_hw.runtime.tick import STANDSTILL
from hofto_hw.runtime.timing import Histogram
from safety.stop import EventKind

#: the per-axis STO and brake words are refreshed every 8th tick (3.7 µs a fill measured on
#: this machine; what the tick acts on it reads itself, these are for status and state())
AXES_EVERY_MASK = 7
STARVED = 2  # StreamPlayer.step: the next row is not there yet (JointMotion ramps down)
_NO_REQ, _RESET_WAIT, _RESET_ANSWER, _MODE_ANSWER, _HOME_ANSWER = 0, 1, 2, 3, 4


class StreamPlayer:
    """Plays the channel's plan ring one row per tick (TrajectoryPlayer's interface):
    ``step`` returns False (a row played), True (the last row reached: held), or
    :data:`STARVED` (the control plane has not written the next row)."""

    def __init__(self, chan: ch.Channel) -> None:
        self.chan = chan
        self.ctl = chan.ctl
        self.k = 0
        self.rows = 0
        self.mask = ch.PLAN_CAP - 1
        #: the plan's acceleration limits [rad/s²]: a starved plan ramps down at them
        #: (JointMotion.play reads it), never steeper than the motion it interrupts
        self.accel = chan.plan_accel

    def begin(self, rows: int) -> None:
        self.k = 0
        self.rows = int(rows)

    @property
    def done(self) -> bool:
        return self.rows > 0 and self.k >= self.rows - 1

    def step(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> int:
        k = self.k
        c = self.chan
        if k >= int(self.ctl[ch.PLAN_HEAD]):
            return STARVED
        np.copyto(q, c.plan_q[k & self.mask])
        if k >= self.rows - 1:
            qd.fill(0.0)
            qdd.fill(0.0)
            self.ctl[ch.PLAN_TAIL] = k + 1
            return True
        np.copyto(qd, c.plan_qd[k & self.mask])
        np.copyto(qdd, c.plan_qdd[k & self.mask])
        self.k = k + 1
        self.ctl[ch.PLAN_TAIL] = k + 1
        return False


class _NoSamples:
    """A Playback's ``executed`` recorder that keeps nothing (a streamed plan has no replay
    figures: those are the scripted replay's of ``hofto-hw run``, planned in the loop's
    process between two stretches of a sim-clock loop)."""

    count = 0

    def push(self, t: float, q: np.ndarray) -> None:
        pass


class StreamedPlayback:
    """The tick's view of a streamed plan (hofto_hw.runtime.teach.Playback's attributes)."""

    def __init__(self, chan: ch.Channel) -> None:
        self.player = StreamPlayer(chan)
        self.start = chan.plan_start
        self.kind = "move"
        self.mode = MOVE_TO
        self.executed = _NoSamples()

    @property
    def completed(self) -> bool:
        return self.player.done


class _TaughtRing:
    """TaughtPathRecorder's ``push`` into the channel's taught ring."""

    def __init__(self, chan: ch.Channel) -> None:
        self.ring = chan.taught
        self.rec = np.zeros((), ch.taught_dtype(chan.n))
        self._q = self.rec["q"]
        self.count = 0

    def push(self, t: float, q: np.ndarray) -> None:
        self.rec["t"] = t
        np.copyto(self._q, q)
        if self.ring.push(self.rec):
            self.count += 1


class StreamRecording:
    """The tick's view of a taught path being recorded for the control plane (the
    attributes of hofto_hw.runtime.teach.Recording the tick uses): ``state`` and
    ``recorder.push``. ``file`` is None: the control plane saves it, not the loop."""

    def __init__(self, chan: ch.Channel) -> None:
        self.recorder = _TaughtRing(chan)
        self.file = None
        self.state = 0
        self.message = ""

    def arm(self) -> None:
        self.state = 0
        self.recorder.count = 0

    def status(self) -> dict[str, Any]:
        return {"file": None, "state": "streamed", "samples": self.recorder.count, "message": ""}


def accel_bits(acc: dict[str, Any]) -> int:
    """hofto_hw.runtime.acceleration.report as the channel's X_ACCEL bits."""
    bits = ch.ACCEL_COMPILED if acc.get("compiled") else 0
    bits |= ch.ACCEL_NUMBA if acc.get("kernels") == "numba" else 0
    bits |= ch.ACCEL_NATIVE if acc.get("native") else 0
    if "fused" in acc:
        bits |= ch.ACCEL_HAS_FUSED | (ch.ACCEL_FUSED if acc["fused"] else 0)
    return bits


def _link_swap(model: Any) -> Any:
    """The payload swap of the loop's model (None when the tool is not on a moving link)."""
    from hofto_hw.errors import ModelError
    from hofto_hw.model.payload import LinkSwap

    try:
        return LinkSwap(model)
    except ModelError:
        return None


class LoopPort:
    """See the module docstring. ``system``: the composed run (tick, loop, motion)."""

    def __init__(self, chan: ch.Channel, system: Any) -> None:
        self.chan = chan
        self.system = system
        self.tick = tick = system.tick
        self.loop = loop = system.loop
        self.ctl = chan.ctl
        self.fctl = chan.fctl
        self.extra = chan.extra
        self.state_rec = chan.state_rec
        self.req = np.zeros((), ch.REQUEST_DTYPE)
        self.rep = np.zeros((), ch.REPLY_DTYPE)
        self.ev_rec = np.zeros((), chan.events.dtype)
        self.playback = StreamedPlayback(chan)
        self.recording = StreamRecording(chan)
        self._stop_seen = int(self.ctl[ch.STOP_SEQ])
        self._fast_seen = 0  # a stop on the stop socket before the first poll counts
        self._watch_log = False
        src = tick.enable_input.source
        self._lease = src == "socket"
        self.extra[ch.X_ENABLE_SOURCE] = ch.SOURCES.index(src) if src in ch.SOURCES else -1
        self.extra[ch.X_HAS_PATH] = 1.0 if tick.motion.path is not None else 0.0
        self.extra[ch.X_HAS_DRAG] = 1.0 if tick.drag is not None else 0.0
        prof = system.cfg.safety.profiles
        self.extra[ch.X_PROFILE] = -1 if prof is None else prof.names().index(prof.active)
        acc = getattr(system, "acceleration", None)
        self.extra[ch.X_ACCEL] = -1 if acc is None else accel_bits(acc)
        self._swap = _link_swap(system.model)
        self.axes = AxesState(system)  # STO and brake per axis into the channel's words
        # homing through the service: the objects written now, before the loop runs
        group = tick.group
        plans = homing_plans(system.cfg, group, group.transport.cycle_time)
        write_homing_objects(group.transport, plans)
        self.homing = LoopHoming(group, plans)
        self._mode_pdo = group.present("mode") & group.present("mode_display")
        self._state = _NO_REQ
        self._seq = 0
        self._reset_at = 0
        self._events_seen = tick.stop.events.count
        # the loop's timing histograms in the channel (the control plane's status reads them)
        loop.wakeup = Histogram(counts=chan.wakeup_counts)
        loop.compute = Histogram(counts=chan.compute_counts)
        self._mono = time.monotonic_ns

    def attach(self, watch_log: bool = False) -> LoopPort:
        """Poll after every tick of ``system.loop``; ``watch_log``: the control plane
        watches the flight recorder (the tick's ``log_failure`` comes from the channel)."""
        self.loop.port = self
        self._watch_log = watch_log
        return self

    # ------------------------------------------------------------------ per tick

    def poll(self) -> None:
        tick, ctl = self.tick, self.ctl
        s = int(ctl[ch.STOP_SEQ])
        f = int(ctl[ch.STOP_FAST_SEQ])  # the stop socket's (stop_server.py)
        if s != self._stop_seen or f != self._fast_seen:  # first, always
            self._stop_seen = s
            self._fast_seen = f
            tick.stop_requested = True
            ctl[ch.STOP_ACK] = s
            ctl[ch.STOP_FAST_ACK] = f
        if self._lease:
            tick.enable_input.pressed = int(ctl[ch.LEASE_NS]) > self._mono()
        if self._watch_log:
            tick.log_failure = int(ctl[ch.LOG_FAILING]) != 0
            tick.log_failure_value = float(ctl[ch.LOG_LOST])
        self._publish()
        if tick.stop.events.count != self._events_seen:
            self._forward_events()
        if self._state != _NO_REQ:
            self._answer()
        elif self.chan.requests.pop_into(self.req):
            self._take()

    def _publish(self) -> None:
        tick, ctl, x = self.tick, self.ctl, self.extra
        stop, motion = tick.stop, tick.motion
        seq = int(ctl[ch.STATE_SEQ]) + 1
        ctl[ch.STATE_SEQ] = seq  # odd: being written
        self.state_rec[...] = tick.tick_rec
        x[ch.X_CATEGORY] = stop.category
        x[ch.X_ACTIVE] = stop.active
        x[ch.X_STOPPING] = 1.0 if stop.category != -1 else 0.0
        x[ch.X_ENABLING] = 1.0 if tick.enabling else 0.0
        x[ch.X_EXIT] = 1.0 if tick.exit_requested else 0.0
        x[ch.X_STOP_REQUESTED] = 1.0 if tick.stop_requested else 0.0
        x[ch.X_OVERRUNS] = tick.overruns
        x[ch.X_LOOP_TICKS] = self.loop.ticks
        d = tick.drag
        x[ch.X_DRAG_ACTIVE] = 1.0 if d is not None and d.active else 0.0
        x[ch.X_PRESSED] = 1.0 if tick.enable_input.pressed else 0.0
        pb = tick.playback
        if pb is self.playback:
            pl = pb.player
            x[ch.X_PLAN_K] = pl.k
            x[ch.X_PLAN_DONE] = 1.0 if pl.done else 0.0
        rec = tick.recording
        if rec is self.recording:
            x[ch.X_TEACH_STATE] = rec.state
            x[ch.X_TEACH_SAMPLES] = rec.recorder.count
        x[ch.X_WAKE_MAX] = self.loop.wakeup.max
        x[ch.X_COMP_MAX] = self.loop.compute.max
        x[ch.X_MOVING] = 0.0 if motion.mode == HOLD and motion._still else 1.0
        if not tick.tick & AXES_EVERY_MASK:  # slow signals for status: every 8th tick
            self.axes.fill(self.chan.sto, self.chan.brake)
        ctl[ch.STATE_SEQ] = seq + 1
        ctl[ch.TICKS] = self.loop.ticks
        tick.wakeup_p99_us = self.fctl[ch.WAKE_P99]
        tick.compute_p99_us = self.fctl[ch.COMP_P99]
        if tick.exit_requested:
            ctl[ch.EXIT] = 1

    def _forward_events(self) -> None:
        tick = self.tick
        ev, e = tick.stop.events, self.ev_rec
        while self._events_seen < ev.count:
            ev.copy(self._events_seen, e, tick.t)
            if not self.chan.events.push(e):
                self.ctl[ch.EVENTS_LOST] += 1
            self._events_seen += 1

    # ------------------------------------------------------------------ requests

    def _reply(self, ok: bool, text: str) -> None:
        """The answer to the request in progress (rare: the text is encoded here)."""
        r = self.rep
        r["seq"] = self._seq
        r["code"] = 1 if ok else 0
        r["text"] = text.encode("utf-8", "replace")[:200]
        self.chan.replies.push(r)
        self._state = _NO_REQ

    def _take(self) -> None:
        """A new request record (the control plane sends one at a time)."""
        r, tick = self.req, self.tick
        self._seq = int(r["seq"])
        kind = int(r["kind"])
        if kind == ch.REQ_RESET:
            if not tick.exit_requested and tick.stop_requested:
                tick.stop_requested = False  # an operator stop ends with its reset
                self._reset_at = tick.tick + 2  # two ticks: no longer a present cause
                self._state = _RESET_WAIT
            else:
                self._start_reset()
            return
        if kind == ch.REQ_PROFILE:
            v = r["value"]
            self._profile(int(r["arg"]), float(v[0]), float(v[1]), float(v[2]), float(v[3]))
            return
        if kind == ch.REQ_PAYLOAD:
            self._payload(r["value"])
            return
        if kind == ch.REQ_MODE or kind == ch.REQ_PLAY:
            self._mode(kind, int(r["mode"]), int(r["arg"]), int(r["flag"]))
            return
        if kind == ch.REQ_HOME:
            self._home(int(r["arg"]))
            return
        if kind == ch.REQ_ZERO:
            self._zero(int(r["arg"]), float(r["value"][0]), float(r["value"][1]))
            return
        self._reply(False, f"unknown request kind {kind}")

    def _at_rest_refusal(self, what: str) -> str:
        """Why ``what`` may not start now ("" when it may): anything latched or stopping,
        the drives not enabled, a homing running, the arm not holding at rest."""
        tick = self.tick
        stop = tick.stop
        if stop.latched or stop.category != -1 or tick.stop_requested:
            names = ", ".join(stop.latched_names()) or "a stop"
            return f"{what} refused: {names} latched: reset first"
        if tick.enabling or not tick.expect_enabled:
            return f"{what} refused: the drives are not enabled"
        if tick.homing is not None:
            return f"{what} refused: homing in progress"
        motion = tick.motion
        moving = float(np.abs(tick.group.qd).max()) >= STANDSTILL
        if motion.mode != HOLD or not motion._still or moving:
            return (
                f"{what} refused: the arm is moving ({MODE_NAMES.get(motion.mode, '?')}); "
                "hold at rest first"
            )
        return ""

    def _home(self, mask: int) -> None:
        """Home the axes of bit mask ``mask`` (in axis order) through the tick."""
        why = self._at_rest_refusal("home")
        axes = [a for a in range(self.tick.n) if mask >> a & 1]
        names = self.tick.group.names
        if not why and not axes:
            why = "home refused: no axis named"
        for a in axes:
            if why:
                break
            if a not in self.homing.plans:
                why = f"home refused: {names[a]} has homing: none (absolute encoder)"
            elif not self._mode_pdo[a]:
                why = (
                    f"home refused: {names[a]}'s drive maps no mode of operation (0x6060/0x6061) "
                    "in its PDOs: stop the service and run hofto-hw home"
                )
        if why:
            self._reply(False, why)
            return
        self.homing.begin(axes)
        self.tick.start_homing(self.homing)
        self._state = _HOME_ANSWER

    def _zero(self, axis: int, counts: float, was: float) -> None:
        """A new zero offset of ``axis`` [counts], taken between two ticks at rest."""
        why = self._at_rest_refusal("zero set")
        if not why and float(self.tick.group.scaling.zero_offset[axis]) != was:
            why = "zero set refused: the axis's zero offset changed since the request was made"
        if why:
            self._reply(False, why)
            return
        self.tick.rezero(axis, counts)
        self._reply(True, "zero offset applied")

    def _moving(self) -> str:
        """Why the arm is not at standstill for a safety setting ('' when it is: holding,
        every joint slower than STANDSTILL, not enabling; after a stop too)."""
        tick = self.tick
        if tick.motion.mode != HOLD or float(np.abs(tick.group.qd).max()) >= STANDSTILL:
            return "the arm is moving"
        if tick.enabling:
            return "the enabling input is pressed"
        return ""

    def _profile(
        self, index: int, collision_scale: float, drag_mass: float, drag_damping: float,
        drag_speed: float,
    ) -> None:  # fmt: skip
        """Switch the safety profile: only at standstill (after a stop too); the collision
        thresholds and the drag's virtual mass, damping and speed limits, in place; a
        flight-log event (PROFILE: its index, its collision scale)."""
        tick = self.tick
        why = self._moving()
        if why:
            self._reply(False, f"refused: {why}; a safety profile changes at standstill")
            return
        if tick.collision is not None:
            tick.collision.scale_thresholds(collision_scale)
        if tick.drag is not None:
            tick.drag.apply_profile(drag_mass, drag_damping, drag_speed)
        tick.stop.note(EventKind.PROFILE, index, collision_scale)
        self.extra[ch.X_PROFILE] = index
        self._reply(True, "profile active")

    def _payload(self, value: np.ndarray) -> None:
        """A new payload (mass, com, and the tool link's inertia the control plane computed
        with it): only at standstill; swapped into the model the observers, the feed-forward
        and the drag share, between two ticks, in place (hofto_hw.model.payload.LinkSwap);
        flight-log events PAYLOAD (joint -1: the mass [kg]; 0, 1, 2: the com's x, y, z [m])."""
        from hofto_hw.model.payload import LINK_NUMBERS, Payload

        why = self._moving()
        if why:
            self._reply(False, f"refused: {why}; the payload changes at standstill")
            return
        swap = self._swap
        if swap is None:
            self._reply(False, "refused: the tool frame is not on a moving link")
            return
        mass = float(value[0])
        com = (float(value[1]), float(value[2]), float(value[3]))
        np.copyto(swap.values, value[4 : 4 + LINK_NUMBERS])
        swap.apply(Payload(mass, com))
        stop = self.tick.stop
        stop.note(EventKind.PAYLOAD, -1, mass)
        for i in range(3):
            stop.note(EventKind.PAYLOAD, i, com[i])
        self._reply(True, "payload active")

    def _start_reset(self) -> None:
        tick = self.tick
        tick.reset_result = ""
        tick.reset_requested = True
        self._state = _RESET_ANSWER

    def _mode(self, kind: int, mode: int, arg: int, flag: int) -> None:
        tick = self.tick
        if tick.stop.stopping():
            self._reply(False, "a stop is latched: reset first")
            return
        if kind == ch.REQ_PLAY:
            if tick.motion.mode != HOLD:
                name = MODE_NAMES.get(tick.motion.mode, "?")
                self._reply(False, f"refused: the arm is in mode {name}: mode hold first")
                return
            if int(self.ctl[ch.PLAN_ID]) != arg:
                self._reply(False, "refused: no trajectory planned")
                return
            pb = self.playback
            pb.mode = mode
            pb.kind = "replay" if mode == REPLAY else "move"
            pb.player.begin(int(self.ctl[ch.PLAN_ROWS]))
            self.ctl[ch.PLAN_TAIL] = 0
            self.ctl[ch.PLAN_TAIL_ID] = arg
            self.extra[ch.X_PLAN_ID] = arg
            tick.mode_result = ""
            tick.play_request = pb
            tick.mode_request = mode
            self._state = _MODE_ANSWER
            return
        if mode == DRAG:
            if tick.drag is None:
                self._reply(False, "no drag: section in the config")
                return
            rec = None
            if flag:
                rec = self.recording
                rec.arm()
            tick.mode_result = ""
            tick.record_request = rec
            tick.mode_request = DRAG
            self._state = _MODE_ANSWER
            return
        if mode == MOVE and tick.motion.path is None:
            self._reply(False, "mode move: the config has no demo path (run.path)")
            return
        if mode not in (MOVE, HOLD):
            self._reply(False, f"unknown mode {mode}")
            return
        tick.mode_request = mode
        self._reply(True, f"mode {MODE_NAMES.get(mode, '?')} requested")

    def _answer(self) -> None:
        tick = self.tick
        st = self._state
        if st == _RESET_WAIT:
            if tick.tick >= self._reset_at:
                self._start_reset()
        elif st == _RESET_ANSWER:
            r = tick.reset_result
            if r and r != "resetting drive faults":
                self._reply(not r.startswith("reset refused"), r)
        elif st == _MODE_ANSWER:
            r = tick.mode_result
            if r:
                self._reply(r in ("drag", "playing"), r)
        elif st == _HOME_ANSWER and tick.homing is None:
            h = self.homing
            if h.result:
                self._reply(False, h.result)
            else:
                self._reply(True, "homed: " + ", ".join(h.homed))

    def detach(self) -> None:
        """Before the channel is unmapped: the loop stops polling and keeps copies of its
        histograms (their counts lived in the channel; numpy views of an unmapped segment
        would crash the summary that reads them)."""
        loop = self.loop
        loop.port = None
        for h in (loop.wakeup, loop.compute):
            h.counts = h.counts.copy()
        tick = self.tick
        if tick.play_request is self.playback:
            tick.play_request = None
        self.playback.player.chan = None  # type: ignore[assignment]
        self.playback.start = self.playback.start.copy()

    def finish(self) -> None:
        """The loop has ended (the control plane finishes and exits)."""
        rec = self.tick.recording
        if rec is self.recording and rec.state <= RECORDING:
            self.extra[ch.X_TEACH_STATE] = 2  # FINISHED: whatever was recorded is saved
        self.ctl[ch.EXIT] = 1
        self.ctl[ch.LOOP_DONE] = 1
