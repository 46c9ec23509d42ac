"""The joint-motion kernels (hofto_hw.control.kernels), compiled and run as Python source,
against the numpy reference of tests/hofto_hw/control/reference.py: the demo path and the ramp
to standstill, over random mode changes and step sizes, non-finite values included. Compiled
and Python source agree bit for bit (both take libm's sines); the numpy reference to the last
bit where numpy's sines are libm's on this machine, else within 1e-12 (numpy's SIMD sines,
e.g. AVX-512). numba is a dependency: these tests skip without it, except under CI (a missing
numba is then a failure).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.control.joint_motion import MOVE, RAMP_DOWN, DemoPath, JointMotion, fade_in
from hofto_hw.control.kernels import path_eval, ramp_step
from hofto_hw.jit import compiled_or_python

from . import reference

require_compiled_kernels()

N = 6
A, PERIOD, PHASE, RAMP = (
    np.linspace(0.1, 0.6, N),
    np.linspace(1.5, 4.0, N),
    np.linspace(-1.0, 2.0, N),
    0.7,
)


def _identical(a: np.ndarray, b: np.ndarray) -> bool:
    """Same values, NaN where NaN, and the same sign of every zero."""
    nan = np.isnan(a)
    return bool(
        np.array_equal(nan, np.isnan(b))
        and np.array_equal(a[~nan], b[~nan])
        and np.array_equal(np.signbit(a[~nan]), np.signbit(b[~nan]))
    )


def _source(kernel):  # the kernel's Python source (numba's py_func)
    return compiled_or_python(kernel, "python")


def _numpy_sines_are_libms() -> bool:
    """np.sin / np.cos give math.sin / math.cos's bits on the demo path's arguments."""
    x = np.concatenate([np.linspace(-10.0, 10.0, 20_001), np.geomspace(1e-8, 1e6, 20_001)])
    x = np.concatenate([x, -x])
    libm = np.array([(math.sin(v), math.cos(v)) for v in x])
    return _identical(libm[:, 0], np.sin(x)) and _identical(libm[:, 1], np.cos(x))


def _close(ref: np.ndarray, got: np.ndarray, exact: bool) -> bool:
    if exact:
        return _identical(ref, got)
    nan = np.isnan(ref)
    return bool(
        np.array_equal(nan, np.isnan(got))
        and np.allclose(got[~nan], ref[~nan], rtol=1e-12, atol=1e-12)
    )


def _motion(backend: str) -> JointMotion:
    path = DemoPath(A, PERIOD, PHASE, ramp=RAMP, backend=backend)  # type: ignore[arg-type]
    return JointMotion(N, np.linspace(2.0, 7.0, N), path, backend=backend)  # type: ignore[arg-type]


def test_the_backends_call_the_one_kernel() -> None:
    """numba: the compiled kernel (what the tick's fused call checks); numpy: its source."""
    fast, slow = _motion("numba"), _motion("python")
    assert fast.path is not None and slow.path is not None
    assert fast.path._use_kernel and fast.path._eval is path_eval
    assert not slow.path._use_kernel and slow.path._eval is _source(path_eval)
    assert fast._ramp_step is ramp_step and slow._ramp_step is _source(ramp_step)


def test_demo_path_agrees_with_the_numpy_reference() -> None:
    rng = np.random.default_rng(3)
    fast, slow = _motion("numba").path, _motion("python").path
    assert fast is not None and slow is not None
    exact = _numpy_sines_are_libms()
    w, q0 = 2.0 * np.pi / PERIOD, rng.normal(0.0, 1.0, N)
    out = {k: [np.zeros(N) for _ in range(3)] for k in ("ref", "fast", "slow")}
    times = np.concatenate([np.linspace(-0.1, 1.0, 1101), rng.uniform(0.0, 1e5, 3000)])
    for t in times:
        reference.demo_path(A, w, PHASE, RAMP, float(t), q0, *out["ref"])
        fast.evaluate(float(t), q0, *out["fast"])
        slow.evaluate(float(t), q0, *out["slow"])
        for r, f, s in zip(out["ref"], out["fast"], out["slow"], strict=True):
            assert _identical(f, s), t  # compiled == its source, to the bit
            assert _close(r, f, exact), t
    q0[2] = np.nan  # a non-finite start pose goes through all alike
    reference.demo_path(A, w, PHASE, RAMP, 2.0, q0, *out["ref"])
    fast.evaluate(2.0, q0, *out["fast"])
    slow.evaluate(2.0, q0, *out["slow"])
    assert _identical(out["fast"][0], out["slow"][0])
    assert np.array_equal(np.isnan(out["ref"][0]), np.isnan(out["fast"][0]))


@pytest.mark.parametrize("t", [np.inf, -np.inf, np.nan])
def test_a_non_finite_time_gives_nan_compiled_and_as_python(t: float) -> None:
    """sin(±inf) is NaN in numpy and compiled; the interpreter's math.sin raises: the kernel
    says NaN in both."""
    k = DemoPath(A, PERIOD, PHASE, ramp=RAMP)._k
    b, bd, bdd = fade_in(1e9, RAMP)
    for fn in (path_eval, _source(path_eval)):
        q, qd, qdd = np.zeros(N), np.zeros(N), np.zeros(N)
        fn(k, t, b, bd, bdd, np.zeros(N), q, qd, qdd)
        assert np.isnan(q).all() and np.isnan(qd).all() and np.isnan(qdd).all()


def test_motion_update_agrees_through_mode_changes() -> None:
    """JointMotion compiled and as Python source, bit for bit; its ramp to standstill against
    the numpy reference (no sines: bit for bit), signed zeros and NaN velocities included."""
    rng = np.random.default_rng(5)
    fast, slow = _motion("numba"), _motion("python")
    assert fast.backend == "numba" and slow.backend == "python"
    start = rng.normal(0.0, 0.5, N)
    fast.start(start)
    slow.start(start)
    rq, rqd, rqdd = np.zeros(N), np.zeros(N), np.zeros(N)
    t = 0.0
    ramps = moves = 0
    for k in range(6000):
        dt = float(rng.choice([1e-3, 5e-4, 2e-3, rng.uniform(1e-4, 5e-3)]))
        t += dt
        r = rng.random()
        if r < 0.01:
            assert fast.move(t) == slow.move(t)
        elif r < 0.02:
            fast.ramp_down()
            slow.ramp_down()
        elif r < 0.022 and fast.mode == RAMP_DOWN:
            bad = rng.choice([np.nan, 0.0, -0.0])  # a non-finite or signed-zero velocity
            j = int(rng.integers(0, N))
            fast.qd[j] = bad
            slow.qd[j] = bad
        ramping = fast.mode == RAMP_DOWN
        ramps += ramping
        moves += fast.mode == MOVE
        if ramping:  # the reference ramp from the same state
            np.copyto(rq, fast.q)
            np.copyto(rqd, fast.qd)
            np.copyto(rqdd, fast.qdd)
            done = reference.ramp_step(fast.ramp_accel, dt, rq, rqd, rqdd)
        fast.update(t, dt)
        slow.update(t, dt)
        assert fast.mode == slow.mode, k
        for a, b in zip((fast.q, fast.qd, fast.qdd), (slow.q, slow.qd, slow.qdd), strict=True):
            assert _identical(a, b), k
        if ramping:
            assert (fast.mode != RAMP_DOWN) == done, k
            for a, b in zip((rq, rqd, rqdd), (fast.q, fast.qd, fast.qdd), strict=True):
                assert _identical(a, b), k
        if not np.all(np.isfinite(fast.qd)):  # seen once: start again from rest
            fast.start(start)
            slow.start(start)
    assert ramps > 100 and moves > 100


def test_ramp_step_agrees_with_the_numpy_reference() -> None:
    """ramp_step compiled, as Python and the numpy reference, bit for bit, from random states
    with signed zeros, NaN and infinite velocities and accelerations."""
    rng = np.random.default_rng(6)
    specials = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 1e-300, -1e-300])
    for k in range(3000):
        q, qd = rng.normal(0.0, 1.0, N), rng.normal(0.0, 0.5, N)
        acc = rng.uniform(0.5, 8.0, N)
        if k % 3 == 0:
            qd[rng.integers(N)] = rng.choice(specials)
        if k % 7 == 0:
            acc[rng.integers(N)] = rng.choice([np.nan, np.inf, 0.0])
        if k % 5 == 0:
            qd[rng.random(N) < 0.5] = 0.0
        dt = float(rng.choice([1e-3, 2e-3, rng.uniform(1e-5, 1e-2)]))
        outs = []
        for fn in (reference.ramp_step, ramp_step, _source(ramp_step)):
            s = [q.copy(), qd.copy(), np.full(N, 7.0)]
            with np.errstate(invalid="ignore"):
                done = fn(acc, dt, *s)
            outs.append((bool(done), s))
        for done, s in outs[1:]:
            assert done == outs[0][0], k
            for a, b in zip(outs[0][1], s, strict=True):
                assert _identical(a, b), k


def test_fade_in_constants_after_the_ramp_are_the_formula_s() -> None:
    """fade_in skips the arithmetic at and after the ramp: the same bits (signed zeros too)."""

    def formula(t: float, ramp: float) -> tuple[float, float, float]:
        x = min(max(t / ramp, 0.0), 1.0)
        b = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)
        bd = 30.0 * x * x * (1.0 - x) ** 2 / ramp
        bdd = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / (ramp * ramp)
        return b, bd, bdd

    rng = np.random.default_rng(8)
    for ramp in (0.7, 1.0, 3e-3, 123.4):
        ts = [0.0, -1.0, ramp, np.nextafter(ramp, 0.0), np.nextafter(ramp, 2 * ramp), 1e9]
        ts += list(rng.uniform(-0.1 * ramp, 3.0 * ramp, 500))
        for t in ts:
            got, want = np.array(fade_in(float(t), ramp)), np.array(formula(float(t), ramp))
            assert _identical(got, want), (t, ramp)
