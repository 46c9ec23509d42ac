"""The compiled joint-motion kernels (hofto_hw.control.kernels) are bit-identical to the numpy
reference: the demo path and the ramp to standstill, over random mode changes and step sizes,
non-finite velocities included. numba is optional: these tests skip without it, except under
CI (a missing numba is then a failure).
"""

from __future__ import annotations

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.control.joint_motion import MOVE, RAMP_DOWN, DemoPath, JointMotion
from hofto_hw.control.kernels import _path_eval_numpy_trig, libm_trig_is_numpys, path_eval

require_compiled_kernels()

N = 6


def _identical(a: np.ndarray, b: np.ndarray) -> bool:
    """Same values, NaN where NaN, and the same sign of every zero."""
    nan = np.isnan(a)
    return bool(
        np.array_equal(nan, np.isnan(b))
        and np.array_equal(a[~nan], b[~nan])
        and np.array_equal(np.signbit(a[~nan]), np.signbit(b[~nan]))
    )


def _motion(backend: str) -> JointMotion:
    path = DemoPath(
        np.linspace(0.1, 0.6, N),
        np.linspace(1.5, 4.0, N),
        np.linspace(-1.0, 2.0, N),
        ramp=0.7,
        backend=backend,  # type: ignore[arg-type]
    )
    return JointMotion(N, np.linspace(2.0, 7.0, N), path, backend=backend)  # type: ignore[arg-type]


def test_demo_path_is_bit_identical() -> None:
    rng = np.random.default_rng(3)
    ref, fast = _motion("numpy").path, _motion("numba").path
    assert ref is not None and fast is not None
    assert ref.backend == "numpy" and fast.backend == "numba"
    q0 = rng.normal(0.0, 1.0, N)
    out_ref = [np.zeros(N) for _ in range(3)]
    out_fast = [np.zeros(N) for _ in range(3)]
    times = np.concatenate([np.linspace(-0.1, 1.0, 1101), rng.uniform(0.0, 100.0, 2000)])
    for t in times:
        ref.evaluate(float(t), q0, *out_ref)
        fast.evaluate(float(t), q0, *out_fast)
        for a, b in zip(out_ref, out_fast, strict=True):
            assert _identical(a, b), t


@pytest.mark.parametrize("trig", ["libm", "numpy"])
def test_both_compiled_path_calls_give_the_reference(trig: str) -> None:
    """The one-call path (libm's sines) and the four-call one (numpy's): the latter bit for
    bit everywhere, the former bit for bit where libm_trig_is_numpys() says so (it is what
    DemoPath picks then), else within 1e-12 (numpy's own SIMD sines, e.g. AVX-512)."""
    rng = np.random.default_rng(4)
    ref, fast = _motion("numpy").path, _motion("numba").path
    assert ref is not None and fast is not None
    fast._eval = path_eval if trig == "libm" else _path_eval_numpy_trig
    exact = trig == "numpy" or libm_trig_is_numpys()
    q0 = rng.normal(0.0, 1.0, N)
    out_ref = [np.zeros(N) for _ in range(3)]
    out_fast = [np.zeros(N) for _ in range(3)]
    times = np.concatenate([np.linspace(-0.1, 1.0, 1101), rng.uniform(0.0, 1e5, 3000)])
    for t in times:
        ref.evaluate(float(t), q0, *out_ref)
        fast.evaluate(float(t), q0, *out_fast)
        for a, b in zip(out_ref, out_fast, strict=True):
            if exact:
                assert _identical(a, b), t
            else:
                np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)
    q0[2] = np.nan  # a non-finite start pose goes through both alike
    ref.evaluate(2.0, q0, *out_ref)
    fast.evaluate(2.0, q0, *out_fast)
    assert _identical(out_ref[0], out_fast[0])


def test_motion_update_is_bit_identical_through_mode_changes() -> None:
    rng = np.random.default_rng(5)
    ref, fast = _motion("numpy"), _motion("numba")
    assert ref.backend == "numpy" and fast.backend == "numba"
    start = rng.normal(0.0, 0.5, N)
    ref.start(start)
    fast.start(start)
    t = 0.0
    ramps = moves = 0
    for k in range(6000):
        dt = float(rng.choice([1e-3, 5e-4, 2e-3, rng.uniform(1e-4, 5e-3)]))
        t += dt
        r = rng.random()
        if r < 0.01:
            assert ref.move(t) == fast.move(t)
        elif r < 0.02:
            ref.ramp_down()
            fast.ramp_down()
        elif r < 0.022 and ref.mode == RAMP_DOWN:
            bad = rng.choice([np.nan, 0.0, -0.0])  # a non-finite or signed-zero velocity
            j = int(rng.integers(0, N))
            ref.qd[j] = bad
            fast.qd[j] = bad
        ramps += ref.mode == RAMP_DOWN
        moves += ref.mode == MOVE
        ref.update(t, dt)
        fast.update(t, dt)
        assert ref.mode == fast.mode, k
        for a, b in zip((ref.q, ref.qd, ref.qdd), (fast.q, fast.qd, fast.qdd), strict=True):
            assert _identical(a, b), k
        if not np.all(np.isfinite(ref.qd)):  # seen once: start again from rest
            ref.start(start)
            fast.start(start)
    assert ramps > 100 and moves > 100


def test_fade_in_constants_after_the_ramp_are_the_formula_s() -> None:
    """fade_in skips the arithmetic at and after the ramp: the same bits (signed zeros too)."""
    from hofto_hw.control.joint_motion import fade_in

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
