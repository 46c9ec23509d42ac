"""A stalled loop (missed deadlines) on the simulated arm holding still: the observers take
the gap in one-cycle steps, so the stall itself reads as no contact, and the setpoint does
not jump ahead by the stall."""

from __future__ import annotations

import numpy as np

from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.runtime.compose import build
from safety.stop import Fault
from tests.support.reference_tick import use_reference


def test_a_100_ms_stall_in_hold_is_no_contact(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    system.loop.run(max_ticks=500)  # settle in hold
    before = np.abs(tick.tau_ext).max()
    system.clock.stall(99)  # the next tick comes 100 cycles after the last one
    system.loop.run(max_ticks=1)
    # one step of 0.1 s (before): HOFTO read up to 165 N·m (joint 2), the momentum observer
    # ~1 N·m after one step (gain·dt = 3 > 2, unstable); the collision level is 4 N·m
    assert np.abs(tick.tau_ext).max() < max(1.0, 2.0 * before), tick.tau_ext
    system.loop.run(max_ticks=200)
    assert np.abs(tick.tau_ext).max() < max(1.0, 2.0 * before), tick.tau_ext
    assert not tick.stop.is_latched(Fault.COLLISION)


def test_the_setpoint_advances_one_cycle_per_tick_after_a_stall(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    tick.mode_request = MOVE
    system.loop.run(max_ticks=300)
    t_cmd = float(tick.st["t_cmd"])
    system.clock.stall(50)
    system.loop.run(max_ticks=1)
    assert abs(tick.st["t_cmd"] - t_cmd - tick.period) < 1e-12
    assert tick.t - t_cmd > 0.05  # while the loop's own clock took the 51 cycles


def test_the_observers_hold_while_the_bus_reports_no_new_sample(cfg: SystemConfig) -> None:
    """A DC bus that lost a frame reports ``sample_dt == -1``: the repeated sample is not
    integrated as a new one (HOFTO read a repeated sample of the moving arm as ~30 N·m);
    with 0.0 (the simulated bus: interval unknown) they run on the loop's dt as before."""
    system = build(cfg, clock="sim", contact=False)
    tick, transport = system.tick, system.group.transport
    tick.mode_request = MOVE
    system.loop.run(max_ticks=400)
    assert transport.sample_dt == 0.0
    held = tick.tau_ext.copy()
    transport.sample_dt = -1.0
    system.loop.run(max_ticks=3)
    np.testing.assert_array_equal(tick.tau_ext, held)
    transport.sample_dt = 0.0
    system.loop.run(max_ticks=1)
    assert not np.array_equal(tick.tau_ext, held)


def test_the_monitor_judges_over_the_interval_the_observers_integrated(
    cfg: SystemConfig,
) -> None:
    """A DC bus whose drives sampled one cycle apart while the master stalled 50 cycles: the
    collision monitor (its acceleration feature, hence the threshold) and the drag's friction
    learning advance by the drives' interval, as the observers do, not by the master's dt
    (a 50x too small acceleration estimate dropped the threshold while the arm accelerated).
    Seen on the reference tick's monitor call; the compiled tick's monitor and learning keep
    the same state bit for bit."""
    fused, reference = (build(cfg, clock="sim", contact=False) for _ in range(2))
    use_reference(reference)
    try:
        tick = reference.tick
        assert tick.collision is not None and tick.drag is not None
        for s in (fused, reference):
            s.tick.mode_request = MOVE
            s.loop.run(max_ticks=400)
        seen: list[float] = []
        learned: list[float] = []
        update, learn = tick.collision.update, tick._learn

        def spy_update(stop, tau_ext, q, qd, qdd, dt):  # type: ignore[no-untyped-def]
            seen.append(dt)
            return update(stop, tau_ext, q, qd, qdd, dt)

        def spy_learn(qd, tau_ext, dt):  # type: ignore[no-untyped-def]
            learned.append(dt)
            return learn(qd, tau_ext, dt)

        tick.collision.update = spy_update  # type: ignore[method-assign]
        tick._learn = spy_learn

        def stalled(sample_dt: float, cycles: int) -> None:
            for s in (fused, reference):
                s.group.transport.sample_dt = sample_dt
                s.clock.stall(cycles)
                s.loop.run(max_ticks=1)
            a, b = fused.tick, tick
            assert a.collision.state.fbuf.tobytes() == b.collision.state.fbuf.tobytes()
            assert a.drag.friction.record.tobytes() == b.drag.friction.record.tobytes()

        stalled(tick.period, 50)  # DC: the drives sampled one cycle after the last
        assert seen == [tick.period], seen
        assert learned in ([], [tick.period]), learned
        stalled(0.0, 9)  # no DC: the loop's dt, as before
        assert abs(seen[-1] - 10 * tick.period) < 1e-9, seen
    finally:
        fused.close()
        reference.close()
