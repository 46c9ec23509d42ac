"""The tuning engine: calibration objective over every sample, per-joint margin choice."""

from __future__ import annotations

import numpy as np

from hofto_hw.replay.calibrate import fit_envelope
from hofto_hw.replay.pulses import Pulse, PulseStats
from hofto_hw.replay.tuning import (
    Candidate,
    PulsedRun,
    choose,
    judge,
    judge_grid,
    per_joint_best,
    thresholds_grid,
    thresholds_of,
)
from safety.collision.kernel import threshold


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


def test_tuning_thresholds_are_the_monitors_formula() -> None:
    """thresholds_of and the margin grid evaluate the monitor's own threshold function (the
    compiled one, joint by joint) on random features and envelopes."""
    rng = np.random.default_rng(4)
    feats = rng.uniform(0.0, 2.0, (30, 3, 5))
    feats[:, :, 0] = 1.0
    env = rng.uniform(0.0, 1.5, (3, 5))
    margin, rest = np.array([0.1, 0.2, 0.3]), np.array([0.5, 0.0, 1.0])
    thr = thresholds_of(feats, env, margin, rest)
    for k in range(30):
        for j in range(3):
            c = env[j] * (1.0 + margin[j])
            ks = env[j, 4] * (1.0 + rest[j])
            f = feats[k, j]
            want = threshold(c[0], c[1], c[2], c[3], ks, f[1], f[2], f[3], f[4])
            assert thr[k, j] == want
    m_scale, r_scale = np.array([1.0, 1.25, 1.5]), np.array([1.0, 2.0, 3.0])
    grid = thresholds_grid(feats, env, m_scale, r_scale)
    for p in range(3):
        one = thresholds_of(feats, env, np.full(3, m_scale[p] - 1.0), np.full(3, r_scale[p] - 1.0))
        np.testing.assert_allclose(grid[:, :, p], one, rtol=1e-14)


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


class _Rec:
    """The part of a Recording that judging reads (the time stamps)."""

    def __init__(self, t: np.ndarray) -> None:
        self.t = t


def _run(est: np.ndarray, pulsed: np.ndarray, t: np.ndarray, pulses: list) -> PulsedRun:
    return PulsedRun(_Rec(t), est, [[(pulsed, pulses)]])  # type: ignore[arg-type]


def test_judge_grid_fused_rows_decide_on_the_mean_of_their_ratios() -> None:
    """logic: mean: row A alone crosses its threshold, row B stays far below: the mean of the
    ratios (1.5 + 0.2)/2 < 1 neither alarms nor detects; each row judged alone, A does."""
    t = np.arange(400) * 0.01
    n = 2
    quiet_a = np.zeros((t.size, n))
    quiet_a[100:150, 0] = 1.2  # a false alarm of A alone (thr 1)
    pulse = Pulse(1, 2.0, 200, 260, rest=True)
    hit_a = np.zeros((t.size, n))
    hit_a[210:240, 1] = 1.5
    hit_b = np.zeros((t.size, n))
    hit_b[210:240, 1] = 0.2
    thr = np.ones((t.size, n, 1))
    a = _run(quiet_a, hit_a, t, [pulse])
    b = _run(np.zeros((t.size, n)), hit_b, t, [pulse])
    alone = [PulseStats.empty([5.0], n)]
    assert judge_grid([a], [thr], 0.03, alone)[:, 0].tolist() == [True, False]
    assert alone[0].hits[0, 1, 1] == 1
    fused = [PulseStats.empty([5.0], n)]
    assert judge_grid([a, b], [thr, thr], 0.03, fused)[:, 0].tolist() == [False, False]
    assert fused[0].tries[0, 1, 1] == 1 and fused[0].hits[0, 1, 1] == 0
    # a second row that sees the contact too carries it over: (1.5 + 0.9)/2 > 1
    b2 = _run(np.zeros((t.size, n)), hit_b * 4.5, t, [pulse])
    both = [PulseStats.empty([5.0], n)]
    judge_grid([a, b2], [thr, thr], 0.03, both)
    assert both[0].hits[0, 1, 1] == 1


def test_judge_grid_matches_judge_setting_by_setting() -> None:
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.008, 0.016, 3000))
    n = 3
    est = rng.normal(0.0, 1.0, (t.size, n)).cumsum(axis=0) * 0.05
    pulsed = est + rng.normal(0.0, 0.5, est.shape)
    pulses = [
        Pulse(k % n, float(t[s]), s, s + 60, rest=bool(k % 2))
        for k, s in enumerate(range(100, 2900, 150))
    ]
    run = _run(est, pulsed, t, pulses)
    levels = np.array([0.5, 1.0, 2.0, 3.0])
    base = rng.uniform(0.8, 1.2, (t.size, n))
    grid = [PulseStats.empty([5.0], n) for _ in levels]
    false = judge_grid([run], [base[:, :, None] * levels], 0.03, grid)
    for k, lv in enumerate(levels):
        one = PulseStats.empty([5.0], n)
        assert judge(run, base * lv, 0.03, one).tolist() == false[:, k].tolist()
        assert np.array_equal(one.hits, grid[k].hits) and np.array_equal(one.tries, grid[k].tries)
        assert one.delays == grid[k].delays


def _cand2(margin: float, rest: float, false: list[int], hits: list[float]) -> Candidate:
    c = _cand(margin, false, hits)
    c.rest_margin = rest
    return c


def test_choose_raises_the_standstill_margin_by_its_own_cushion() -> None:
    """The margin of the standstill term is chosen and cushioned apart from the others: a
    joint whose rest pulses need a low standstill margin keeps it."""
    cands = [
        _cand2(m, r, [0, 0], [10 - 5 * m - 10 * r] * 2)
        for m in (0.1, 0.2, 0.3)
        for r in (0.0, 0.05, 0.1, 0.2)
    ]
    ch = choose(cands, cushion=0.1, rest_cushion=0.05)
    assert ch.margin == [0.2, 0.2] and ch.rest_margin == [0.05, 0.05]
    ch = choose(cands, cushion=0.1)  # the rest cushion defaults to the cushion
    assert ch.margin == [0.2, 0.2] and ch.rest_margin == [0.1, 0.1]
    # without rest margins the standstill term follows the margin
    assert choose([_cand(0.3, [0, 0], [5, 5])]).rest_margin == [0.3, 0.3]


def test_per_joint_best_takes_each_joint_from_its_best_setting() -> None:
    """Two momentum gains: the first finds more on joint 1, the second on joint 2; the
    combined choice takes each joint's figures, margins and estimate column from its best."""
    t = np.arange(50) * 0.01
    pulse = Pulse(0, 0.1, 10, 30, rest=False)

    def runs(value: float) -> list[PulsedRun]:
        est = np.full((t.size, 2), value)
        return [_run(est, est + 1.0, t, [pulse])]

    a = choose([_cand(0.3, [0, 0], [9, 4])])
    b = choose([_cand(0.6, [0, 0], [5, 8])])
    combined, mixed, pick = per_joint_best([a, b], [runs(1.0), runs(2.0)])
    assert pick == [0, 1]
    assert combined.margin == [0.3, 0.6]
    assert combined.stats.hits[0, 0].tolist() == [9, 8]
    assert mixed[0].est[0].tolist() == [1.0, 2.0]
    assert mixed[0].pulsed[0][0][0][0].tolist() == [2.0, 3.0]
    assert combined.score[0] > max(a.score[0], b.score[0])
