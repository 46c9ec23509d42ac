"""Injected contact pulses: the train, the monitor's trip rule, the observer re-run."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.identify.data import Recording
from hofto_hw.replay.pulses import PulseStats, pulse_train, score, tally, trips
from hofto_hw.replay.runner import run_monitor, run_observer
from safety.collision import CollisionMonitor


def _times(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.uniform(0.008, 0.016, n))  # irregular like the UR10e logs


def test_trips_match_the_collision_monitor() -> None:
    rng = np.random.default_rng(3)
    t = _times(3000)
    qd = np.zeros((t.size, 3))
    est = rng.normal(0.0, 1.0, (t.size, 3)).cumsum(axis=0) * 0.05
    cfg = CollisionConfig(base=[1.0, 1.5, 2.0], debounce_time=0.03)
    thr, joints, _ = run_monitor(
        Recording(t, qd, qd, qd, "synthetic", np.arange(t.size)), est, CollisionMonitor(cfg)
    )
    mine = trips(est, thr, t, cfg.debounce_time)
    for j in range(3):
        first_monitor = np.flatnonzero(joints[:, j])
        first_mine = np.flatnonzero(mine[:, j])
        assert first_monitor.size and first_mine.size
        assert first_mine[0] == first_monitor[0]
        # every rising edge of the monitor's latched state is a debounce met here
        rises = np.flatnonzero(np.diff(joints[:, j].astype(int)) == 1) + 1
        assert np.all(mine[rises, j])


def test_pulse_train_lays_separate_pulses_on_the_joints_in_turn() -> None:
    t = _times(4000, 1)
    qd = np.zeros((t.size, 6))
    qd[t > t[-1] / 2, 2] = 0.3  # the second half moves
    p, pulses = pulse_train(t, qd, 7.0, 0.4, np.random.default_rng(0))
    assert len(pulses) >= 10
    joints = [q.joint for q in pulses]
    assert all((b - a) % 6 == 1 for a, b in itertools.pairwise(joints))
    for a, b in itertools.pairwise(pulses):
        assert t[b.start] - t[a.stop - 1] >= 1.0  # the observer settles in between
    for q in pulses:
        assert np.max(np.abs(p[q.start : q.stop, q.joint])) == pytest.approx(7.0, rel=0.02)
        assert q.rest == (t[q.stop - 1] <= t[-1] / 2)
    assert np.count_nonzero(p.any(axis=1)) == sum(
        np.count_nonzero(p[q.start : q.stop, q.joint]) for q in pulses
    )


def test_pulse_through_the_momentum_observer_is_found_and_counted(er3a_model) -> None:
    from hofto_hw.config.models import MomentumConfig
    from hofto_hw.observers import make_observer

    t = np.arange(0.0, 12.0, 0.01)
    q = np.tile(er3a_model.home, (t.size, 1))
    qd = np.zeros_like(q)
    g = er3a_model.create_data().gravity(er3a_model.home).copy()
    rec = Recording(t, q, qd, np.tile(g, (t.size, 1)), "still", np.arange(t.size))
    cfg = MomentumConfig(type="momentum", gain=[20.0] * 6)
    p, pulses = pulse_train(t, qd, 10.0, 0.4, np.random.default_rng(1))
    pulsed = dataclasses.replace(rec, tau=rec.tau - p)
    est = run_observer(pulsed, make_observer(cfg, er3a_model, backend="python"))
    for q_ in pulses:  # a contact p on the held arm is estimated as +p (after the lag)
        seg = est[q_.start : q_.stop, q_.joint]
        peak = seg[np.argmax(np.abs(seg))]
        assert np.sign(peak) == np.sign(p[q_.start : q_.stop, q_.joint].sum())
        assert 8.0 < abs(peak) < 10.0
    thr = np.full_like(est, 5.0)
    delays = score(pulses, est, thr, t, 0.03)
    assert all(d is not None and 0.05 < d < 0.3 for d in delays)
    assert all(d is None for d in score(pulses, est, np.full_like(est, 11.0), t, 0.03))
    stats = PulseStats.empty([10.0], 6)
    tally(stats, 0, pulses, delays)
    assert stats.tries[0, 1].sum() == len(pulses) and stats.hits[0, 1].sum() == len(pulses)
    assert stats.tries[0, 0].sum() == 0  # nothing moved: every pulse is at rest
