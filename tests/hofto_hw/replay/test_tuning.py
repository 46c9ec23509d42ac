"""The tuning engine: calibration objective over every sample, per-joint margin choice."""

from __future__ import annotations

import numpy as np

from hofto_hw.replay.calibrate import fit_envelope
from hofto_hw.replay.pulses import PulseStats
from hofto_hw.replay.tuning import Candidate, choose, thresholds_of


def test_envelope_objective_counts_every_sample() -> None:
    """Motion residuals below min_base cannot bind, but the threshold there still counts:
    covering a slow creep with the velocity term would make every moving threshold huge."""
    n_move, n_creep, n_slow = 800, 100, 100
    qd = np.r_[np.full(n_move, 1.0), np.full(n_creep, 0.04), np.full(n_slow, 0.01)]
    resid = np.r_[np.full(n_move, 0.3), np.full(n_creep, 3.0), np.full(n_slow, 0.6)]
    feats = np.zeros((qd.size, 5))
    feats[:, 0] = 1.0
    feats[:, 1] = qd
    env = fit_envelope(feats, resid, (True, True, False, False, False), min_base=0.5)
    assert np.all(feats @ env >= resid - 1e-9)
    moving_threshold = env[0] + env[1] * 1.0
    assert moving_threshold < 5.0  # the base covers the creep (3 N·m), not kv ≈ 62 N·m·s/rad


def _cand(margin: float, false: list[int], hits: list[float], mt: float = 1.0) -> Candidate:
    stats = PulseStats.empty([10.0], 2)
    stats.tries[0, 0] = 10
    stats.hits[0, 0] = hits
    stats.delays[0][0] = [[0.1] * int(h) for h in hits]
    return Candidate(mt, 0.0, margin, np.asarray(false, dtype=float), stats)


def test_choose_takes_per_joint_the_most_sensitive_margin_without_false_alarms() -> None:
    cands = [
        _cand(0.2, [1, 0], [10, 10]),  # joint 1 false alarm
        _cand(0.6, [0, 0], [8, 7]),
        _cand(1.0, [0, 0], [6, 5]),
        _cand(0.2, [0, 3], [4, 4], mt=2.0),  # joint 2 never clean at this timing...
    ]
    ch = choose(cands)
    assert ch.moving_time == 1.0
    assert ch.margin == [0.6, 0.2]  # joint 2 is clean at 0.2 at this timing
    assert ch.stats.hits[0, 0].tolist() == [8, 10]


def test_thresholds_of_scales_each_joint_by_its_margin() -> None:
    feats = np.ones((4, 2, 5))
    env = np.array([[1.0, 0, 0, 0, 0], [2.0, 0, 0, 0, 0]])
    thr = thresholds_of(feats, env, np.array([0.5, 1.0]))
    assert np.allclose(thr, [[1.5, 4.0]] * 4)


def test_choose_raises_each_margin_by_the_cushion() -> None:
    cands = [
        _cand(0.2, [0, 0], [9, 9]),
        _cand(0.3, [0, 0], [8, 8]),
        _cand(0.5, [0, 0], [6, 6]),
    ]
    assert choose(cands).margin == [0.2, 0.2]
    ch = choose(cands, cushion=0.1)
    assert ch.margin == [0.3, 0.3]
    assert ch.stats.hits[0, 0].tolist() == [8, 8]  # the figures of the margin shipped
    assert choose(cands, cushion=0.15).margin == [0.5, 0.5]  # the next margin tried above
