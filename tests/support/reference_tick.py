"""The tick's Python reference: every stage of :class:`hofto_hw.runtime.tick.Tick` on every
tick, sections 1-3 included (the drive group's ``read``, the snapshot's ``compute`` and the
observer bank's ``update``, each part's own method), where production runs them in the
compiled call (:mod:`hofto_hw.runtime.fused`) and its stages only on what is rare.

tests/hofto_hw/runtime/test_fused.py compares the two tick by tick, bit for bit; tests that
inject a fault through a part's Python method (``group.read``, ``bank.update``) run on it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hofto_hw.control.joint_motion import DRAG
from hofto_hw.recording.kernels import fill_tick
from hofto_hw.runtime import tick_kernels as tk
from hofto_hw.runtime.fused import S_FF, S_OFF, S_PATH
from hofto_hw.runtime.tick import Tick
from hofto_hw.runtime.tick_events import DRIVE_CAUSES
from safety.collision import COLLIDED, CONTACT
from tests.support.reference_safety import bus_check, finite, limits_check


class ReferenceTick(Tick):
    """A built :class:`Tick` that runs the Python stages on every tick (:func:`use_reference`
    turns a built system's tick into one: the same parts, the same arrays)."""

    def step(self, t: float, dt: float, wakeup_us: float, missed: int, compute_us: float) -> None:
        g = self.group
        self.tick += 1
        self.t = t
        self.stop.begin_tick(self.tick)
        if self.script is not None:
            self.script.step(self)
        status = g.exchange()  # 1. exchange
        self._front(dt)  # 2. joint state, 3. snapshot and observers
        self._drag_front()  # 3b. drag
        self._safety(status, dt)  # 4. safety
        self._requests(missed)  # 4 (end): overruns, requests, reset, stop measurement
        self._control()  # 5. controller and 6. command
        self._record(status, wakeup_us, compute_us)  # 7. the record into the sink

    def _control(self) -> None:
        """Sections 5 (controller) and 6 (command): the rare decisions as production takes
        them (Tick._decide), then the steps of sections 5-7 they ask for in Python, through
        the parts' own methods (production: fused.section57, compiled)."""
        m = self.motion
        what = self._decide()
        if what & S_PATH:  # the demo path (JointMotion.update's; _decide moved its version)
            m.path.evaluate(float(self.st["t_cmd"]) - m.t0, m.q0, m.q, m.qd, m.qdd)
        if what & S_FF:
            self.feedforward.inverse_dynamics(m.q, m.qd, m.qdd, out=self.tau_ff)
        if what & S_OFF:
            self.tau_ff += self._tau_off  # the hand's torque off the drives' offset
        self.group.command_position(m.q, self.tau_ff)

    def _record(self, status: int, wakeup_us: float, compute_us: float) -> None:
        """Section 7: the tick record (and q_sent = motion.q, the command just sent) by the
        record fill (production: fused.section57), then into the sink."""
        m = self.motion
        # the casts keep the kernel on its warmed signature whatever numbers callers pass
        fill_tick(
            self._rec1, self.group.sample, m.q, self.tau_ext, self.q_sent, float(self.t), self.tick,
            m.mode, self.stop.latched, int(status), float(wakeup_us), float(compute_us),
            float(self.st["sample_dt"]),
        )  # fmt: skip
        self._push()

    def _refresh(self, rebuild: bool = True) -> None:
        """Nothing to keep for a compiled call (the reference never takes it)."""

    def _safety(self, status: int, dt: float) -> None:
        """Section 4 through the parts' own methods, each reporting to the stop controller as
        it finds (production: fused.section4's fault array, Tick._report_faults)."""
        g, stop, motion, snap = self.group, self.stop, self.motion, self.snapshot
        self._homing_step()
        q, qd, tau = g.q, g.qd, g.tau
        st = self.st
        obs_dt = float(st["sample_dt"])
        dragging = motion.mode == DRAG
        good = bus_check(
            self.bus, stop, status, g.fresh, g.states, self.err_codes, self.expect_enabled
        )
        lim = self.limits
        ok = snap.finite or (finite(stop, q) & finite(stop, qd) & finite(stop, tau))
        flags = tk.tick_flags(
            self.tau_ext, g.states, tk.POWERED, motion.qdd, self.tick_rec["qdd_cmd"]
        )
        if not flags & tk.ESTIMATES_FINITE:
            for i in range(len(self.observers)):
                ok &= finite(stop, self.tau_ext[i])
        powered = self.expect_enabled and not self.enabling and stop.category in (-1, 2)
        st["since_fresh"] += dt
        gap = tk.jump_gap(float(st["since_fresh"]), self.period)
        limits_check(lim, stop, q, qd, tau, self.q_sent, good, powered, gap)
        if good:
            st["since_fresh"] = 0.0
        trusted = ok and good and not stop.active & DRIVE_CAUSES and not self.enabling
        trusted = trusted and self.homing is None
        monitored = (
            self.collision is not None and trusted and tk.judged(self.tick, self._judge_from, flags)
        )
        if monitored != st["monitored"]:
            monitored = bool(monitored)
            st["monitored"] = monitored
            self.tick_rec["monitored"] = monitored
        if monitored:
            mdt = obs_dt if obs_dt > 0.0 else dt
            est = self._monitored(True) if dragging else self.tau_ext
            flags = self.collision.update(stop, est, q, qd, motion.qdd, mdt)
            if self._learn is not None and motion.mode != DRAG and stop.category == -1:
                if not flags & (COLLIDED | CONTACT):  # contact-free motion: friction error
                    self._learn(g.qd, self.tau_ext[self.drag_row], mdt)

    def _front(self, dt: float) -> None:
        """Sections 2-3: the joint state in SI, the snapshot and the observers over the sample
        interval (the bus's when it knows it, else dt; held over a lost sample)."""
        self.group.read()
        sample_dt = self._transport.sample_dt
        obs_dt = 0.0
        if sample_dt >= 0.0:
            obs_dt = sample_dt if sample_dt > 0.0 else dt
            self._observe(obs_dt)
        st = self.st
        st["finite"] = self.snapshot.finite
        st["sample_dt"] = obs_dt
        st["cmd_dt"] = cmd_dt = tk.command_dt(dt, self.period)
        st["t_cmd"] += cmd_dt

    def _observe(self, dt: float) -> None:
        """The snapshot of the sample and every observer from it; after a stall (k > 1
        cycles) the gap in k steps of dt/k from the last tick's sample, interpolated
        linearly; then the sample kept (the next stall's interpolation start)."""
        snap, g = self.snapshot, self.group
        q, qd, tau = g.q, g.qd, g.tau
        k = 1 if dt <= self._stall_dt else tk.gap_steps(dt, self.period)
        if k == 1:
            snap.compute(q, qd, tau)
            self._bank.update(dt)
        else:
            h = dt / k
            prev, x = self._prev, self.state["interp"][0]
            for s in range(1, k + 1):
                a = s / k
                for j, now in enumerate((q, qd, tau)):
                    tk.lerp(prev[j], now, a, x[j])
                snap.compute(x[0], x[1], x[2])
                self._bank.update(h)
        np.copyto(self._prev, g.sample)


def use_reference(system: Any, on: bool = True) -> None:
    """Run ``system``'s tick as the reference (``on``) or as built (the production Tick)."""
    tick = system.tick
    kept = vars(tick).get("step")  # a probe put back as an attribute pins the old class's step
    if getattr(kept, "__func__", None) in (Tick.step, ReferenceTick.step):
        del tick.step
    if on:
        tick.__class__ = ReferenceTick
    else:
        tick.__class__ = Tick
        tick._refresh()
