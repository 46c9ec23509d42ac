"""The tick's rare events: what its Python stages do when the compiled call's answer says
something is not quiet (hofto_hw/runtime/tick.py): the stop's measurement, a reset and its
fault-reset edges, enabling and the brake release check, mode changes (drag, play, move,
hold), teach recording, the drag's controller and its stop reasons, homing and a new zero.

:class:`TickEvents` is a part of :class:`~hofto_hw.runtime.tick.Tick` (its base class):
the methods read and write the tick's own attributes. None runs on a quiet tick; the
agreement test (tests/hofto_hw/runtime/test_fused.py) fails if one ran on a tick the
compiled call took as quiet. Rare: these may allocate (result messages), nothing else of
the tick does.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import State
from hofto_hw.control.drag import DragReason
from hofto_hw.control.joint_motion import DRAG, HOLD, MOVE, PLAYING
from hofto_hw.runtime.teach import FINISHED, RECORDING
from safety.stop import EventKind, Fault

_FAULT = int(State.FAULT)
STANDSTILL = 0.01  # rad/s: every joint slower than this counts as stopped
MAX_STOPS = 256  # stop episodes kept for the summary
FAULT_RESET_TICKS = 20  # ticks of fault-reset edges before a reset is retried
DRIVE_CAUSES = (
    (1 << Fault.DRIVE_FAULT) | (1 << Fault.DRIVE_DISABLED) | (1 << Fault.STO) | (1 << Fault.BRAKE)
)


class TickEvents:
    """The rare-event handlers of :class:`~hofto_hw.runtime.tick.Tick` (module docstring)."""

    # the tick's attributes these handlers use (set by Tick.__init__)
    group: Any
    stop: Any
    motion: Any
    snapshot: Any
    observers: list[Any]
    limits: Any
    collision: Any
    drag: Any
    enable_input: Any
    tau_ext: np.ndarray
    st: Any
    n: int
    tick: int
    t: float

    def _refresh(self, rebuild: bool = True) -> None: ...  # Tick's: the rare states again

    def _measure_stop(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Stopping time [s] and distance [rad, max over joints] from the latch to rest."""
        stop = self.stop
        if stop.first_tick == self.tick and self.n_stops < MAX_STOPS:
            self._measuring = True
            self._t_detect = self.t
            np.copyto(self._q_detect, q)
            self.stop_tick[self.n_stops] = self.tick
            self.n_stops += 1
        if not self._measuring:
            return
        np.abs(qd, out=self._d)
        if self._d.max() < STANDSTILL:
            i = self.n_stops - 1
            self.stop_time[i] = self.t - self._t_detect
            np.subtract(q, self._q_detect, out=self._d)
            np.abs(self._d, out=self._d)
            self.stop_distance[i] = self._d.max()
            stop.note(EventKind.STANDSTILL, -1, self.stop_time[i])
            self._measuring = False

    def _reset(self) -> None:
        """Process a reset request (rare: may allocate the result message).

        A latched drive fault whose drive still shows Fault first gets fault-reset edges for
        FAULT_RESET_TICKS ticks (the drive leaves Fault only if its cause is gone); then the
        reset is tried once more and refused if any cause persists."""
        self.reset_requested = False
        sto = self.group.sto_in_image(self._sto_seen, by_state=False)
        if sto.any():  # STO is a state: no reset enables through it
            names = [self.group.names[i] for i in np.flatnonzero(sto)]
            self.reset_result = "reset refused, safe torque off active: " + ", ".join(names)
            return
        if self.reenable_refused and not self.group.all_in(State.OPERATION_ENABLED):
            self.reset_result = self.reenable_refused  # its brake would stay closed
            return
        done, msg = self.stop.reset()
        if not done and not self._edges_tried and self.stop.active & DRIVE_CAUSES:
            if not self.stop.active & self.stop.latched & ~DRIVE_CAUSES:
                self._fault_resetting = FAULT_RESET_TICKS
                self.reset_result = "resetting drive faults"
                return
        self._edges_tried = False
        self.reset_result = msg
        if not done:
            return
        g = self.group
        self.snapshot.reset_memory()
        for obs in self.observers:
            obs.reset(g.q, g.qd)
        self._check_bank()
        self._judge_from = self.tick + 1 + self.settle_ticks
        self.limits.reset(g.q)
        if self.collision is not None:
            first = self.collision.first_tick
            for r in range(self.first_detect.shape[0]):
                if self.first_detect[r] < 0:
                    self.first_detect[r] = first[r]
            self.collision.reset()
        self.motion.start(g.q)
        if not g.all_in(State.OPERATION_ENABLED):
            self.enabling = True
            self._enable_ticks = 0
            self._released = False  # the brakes open again: their check again
            self._release_running = 0

    def start_homing(self, homing: Any) -> None:
        """Run ``homing`` (a begun hofto_hw.runtime.homing_run.LoopHoming) from the next tick
        (between ticks: the control plane's port, after its checks)."""
        self.homing = homing
        self._refresh()  # not quiet from the next tick on

    def rezero(self, axis: int, counts: float) -> None:
        """Between ticks: encoder count ``counts`` is joint angle 0 of ``axis`` from now on
        (``hofto-hw zero set`` through the service, at rest). The reference, the last
        command and the monitored position move with the reading, so the drive's target in
        counts is unchanged; the observers start again from the new reading."""
        shift = self.group.set_zero_offset(axis, counts)
        self.motion.q[axis] += shift
        self.motion.version += 1
        self.q_sent[axis] += shift
        self.restart_estimates()
        self._refresh()  # not quiet from the next tick on

    def restart_estimates(self) -> None:
        """After the joint reading moved under the estimators (homing, a new zero; rare:
        may allocate): the snapshot's memory, the observers, the limit monitor's last
        position start from the measured state; the collision monitor judges again after
        the settling time."""
        g = self.group
        self.snapshot.reset_memory()
        for obs in self.observers:
            obs.reset(g.q, g.qd)
        self._check_bank()
        np.copyto(self._prev, g.sample)
        self.limits.reset(g.q)
        self._judge_from = self.tick + 1 + self.settle_ticks

    def _enable_step(self) -> None:
        """Walk every axis toward Operation enabled, one controlword per tick (bumpless:
        targets hold the measured position); a faulted axis gets a fault-reset edge."""
        g = self.group
        self._enable_ticks += 1
        if g.sto_in_image(self._sto_seen, by_state=False).any():  # STO toggled while enabling
            self._latch_now(Fault.STO, int(np.argmax(self._sto_seen)), -1.0)
            return
        if g.all_in(State.OPERATION_ENABLED):
            if self._release_step():
                return  # the brakes are opening: hold where the check started
            self.enabling = False
            self.expect_enabled = True
            self._judge_from = self.tick + self.settle_ticks
            self.motion.start(g.q)
            return
        if self._enable_ticks > g.timeout_cycles and g.sto_in_image(self._sto_seen, True).any():
            # an axis that will not leave Switch on disabled: STO where no signal is mapped
            self._latch_now(Fault.STO, int(np.argmax(self._sto_seen)), -1.0)
            return
        sm.controlwords_toward_no_reset(g.states, State.OPERATION_ENABLED, self._cw)
        if self.tick & 1:
            for i in range(self.n):
                if g.states[i] == _FAULT:
                    self._cw[i] = sm.CW_FAULT_RESET
        np.copyto(self.controlword, self._cw)
        self.motion.start(g.q)

    def _release_step(self) -> bool:
        """The brake release check of a re-enable (issue 28; the same check as at start-up,
        :class:`drivers.cia402.brake.ReleaseCheck`): True while it runs, holding the position
        it started at; a joint that moved beyond its bound latches BRAKE naming it."""
        check = self.release_check
        if check is None or self._released:
            return False
        if self._release_running == 0:
            check.start(self.group.q)
            self.motion.start(check.q0)
            self._release_running = 1
        result = check.step(self.group.q)
        if result == check.RUNNING:
            return True
        self._released = True
        self._release_running = 0
        if result >= 0:
            self._latch_now(Fault.BRAKE, result, check.moved)
            return True
        return False

    def _latch_now(self, fault: int, joint: int, value: float) -> None:
        """A fault found while enabling (section 5, after the stop was acted on this tick):
        latched, and its category commanded in this same tick."""
        self.stop.report(fault, joint, value)
        cat = self.stop.category
        if cat == 0 or cat == 1:
            self.enabling = False
            if cat == 0:
                self.group.command_disable_voltage()
            else:
                self.group.command_quick_stop()

    def _fault_reset_edge(self) -> None:
        """Rising edges of controlword bit 7 on faulted axes; then retry the reset."""
        self._fault_resetting -= 1
        if self._fault_resetting == 0:
            self._edges_tried = True
            self.reset_requested = True
            return
        if self.tick & 1:
            g = self.group
            for i in range(self.n):
                if g.states[i] == _FAULT:
                    self.controlword[i] = sm.CW_FAULT_RESET

    def _change_mode(self, qd: np.ndarray) -> None:
        want = self.mode_request
        self.mode_request = -1
        motion = self.motion
        if want == DRAG:
            self.mode_result = self._enter_drag(qd)
            self.record_request = None
        elif want in PLAYING:
            self.mode_result = self._enter_play(want, qd)
            self.play_request = None
        elif want == MOVE and motion.mode != DRAG:
            if self.expect_enabled and not self.enabling:
                motion.move(float(self.st["t_cmd"]))
        else:  # hold, or move while dragging: ramp the drag's velocity down first
            motion.ramp_down()

    def _refuse_mode(self) -> None:
        """A mode request during a stop is answered, not kept for after the reset."""
        self.mode_request = -1
        self.record_request = None
        self.play_request = None
        self.mode_result = "refused: a fault is latched, reset first"

    def _refuse_entry(self, qd: np.ndarray, not_still: str) -> str:
        """Why a mode that moves the arm may not start now ('' when it may): it starts only
        from HOLD at standstill, powered, with no latched fault; ``not_still`` is the answer
        when the arm is not holding still."""
        if self.stop.latched:
            return "refused: a fault is latched, reset first"
        if not self.expect_enabled or self.enabling:
            return "refused: drives not enabled"
        np.abs(qd, out=self._d)
        if self.motion.mode != HOLD or self._d.max() >= STANDSTILL:
            return not_still
        return ""

    def _enter_drag(self, qd: np.ndarray) -> str:
        """Drag mode only from standstill, powered, with no latched fault."""
        motion = self.motion
        if self.drag is None:
            return "refused: no drag section in the config"
        refused = self._refuse_entry(qd, "refused: the arm is not at standstill")
        if refused:
            return refused
        self.drag.start(motion.q)
        motion.mode = DRAG
        self.recording = self.record_request
        return "drag"

    def _enter_play(self, want: int, qd: np.ndarray) -> str:
        """Play the planned trajectory of ``play_request``: from HOLD at standstill, powered,
        nothing latched, and only if it starts where the hold is (planned from it)."""
        pb, motion = self.play_request, self.motion
        if pb is None or pb.mode != want:
            return "refused: no trajectory planned"
        refused = self._refuse_entry(qd, "refused: the arm is not holding at standstill")
        if refused:
            return refused
        np.subtract(motion.q, pb.start, out=self._d)
        np.abs(self._d, out=self._d)
        if self._d.max() > 1e-9:
            return "refused: the hold moved while the trajectory was planned; try again"
        motion.play(pb.player, want)
        self.playback = pb
        return "playing"

    def _teach_record(self, q: np.ndarray) -> None:
        """Taught path while the hand drags (its drag ends: FINISHED, saved off the tick);
        the measured q of every played tick (the replay figures)."""
        rec, mode = self.recording, self.motion.mode
        if rec is not None and rec.state <= RECORDING:
            if mode == DRAG and self.drag.active:
                rec.recorder.push(self.t, q)
                rec.state = RECORDING
            elif rec.state == RECORDING or mode != DRAG:
                rec.state = FINISHED
        pb = self.playback
        if pb is not None and (mode == pb.mode and self.motion.player is pb.player):
            pb.executed.push(self.t, q)

    def _drag_observe(self, q: np.ndarray, qd: np.ndarray, dt: float) -> None:
        """The drag controller's tick: reads the enabling input, estimates the tool wrench
        from the configured observer row, checks the force limit and the off-tool contact."""
        inp = self.enable_input
        if inp.source == "digital_input":
            inp.from_word(int(self._din[inp.axis]))
        d = self.drag
        self.drag_reason = d.update(
            q, qd, self.tau_ext[self.drag_row], dt, inp.pressed, self.stop.latched != 0
        )
        if d.category == 2:
            self.drag_reason = DragReason.ENABLE_RELEASED
        np.copyto(self._wrench, d.wrench)
        self._wrench_set = True

    def _monitored(self, dragging: bool) -> np.ndarray:
        """The collision monitor's input: the estimates, minus (while the hand drags) each
        row's own tool-force fit, so the monitor stays armed for contacts off the tool
        while the hand's own push is the drag force limit's to judge."""
        if not (dragging and self.drag.active):
            return self.tau_ext
        return self.drag.monitor_input(self.tau_ext, self._tau_mon)

    def _drag_report(self) -> None:
        """Map the drag's stop request to a fault class (safety latches, the loop acts)."""
        reason, d, stop = self.drag_reason, self.drag, self.stop
        self.drag_reason = 0
        if reason == DragReason.ENABLE_RELEASED:
            stop.report(Fault.ENABLING_RELEASED)
        elif reason == DragReason.FORCE_LIMIT:
            stop.report(Fault.COLLISION, -1, d.estimator.force_norm)
        elif reason == DragReason.CONTACT_OFF_TOOL:
            # joint = link index (the link after joint j is link j + 1, 1-based)
            stop.report(Fault.COLLISION, d.contact_link - 1, d.mismatch)
