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
