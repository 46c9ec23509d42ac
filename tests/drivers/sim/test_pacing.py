"""WallCycles: plant ticks per exchange by the wall clock."""

from __future__ import annotations

from drivers.sim.pacing import WallCycles


def test_one_tick_per_exchange_at_rate_with_jitter() -> None:
    w = WallCycles(0.005)
    t, counts = 0.0, []
    for k in range(200):
        t = k * 0.005 + (0.003 if k % 7 == 3 else 0.0)  # an exchange 0.6 cycle late now and then
        counts.append(w.due(t))
    assert counts[0] == 1
    assert sum(counts) in (200, 201), sum(counts)
    assert max(counts) <= 2


def test_a_stall_is_caught_up_a_pause_is_not() -> None:
    w = WallCycles(0.005, limit=0.15)
    for k in range(10):
        w.due(k * 0.005)
    assert w.due(0.045 + 0.1) == 20  # 100 ms after the last: 20 cycles
    assert w.due(0.150) == 1
    assert w.due(0.150 + 1.0) == 1  # a second without exchanges: start-up, not a stall
    assert w.capped == 1
    assert w.caught_up == 19
