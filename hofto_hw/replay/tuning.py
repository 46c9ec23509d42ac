"""Threshold settings chosen by cross-validation over contact-free recordings with injected
pulses (the engine behind ``hofto-hw tune``).

The recordings (free motion and static holds, no contact) are split into ``folds`` groups.
For each candidate timing of the monitor (``moving_time``: how long after a stop the reversal
term lasts, i.e. covers the observer's lag behind the deceleration; ``standstill_time``: how
long after a stop the standstill term takes to rise to the held-friction margin) the envelope
of the sustained residual is fitted (linear program, :mod:`hofto_hw.replay.calibrate`) on all
folds but one, and the left-out fold is judged with the monitor's trip rule: a joint that
trips on the contact-free estimate is a false alarm; injected pulses
(:mod:`hofto_hw.replay.pulses`) give the detection rate and delay. Every calibration margin
is judged on the same fits (the margin only scales the envelope). Per joint the margin with 0
false alarms on every left-out fold and the most pulses found wins; the timing with the most
pulses over all joints (each at its best margin) wins. Joints are independent in the monitor
(each trips on its own threshold), which is why the margin can be chosen per joint.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.errors import UserError
from hofto_hw.identify.data import Recording
from hofto_hw.observers.base import Observer
from hofto_hw.replay.calibrate import (
    config_from_envelope,
    features,
    fit_envelope,
    sustained,
)
from hofto_hw.replay.pulses import (
    Pulse,
    PulseStats,
    pulse_train,
    score,
    tally,
    time_above,
    trips,
)
from hofto_hw.replay.runner import run_observer
from safety.collision.kernel import threshold

FloatArray = NDArray[np.float64]
TERMS = (True, True, True, True, True)


@dataclass
class PulsedRun:
    """One contact-free recording, its estimate ``est`` (N, n) [N·m], and per amplitude a
    list of rounds (estimate with the pulse train (N, n), the pulses)."""

    rec: Recording
    est: FloatArray
    pulsed: list[list[tuple[FloatArray, list[Pulse]]]]


def pulsed_runs(
    recs: list[Recording],
    make_observer: Callable[[Recording], Observer],
    amplitudes: list[float],
    width: float,
    rounds: int,
    seed: int,
) -> list[PulsedRun]:
    """Run the observer over each recording, then once per amplitude and round with a pulse
    train subtracted from the measured torque (same seed: same pulse times for every
    observer and setting)."""
    out = []
    for i, rec in enumerate(recs):
        est = run_observer(rec, make_observer(rec))
        per_amp = []
        for amp in amplitudes:
            rng = np.random.default_rng([seed, i])  # same times for every amplitude
            rounds_out = []
            for _ in range(rounds):
                p, pulses = pulse_train(rec.t, rec.qd, amp, width, rng)
                pulsed = dataclasses.replace(rec, tau=rec.tau - p)
                rounds_out.append((run_observer(pulsed, make_observer(rec)), pulses))
            per_amp.append(rounds_out)
        out.append(PulsedRun(rec, est, per_amp))
    return out


def scaled(
    env: FloatArray, margin: FloatArray, rest_margin: FloatArray | None = None
) -> FloatArray:
    """Envelope (n, 5) scaled per joint by 1 + margin (n,), its standstill column by
    1 + rest_margin (n,) instead when given."""
    out = env * (1.0 + margin)[:, None]
    if rest_margin is not None:
        out[:, 4] = env[:, 4] * (1.0 + rest_margin)
    return out


def thresholds_of(
    feats: FloatArray, env: FloatArray, margin: FloatArray, rest_margin: FloatArray | None = None
) -> FloatArray:
    """(N, n) thresholds [N·m] from features (N, n, 5) [1, |qd|, |a|, r, s] and envelope (n,
    5)·(1 + margin (n,)) (the standstill term by 1 + rest_margin (n,) when given): the
    monitor's own threshold formula (safety.collision.kernel.threshold, run as Python on
    arrays)."""
    c = scaled(env, margin, rest_margin)
    f = feats
    return _threshold(
        c[:, 0] * f[:, :, 0], c[:, 1], c[:, 2], c[:, 3], c[:, 4],
        f[:, :, 1], f[:, :, 2], f[:, :, 3], f[:, :, 4],
    )  # fmt: skip


def thresholds_grid(
    feats: FloatArray, env: FloatArray, m_scale: FloatArray, r_scale: FloatArray
) -> FloatArray:
    """(N, n, P) thresholds [N·m] for P margin settings at once: features (N, n, 5), envelope
    (n, 5), every term but the standstill one scaled by ``m_scale`` (P,), the standstill term
    by ``r_scale`` (P,) (the same formula as :func:`thresholds_of`, a last axis for P)."""
    c = env[:, :, None] * m_scale  # (n, 5, P)
    c[:, 4] = env[:, 4, None] * r_scale
    f = feats[:, :, :, None]
    return _threshold(
        c[:, 0] * f[:, :, 0], c[:, 1], c[:, 2], c[:, 3], c[:, 4],
        f[:, :, 1], f[:, :, 2], f[:, :, 3], f[:, :, 4],
    )  # fmt: skip


_threshold = getattr(threshold, "py_func", threshold)


def trips_of(above: NDArray[np.bool_], t: FloatArray, debounce: float) -> NDArray[np.bool_]:
    """:func:`hofto_hw.replay.pulses.trips` on a precomputed (N, m) above-threshold mask."""
    return time_above(above, t) >= max(debounce - 1e-9, 1e-12)


def judge(run: PulsedRun, thr: FloatArray, debounce: float, stats: PulseStats) -> NDArray[np.bool_]:
    """Tally the run's pulses against thresholds ``thr`` (N, n) into ``stats``; returns which
    joints (n,) trip on the contact-free estimate (false alarms)."""
    t = run.rec.t
    for a, rounds in enumerate(run.pulsed):
        for est, pulses in rounds:
            tally(stats, a, pulses, score(pulses, est, thr, t, debounce))
    return trips(run.est, thr, t, debounce).any(axis=0)


def judge_grid(
    runs: list[PulsedRun], thrs: list[FloatArray], debounce: float, stats: list[PulseStats]
) -> NDArray[np.bool_]:
    """:func:`judge` for P threshold settings at once, and for fused rows: ``runs`` one per row
    (the same recording and pulses, each row's observer), ``thrs`` their thresholds (N, n, P),
    ``stats`` one per setting. One row: a joint trips when |est| > thr for ``debounce``; two
    or more: when the mean of the rows' ratios |est_r| / thr_r > 1 for ``debounce`` (the
    monitor's ``logic: mean``). Returns (n, P): which joints trip on the contact-free
    estimates (false alarms) per setting."""
    t = runs[0].rec.t
    n, P = thrs[0].shape[1:]

    def tripped(ests: list[FloatArray]) -> NDArray[np.bool_]:
        if len(ests) == 1:
            above = np.abs(ests[0])[:, :, None] > thrs[0]
        else:
            ratio = sum(np.abs(e)[:, :, None] / th for e, th in zip(ests, thrs, strict=True))
            above = ratio / len(ests) > 1.0
        return trips_of(above.reshape(t.size, n * P), t, debounce).reshape(t.size, n, P)

    for a, rounds in enumerate(runs[0].pulsed):
        for i, (_, pulses) in enumerate(rounds):
            tr = tripped([r.pulsed[a][i][0] for r in runs])
            for p in pulses:
                win = tr[p.start : p.stop, p.joint]  # (L, P)
                hit = win.any(axis=0)
                first = win.argmax(axis=0)
                s = int(p.rest)
                for k in range(P):
                    st = stats[k]
                    st.tries[a, s, p.joint] += 1
                    if hit[k]:
                        st.hits[a, s, p.joint] += 1
                        st.delays[a][s][p.joint].append(float(t[p.start + first[k]] - p.t0))
    return tripped([r.est for r in runs]).any(axis=0)


def envelopes(
    feats: FloatArray, sus: FloatArray, rest_weight: FloatArray, min_base: float
) -> FloatArray:
    """Envelope (n, 5) of every joint, each with its own rest weight (n,)."""
    n = sus.shape[1]
    return np.stack(
        [fit_envelope(feats[:, j], sus[:, j], TERMS, min_base, rest_weight[j]) for j in range(n)]
    )


@dataclass
class Candidate:
    """Cross-validated figures of one timing, rest weight and margin: ``false`` (n,) left-out
    runs with a false trip per joint, ``stats`` the left-out pulses. ``rest_margin`` scales
    the standstill term (None: ``margin`` does, as every other term)."""

    moving_time: float
    standstill_time: float
    margin: float
    false: FloatArray
    stats: PulseStats
    rest_weight: float = 1.0
    rest_margin: float | None = None

    @property
    def rest(self) -> float:
        """The margin on the standstill term."""
        return self.margin if self.rest_margin is None else self.rest_margin


def folds_of(n_runs: int, folds: int) -> list[int]:
    """Fold index of each run (round robin in the order given)."""
    if not 2 <= folds <= n_runs:
        raise UserError(f"tune: --folds must be 2..{n_runs} (number of recordings), got {folds}")
    return [i % folds for i in range(n_runs)]


def cross_validate(
    runs: list[PulsedRun] | list[list[PulsedRun]],
    template: CollisionConfig,
    moving_times: list[float],
    standstill_times: list[float],
    margins: list[float],
    folds: int,
    min_base: float = 1.0,
    say: Callable[[str], None] = lambda _m: None,
    rest_weights: tuple[float, ...] = (1.0,),
    rest_margins: list[float] | None = None,
    feature_cache: dict[tuple[float, float], list[FloatArray]] | None = None,
) -> list[Candidate]:
    """Figures on the left-out folds of every (moving_time, standstill_time, rest weight,
    margin[, rest margin]); the rest weight (see :func:`hofto_hw.replay.calibrate.fit_envelope`)
    and the margins are chosen per joint later.

    ``runs``: one observer's pulsed runs, or a list of rows (each row one observer's runs of
    the same recordings and pulses, see :func:`pulsed_runs`): the rows are judged fused, the
    monitor's ``logic: mean`` (:func:`judge_fused`), each row with its own envelope scaled by
    the same margins. ``rest_margins``: margins of the standstill term tried with every
    margin (None: the standstill term takes the margin of the others). ``feature_cache``:
    the runs' features per (moving_time, standstill_time), shared between calls on the same
    recordings (they depend on the motion only)."""
    rows: list[list[PulsedRun]] = runs if isinstance(runs[0], list) else [runs]  # type: ignore[list-item,assignment]
    first = rows[0]
    n = first[0].est.shape[1]
    amps = len(first[0].pulsed)
    fold = folds_of(len(first), folds)
    deb = template.debounce_time
    sus = [[sustained(r.rec, r.est, deb) for r in row] for row in rows]
    pairs: list[tuple[float, float | None]] = (
        [(m, None) for m in margins]
        if rest_margins is None
        else [(m, r) for m in margins for r in rest_margins]
    )
    out = []
    for mt in moving_times:
        for st in standstill_times:
            tmpl = template.model_copy(update={"moving_time": mt, "standstill_time": st})
            cache = {} if feature_cache is None else feature_cache
            if (mt, st) not in cache:
                cache[(mt, st)] = [features(r.rec, tmpl) for r in first]
            feats = cache[(mt, st)]
            for w in rest_weights:
                cands = {
                    pr: Candidate(
                        mt, st, pr[0], np.zeros(n), PulseStats.empty([0.0] * amps, n), w, pr[1]
                    )
                    for pr in pairs
                }
                cand_list = list(cands.values())
                stats = [c.stats for c in cand_list]
                m_scale = np.array([1.0 + m for m, _ in pairs])
                r_scale = np.array([1.0 + (m if rm is None else rm) for m, rm in pairs])
                for f in range(folds):
                    fit = [i for i in range(len(first)) if fold[i] != f]
                    feats_fit = np.concatenate([feats[i] for i in fit])
                    envs = [
                        envelopes(
                            feats_fit, np.concatenate([s[i] for i in fit]), np.full(n, w), min_base
                        )
                        for s in sus
                    ]
                    for i in (i for i in range(len(first)) if fold[i] == f):
                        # thresholds are linear in the margins: (N, n, P) for every pair at once
                        thrs = [thresholds_grid(feats[i], e, m_scale, r_scale) for e in envs]
                        false = judge_grid([row[i] for row in rows], thrs, deb, stats)
                        for k, c in enumerate(cand_list):
                            c.false += false[:, k]
                for c in cands.values():
                    rest = "" if c.rest_margin is None else f", rest margin {c.rest_margin:g}"
                    say(
                        f"moving_time {mt:g} s, standstill_time {st:g} s, rest weight {w:g}, "
                        f"margin {c.margin:g}{rest}: false trips per joint "
                        f"{c.false.astype(int).tolist()}, pulses found "
                        f"{int(c.stats.hits.sum())}/{int(c.stats.tries.sum())}"
                    )
                out.extend(cands.values())
    return out


def _joint_score(stats: PulseStats, j: int) -> tuple[float, float]:
    """(sum of detection rates over amplitudes and states, -median delay) of joint j."""
    rate = np.nan_to_num(stats.rate[:, :, j])
    d = [x for state in stats.delays for row in state for x in row[j]]
    return float(rate.sum()), -float(np.median(d)) if d else -np.inf


@dataclass
class Choice:
    """The chosen timing, per-joint margins and their left-out figures (``stats``, per joint
    from that joint's chosen candidate; ``false`` (n,)). ``rest_margin`` (n,): the margins of
    the standstill term (equal to ``margin`` unless rest margins were searched)."""

    moving_time: float
    standstill_time: float
    margin: list[float]
    false: FloatArray
    stats: PulseStats
    rest_weight: list[float] = dataclasses.field(default_factory=list)
    #: (sum of left-out detection rates over joints, amplitudes and states, -median delay)
    score: tuple[float, float] = (0.0, 0.0)
    rest_margin: list[float] = dataclasses.field(default_factory=list)


def choose(
    candidates: list[Candidate], cushion: float = 0.0, rest_cushion: float | None = None
) -> Choice:
    """Per joint the margins with 0 false trips and the best score, raised by ``cushion`` (to
    the nearest margin tried at or above it that is clean too, with the same rest weight: a
    margin just clean on the left-out runs is clean by luck as often as not); the standstill
    term's margin by ``rest_cushion`` (default: ``cushion``); the timing whose joints score
    best in total (a timing where some joint has no margin without false trips loses)."""
    rc = cushion if rest_cushion is None else rest_cushion
    timings = sorted({(c.moving_time, c.standstill_time) for c in candidates})
    best: tuple[tuple[float, ...], Choice] | None = None
    for mt, st in timings:
        group = [c for c in candidates if (c.moving_time, c.standstill_time) == (mt, st)]
        n = group[0].false.size
        picks = []
        for j in range(n):
            ok = [c for c in group if c.false[j] == 0]
            if not ok:
                break
            pick = max(
                ok, key=lambda c: (_joint_score(c.stats, j), -c.margin, -c.rest, -c.rest_weight)
            )
            above = [
                c
                for c in ok
                if c.rest_weight == pick.rest_weight
                and c.margin >= pick.margin + cushion - 1e-9
                and c.rest >= pick.rest + rc - 1e-9
            ]
            picks.append(min(above, key=lambda c: (c.margin, c.rest)) if above else pick)
        if len(picks) < n:
            continue
        stats = PulseStats.empty(group[0].stats.amplitudes, n)
        for j, c in enumerate(picks):
            stats.add(c.stats.joint(j))
        total = sum(_joint_score(stats, j)[0] for j in range(n))
        delays = [x for a in stats.delays for s in a for row in s for x in row]
        key = (total, -float(np.median(delays)) if delays else -np.inf)
        choice = Choice(
            mt,
            st,
            [c.margin for c in picks],
            np.zeros(n),
            stats,
            [c.rest_weight for c in picks],
            key,
            [c.rest for c in picks],
        )
        if best is None or key > best[0]:
            best = (key, choice)
    if best is None:
        raise UserError(
            "tune: no setting gave 0 false alarms on every joint of the left-out runs "
            "(try larger --margins)"
        )
    return best[1]


def refit(
    recs: list[Recording],
    ests: list[FloatArray],
    monitor: CollisionConfig,
    margin: list[float],
    rest_weight: list[float] | None = None,
    min_base: float = 1.0,
    rest_margin: list[float] | None = None,
) -> CollisionConfig:
    """``monitor``'s timing and filters with its per-joint terms fitted on ``recs`` (their
    contact-free estimates ``ests`` (N_i, n) [N·m]) and scaled by the per-joint ``margin``
    (the standstill term by ``rest_margin`` when given)."""
    n = len(margin)
    feats = np.concatenate([features(r, monitor) for r in recs])
    sus = np.concatenate(
        [sustained(r, e, monitor.debounce_time) for r, e in zip(recs, ests, strict=True)]
    )
    weights = np.asarray(rest_weight or [1.0] * n)
    env = envelopes(feats, sus, weights, min_base)
    m = np.asarray(margin, dtype=float)
    rm = None if not rest_margin else np.asarray(rest_margin, dtype=float)
    return config_from_envelope(monitor, scaled(env, m, rm), 0.0, TERMS)


def final_config(
    runs: list[PulsedRun], template: CollisionConfig, choice: Choice, min_base: float = 1.0
) -> tuple[CollisionConfig, FloatArray]:
    """The monitor config fitted on every run with the chosen timing and margins; and the
    peak |est| (n,) [N·m] on them."""
    tmpl = template.model_copy(
        update={"moving_time": choice.moving_time, "standstill_time": choice.standstill_time}
    )
    cfg = refit(
        [r.rec for r in runs],
        [r.est for r in runs],
        tmpl,
        choice.margin,
        choice.rest_weight,
        min_base,
        choice.rest_margin,
    )
    peak = np.max(np.abs(np.concatenate([r.est for r in runs])), axis=0)
    return cfg, peak


def per_joint_best(
    choices: list[Choice], runs: list[list[PulsedRun]]
) -> tuple[Choice, list[PulsedRun], list[int]]:
    """For an observer whose joints are decoupled (the momentum observer: joint j's estimate
    depends on joint j's gain only), the best setting per joint: of each joint, the figures,
    margins and estimates of the setting (``choices[i]`` with its ``runs[i]``, all of the same
    recordings and pulses) that scores best on it. Returns the combined choice, runs and
    which setting each joint took. The settings must share the monitor timing (the timing
    is common to all joints); otherwise the best whole setting is returned."""
    timing = {(c.moving_time, c.standstill_time) for c in choices}
    best_whole = max(range(len(choices)), key=lambda i: choices[i].score)
    n = choices[0].false.size
    if len(timing) > 1:
        return choices[best_whole], runs[best_whole], [best_whole] * n
    pick = [
        max(range(len(choices)), key=lambda i, j=j: (_joint_score(choices[i].stats, j), -i))
        for j in range(n)
    ]
    stats = PulseStats.empty(choices[0].stats.amplitudes, n)
    for j, i in enumerate(pick):
        stats.add(choices[i].stats.joint(j))
    total = sum(_joint_score(stats, j)[0] for j in range(n))
    delays = [x for a in stats.delays for s in a for row in s for x in row]
    first = choices[0]
    combined = Choice(
        first.moving_time,
        first.standstill_time,
        [choices[i].margin[j] for j, i in enumerate(pick)],
        np.zeros(n),
        stats,
        [choices[i].rest_weight[j] for j, i in enumerate(pick)],
        (total, -float(np.median(delays)) if delays else -np.inf),
        [choices[i].rest_margin[j] for j, i in enumerate(pick)],
    )

    def column_mix(arrays: list[FloatArray]) -> FloatArray:
        out = arrays[0].copy()
        for j, i in enumerate(pick):
            out[:, j] = arrays[i][:, j]
        return out

    mixed = []
    for k, run in enumerate(runs[0]):
        per_amp = [
            [
                (column_mix([runs[i][k].pulsed[a][r][0] for i in range(len(runs))]), pulses)
                for r, (_, pulses) in enumerate(rounds)
            ]
            for a, rounds in enumerate(run.pulsed)
        ]
        mixed.append(PulsedRun(run.rec, column_mix([rs[k].est for rs in runs]), per_amp))
    return combined, mixed, pick
