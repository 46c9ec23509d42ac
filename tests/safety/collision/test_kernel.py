"""The monitor tick (safety/collision/kernel.py, compiled and as its Python source) against
the numpy reference (tests/safety/collision/reference.py): same ratios and thresholds to
1e-12, identical trips, releases, decisions and first crossings over thousands of random
steps with NaN/inf injections, both phases, every fusion logic, several rows."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.config.safety import CollisionLevelsConfig, StopCategories
from safety.collision import CollisionLevels, from_thresholds
from safety.collision import kernel as K
from safety.collision import params as P
from safety.collision import state as S
from safety.stop import StopController
from tests.safety.collision.reference import ReferenceLevels

require_compiled_kernels()

N = 6
STEPS = 4000
TOL = 1e-12


def _levels_cfg(logic: str, observer: str = "both") -> CollisionLevelsConfig:
    return CollisionLevelsConfig(
        observer=observer,
        logic=logic,
        contact={"nominal": [1.2] * N, "acceleration": [3.0] * N},
        collision={"nominal": [4.0, 4.0, 3.0, 2.0, 2.0, 1.5], "acceleration": [6.0] * N},
        velocity_gain=[0.3] * N,
        acceleration_gain=[0.05] * N,
        reversal_margin=[2.0] * N,
        standstill_margin=[1.0] * N,
        standstill_time=0.05,
        acceleration_phase=2.0,
        phase_hold=0.02,
        debounce_time=0.003,
        release_time=0.005,
    )


def _inputs(k: int, seed: int, bad: bool = True):
    rng = np.random.default_rng(seed)
    t = np.arange(STEPS) * 1e-3
    qd = 0.3 * np.sin(np.outer(t, rng.uniform(0.5, 4.0, N))) + rng.normal(0, 2e-3, (STEPS, N))
    qd[1000:1400] *= 0.01  # a rest: standstill and reversal terms
    tau = rng.normal(0, 1.5, (STEPS, k, N))
    for _ in range(40):  # contacts on one row or on all rows, that trip and release
        a, j = rng.integers(0, STEPS - 60), rng.integers(0, N)
        rows = slice(None) if rng.random() < 0.5 else rng.integers(0, k)
        tau[a : a + rng.integers(2, 60), rows, j] += rng.choice([-12.0, 12.0])
    qdd = rng.normal(0, 0.3, (STEPS, N))
    for _ in range(20):  # acceleration phases
        a = rng.integers(0, STEPS - 30)
        qdd[a : a + 30, rng.integers(0, N)] = 5.0
    dt = 1e-3 * (1.0 + 0.2 * rng.random(STEPS))
    if bad:
        for _ in range(60):
            tau[rng.integers(STEPS), rng.integers(k), rng.integers(N)] = rng.choice(
                [np.nan, np.inf, -np.inf]
            )
        for _ in range(30):
            qd[rng.integers(STEPS), rng.integers(N)] = rng.choice([np.nan, np.inf])
    return tau, qd, qdd, dt


_FIELDS = ("lev", "feat", "joints", "hits", "level_joints", "row_hit", "bad", "sst", "first_tick")


def _trace(mon, tau, qd, qdd, dt) -> dict[str, np.ndarray]:
    """Every state array after every step (the comparison runs after the loop)."""
    s = mon.state
    out = {f: np.zeros((STEPS, *getattr(s, f).shape), getattr(s, f).dtype) for f in _FIELDS}
    out["collision"] = np.zeros(STEPS, dtype=bool)
    for i in range(STEPS):
        out["collision"][i] = mon.step(tau[i], qd[i], qdd[i], dt[i], i)
        for f in _FIELDS:
            out[f][i] = getattr(s, f)
    return out


def _lockstep(make, k: int, seed: int) -> dict[str, int]:
    """The reference, the kernel's Python source (backend python) and the compiled kernel over
    the same inputs."""
    fast, source = make("numba"), make("python")
    assert fast.backend == "numba" and source.backend == "python"
    ref = ReferenceLevels(fast.params)
    inputs = _inputs(k, seed)
    a = _trace(ref, *inputs)
    for mon in (fast, source):
        b = _trace(mon, *inputs)
        for f in ("collision", "joints", "hits", "level_joints", "row_hit", "bad", "sst"):
            np.testing.assert_array_equal(a[f], b[f], err_msg=f)  # identical trips, releases
        np.testing.assert_array_equal(a["first_tick"], b["first_tick"])
        for f in ("lev", "feat"):
            np.testing.assert_allclose(b[f], a[f], rtol=TOL, atol=TOL, err_msg=f)
    col = a["collision"]
    L = a["hits"].shape[1] - 1
    return {
        "collision": int(col.sum()),
        "release": int((col[:-1] & ~col[1:]).sum()),
        "contact": int(a["hits"][:, 0].sum()) if L > 1 else 1,
        "accel_phase": int(a["sst"][:, S.ST_ACCEL_PHASE].sum()),
        "nominal_phase": int((a["sst"][:, S.ST_ACCEL_PHASE] == 0).sum()),
        "nonfinite": int(a["hits"][:, L].sum()),
    }


@pytest.mark.parametrize("logic", ["any", "all", "mean"])
def test_levels_numpy_and_compiled_agree(logic: str) -> None:
    rows = ["hofto", "momentum", "eso"]
    cfg = _levels_cfg(logic)
    seen = _lockstep(lambda b: CollisionLevels(cfg, rows, backend=b), len(rows), seed=3)
    # the run exercised what it claims to compare
    assert all(v > 0 for v in seen.values()), seen


@pytest.mark.parametrize("logic", ["any", "mean"])
def test_thresholds_rows_numpy_and_compiled_agree(logic: str) -> None:
    a = CollisionConfig(
        base=[3.0, 4.0, 2.0, 1.0, 1.0, 1.0],
        velocity_gain=[1.0] * N,
        acceleration_gain=[0.2] * N,
        reversal_margin=[3.0] * N,
        standstill_margin=[2.0] * N,
        debounce_time=0.002,
        release_time=0.004,
    )
    b = a.model_copy(update={"base": [5.0, 2.0, 2.5, 1.5, 0.8, 1.2], "reversal_margin": None})
    p = from_thresholds({"hofto": a, "momentum": b}, logic=logic)
    seen = _lockstep(lambda be: CollisionLevels.from_params(p, backend=be), 2, seed=5)
    assert seen["collision"] > 0 and seen["release"] > 0 and seen["nonfinite"] > 0


def test_kernel_indices_match_the_layouts() -> None:
    for name in ("S_V_REV", "S_TAU_A", "S_MOVING_TIME", "S_REVERSAL_TIME", "S_V_STILL"):
        assert getattr(K, name) == getattr(P, name)
    for name in ("S_STILL_TIME", "S_ACCEL_LEVEL", "S_PHASE_HOLD", "S_TRIP_AFTER"):
        assert getattr(K, name) == getattr(P, name)
    assert (K.S_RELEASE_AFTER, K.S_RELEASE_RATIO, K.S_LOGIC) == (
        P.S_RELEASE_AFTER,
        P.S_RELEASE_RATIO,
        P.S_LOGIC,
    )
    assert (K.F_QD_PREV, K.F_ACCEL, K.F_MOVING, K.F_REVERSAL, K.F_STILL, K.F_QD_OK) == (
        S.F_QD_PREV,
        S.F_ACCEL,
        S.F_MOVING,
        S.F_REVERSAL,
        S.F_STILL,
        S.F_QD_OK,
    )
    assert (K.ST_STARTED, K.ST_PHASE_LEFT, K.ST_ACCEL_PHASE) == (
        S.ST_STARTED,
        S.ST_PHASE_LEFT,
        S.ST_ACCEL_PHASE,
    )
    assert (K.L_THR, K.L_RATIO, K.L_ABOVE, K.L_BELOW) == (S.L_THR, S.L_RATIO, S.L_ABOVE, S.L_BELOW)
    assert K.N_SCAL == P.N_SCAL
    assert [K.LOGIC_ANY, K.LOGIC_ALL, K.LOGIC_MEAN] == [P.LOGICS.index(x) for x in P.LOGICS]


def test_compiled_update_allocates_nothing() -> None:
    mon = CollisionLevels(_levels_cfg("mean"), ["hofto", "momentum"], backend="numba")
    stop = StopController.from_config(StopCategories())
    tau = np.full((2, N), 0.5)
    q = qd = qdd = np.zeros(N)
    for i in range(10):
        stop.begin_tick(i)
        mon.update(stop, tau, q, qd, qdd, 1e-3)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for i in range(3000):
        stop.begin_tick(10 + i)
        mon.update(stop, tau, q, qd, qdd, 1e-3)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert grown < 2000  # bytes: no array per tick


@pytest.mark.parametrize("logic", ["any", "mean"])
def test_update_flags_agree_and_say_what_the_state_says(logic: str) -> None:
    """update's one int (COLLIDED | CONTACT | NONFINITE) from either backend: the same, tick by
    tick, as the state's own answers; the stop controllers see the same events."""
    cfg, rows = _levels_cfg(logic), ["hofto", "momentum", "eso"]
    tau, qd, qdd, dt = _inputs(len(rows), seed=11)
    q = np.zeros(N)
    seen: dict[str, list[int]] = {}
    stops = {}
    for be in ("python", "numba"):
        mon = CollisionLevels(cfg, rows, backend=be)
        stop = StopController.from_config(StopCategories())
        flags = []
        for i in range(STEPS):
            stop.begin_tick(i)
            f = mon.update(stop, tau[i], q, qd[i], qdd[i], dt[i])
            assert bool(f & S.COLLIDED) == mon.collision
            assert bool(f & S.CONTACT) == mon.contact
            assert bool(f & S.NONFINITE) == mon.fault_nonfinite
            flags.append(f)
        seen[be], stops[be] = flags, stop
    ref = ReferenceLevels(mon.params)
    expected = []
    for i in range(STEPS):
        ref.step(tau[i], qd[i], qdd[i], dt[i], i)
        expected.append(S.flags_of(ref.state.hits))
    assert seen["python"] == seen["numba"] == expected
    f = np.array(seen["python"])
    for bit in (S.COLLIDED, S.CONTACT, S.NONFINITE):
        assert (f & bit).any() and not (f & bit).all(), bit  # the run exercised each flag
    a, b = stops["python"].events, stops["numba"].events
    assert a.count == b.count > 0
    for name in ("tick", "kind", "joint", "category"):
        np.testing.assert_array_equal(getattr(a, name)[: a.count], getattr(b, name)[: b.count])
    np.testing.assert_allclose(b.value[: b.count], a.value[: a.count], rtol=TOL, atol=TOL)


