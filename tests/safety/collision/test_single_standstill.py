"""The standstill term of the collision monitor: separate from the reversal term, off by
default."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.config.collision import CollisionConfig
from safety.collision import CollisionMonitor


def _threshold(cfg: CollisionConfig, qd: float, ticks: int = 300) -> np.ndarray:
    mon = CollisionMonitor(cfg)
    v = np.full(2, qd)
    mon.reset(v)
    for _ in range(ticks):
        mon.update(np.zeros(2), v, 0.01)
    return mon.threshold.copy()


def test_standstill_margin_applies_at_rest_only_however_long() -> None:
    cfg = CollisionConfig(base=[2.0, 1.0], standstill_margin=[8.0, 3.0], reversal_margin=[5.0, 5.0])
    assert _threshold(cfg, 0.0) == pytest.approx([10.0, 4.0])  # 3 s at rest: still there
    assert _threshold(cfg, 0.5) == pytest.approx([2.0, 1.0])  # in steady motion: the base


def test_without_standstill_margin_the_threshold_is_unchanged() -> None:
    cfg = CollisionConfig(base=[2.0, 1.0])
    assert _threshold(cfg, 0.0) == pytest.approx([2.0, 1.0])


def test_a_held_residual_at_rest_no_longer_trips_with_the_standstill_term() -> None:
    held = np.array([6.0, 0.0])  # friction held at rest, unmodelled
    for ks, expected in ((None, True), ([5.0, 0.0], False)):
        mon = CollisionMonitor(CollisionConfig(base=[3.0, 3.0], standstill_margin=ks))
        mon.reset(np.zeros(2))
        tripped = False
        for _ in range(50):
            tripped |= mon.update(held, np.zeros(2), 0.01)
        assert tripped is expected


def test_standstill_time_lets_the_indicator_rise_after_a_stop_and_drop_at_once() -> None:
    mon = CollisionMonitor(
        CollisionConfig(base=[1.0], standstill_margin=[4.0], standstill_time=1.0)
    )
    mon.reset(np.array([0.5]))
    for _ in range(50):
        mon.update(np.zeros(1), np.array([0.5]), 0.01)
    assert mon.still[0] < 1e-6
    for _ in range(10):  # 0.1 s after the stop
        mon.update(np.zeros(1), np.zeros(1), 0.01)
    assert 0.05 < mon.still[0] < 0.15
    for _ in range(500):  # 5 s at rest
        mon.update(np.zeros(1), np.zeros(1), 0.01)
    assert mon.threshold[0] == pytest.approx(5.0, rel=1e-2)
    mon.update(np.zeros(1), np.array([0.5]), 0.01)
    assert mon.threshold[0] == pytest.approx(1.0, abs=1e-6)
