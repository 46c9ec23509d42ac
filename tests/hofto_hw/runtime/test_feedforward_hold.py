"""The tick reuses its feed-forward while the motion's reference holds, and only then: over a
run with holds, a drag (the hand's torque added), a payload change at a hold, a move along
the demo path and a ramp to standstill, tau_ff is bit for bit the feed-forward evaluated
afresh every tick."""

from __future__ import annotations

import numpy as np

from hofto_hw.config.models import SystemConfig
from hofto_hw.config.runtime import ScriptedDragConfig
from hofto_hw.control.joint_motion import DRAG, HOLD, MOVE, RAMP_DOWN
from hofto_hw.model.payload import Payload, apply_payload
from hofto_hw.runtime.compose import build
from hofto_hw.runtime.drag_script import DragScript
from hofto_hw.runtime.fused import S_FF

SCRIPT = ScriptedDragConfig(
    reset=0.01, mode=0.05, press=0.1, push_start=0.3, push_end=0.8, release=1.0, settle=0.2
)


def test_feedforward_reused_at_hold_equals_evaluating_every_tick(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    tick.script = DragScript(SCRIPT, system.bus.plant, system.rate_hz)
    ff = tick.feedforward
    model = ff.model
    ref = model.create_data(ff.backend)  # evaluated every tick, same implementation
    ref_tau = np.zeros(model.n)
    evaluated = []  # ticks the Python stages had the compiled sections 5-7 evaluate it
    real_s57 = tick._s57_call

    def counted(hot, rx, rec, t, k, what, *rest):
        if what & S_FF:
            evaluated.append(tick.tick)
        return real_s57(hot, rx, rec, t, k, what, *rest)

    tick._s57_call = counted
    modes: set[int] = set()

    def check() -> bool:
        m = tick.motion
        ref.inverse_dynamics(m.q, m.qd, m.qdd, out=ref_tau)
        if m.mode == DRAG:
            np.add(ref_tau, tick.drag.tau_offset, out=ref_tau)
        assert tick.tau_ff.tobytes() == ref_tau.tobytes(), (tick.tick, m.mode)
        modes.add(m.mode)
        return False

    def run(ticks: int) -> None:
        system.loop.run(max_ticks=ticks, should_stop=check)

    try:
        run(1500)  # hold, drag mode, the push, the release (category 2), the ramp, hold
        assert {HOLD, DRAG} <= modes and tick.drag.active is False
        held = len(evaluated)
        run(100)  # holding still: nothing to evaluate
        assert tick.motion.mode == HOLD and len(evaluated) == held
        load = Payload(1.0, (0.0, 0.0, 0.05), (0.0,) * 6)
        apply_payload(system.bus.plant.true_model, load)  # the arm picks up a tool at the hold,
        apply_payload(model, load)  # and the controller's model is told
        run(1)
        assert evaluated[-1] == tick.tick  # the new payload's feed-forward at once
        run(50)
        tick.reset_requested = True
        run(5)
        tick.mode_request = MOVE
        run(600)
        assert tick.motion.mode == MOVE, (tick.reset_result, tick.mode_result, tick.stop.latched)
        moving = len(evaluated)
        tick.mode_request = HOLD
        run(400)  # the ramp to standstill, then the hold
        assert RAMP_DOWN in modes and tick.motion.mode == HOLD
        assert len(evaluated) - moving < 400  # the hold after the ramp reuses it
        model.rotor_inertia = model.rotor_inertia * 1.5  # the setter bumps model.revision
        run(20)
    finally:
        system.close()
    assert len(evaluated) < tick.tick - 300  # the holds skipped hundreds of evaluations