def test_flag_bits_match_the_state() -> None:
    assert (K.COLLIDED, K.CONTACT, K.NONFINITE) == (S.COLLIDED, S.CONTACT, S.NONFINITE)


def test_features_are_the_ticks_and_agree_with_the_reference() -> None:
    """CollisionLevels.features (what calibration reads) advances the features as a tick does:
    the reference's features over random velocities with NaN/inf, both backends."""
    cfg, rows = _levels_cfg("any"), ["hofto", "momentum"]
    _, qd, _, dt = _inputs(len(rows), seed=13)
    for be in ("python", "numba"):
        mon = CollisionLevels(cfg, rows, backend=be)
        ref = ReferenceLevels(mon.params)
        for i in range(STEPS):
            mon.features(qd[i], dt[i])
            ref._step.features(qd[i], dt[i])
            np.testing.assert_allclose(mon.state.feat, ref.state.feat, rtol=TOL, atol=TOL)
            np.testing.assert_array_equal(mon.state.bad, ref.state.bad)
        assert mon.state.feat[S.F_STILL].min() < 0.5 < mon.state.feat[S.F_REVERSAL].max()


def test_threshold_formula_on_arrays_is_the_kernels() -> None:
    """K.threshold run as Python on arrays (tuning's use) gives the compiled scalar's values
    bit for bit, and the formula of safety/collision/__init__.py."""
    rng = np.random.default_rng(2)
    args = rng.uniform(0.0, 3.0, (9, 50))
    as_arrays = K.threshold.py_func(*args)
    compiled = np.array([K.threshold(*args[:, i]) for i in range(50)])
    np.testing.assert_array_equal(as_arrays, compiled)
    base, kv, ka, kr, ks, aq, aa, r, st = args
    np.testing.assert_allclose(as_arrays, base + kv * aq + ka * aa + kr * r + ks * st, rtol=1e-14)


def test_standstill_indicator_is_one_formula_for_the_monitor_and_calibration() -> None:
    """standstill_now (compiled and as Python) is exp(-(v/v_s)²) to 1e-12 (numpy's exp and a
    division in the reference), zero, NaN and infinite velocities included; with no
    standstill time the monitor's feature is exactly it."""
    require_compiled_kernels()
    rng = np.random.default_rng(5)
    v_s = 0.02
    v = np.concatenate([rng.normal(0.0, 0.05, 500), [0.0, -0.0, np.inf, -np.inf, np.nan]])
    ref = np.exp(-((v / v_s) ** 2))
    for fn in (K.standstill_now, K.standstill_now.py_func):
        got = np.array([fn(x, 1.0 / v_s) for x in v])
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12, equal_nan=True)
    n = 4
    feat, sst, bad = np.zeros((6, n)), np.zeros(3), np.zeros(n, dtype=bool)
    scal = np.zeros(P.N_SCAL)
    scal[[P.S_V_REV, P.S_TAU_A, P.S_V_STILL, P.S_MOVING_TIME, P.S_REVERSAL_TIME]] = (
        0.05,
        0.01,
        v_s,
        0.5,
        0.5,
    )
    scal[P.S_STILL_TIME] = 0.0
    qd = rng.normal(0.0, 0.03, n)
    K.features_step(feat, sst, bad, scal, qd, 1e-3)
    expect = [K.standstill_now(x, 1.0 / v_s) for x in qd]
    np.testing.assert_array_equal(feat[S.F_STILL], expect)
