"""The HOFTO kernel's own arithmetic.

Output injection: sig^p(x) = |x|^p·sign(x) on the compiled path against numpy's
np.power (the numpy reference's arithmetic) on the values where a formulation other than
libm's pow could go wrong: zeros of both signs, subnormals, the extremes of the float range,
infinities and NaN, for every kind of power the kernel treats apart (0, 1, the roots 1/4,
1/2, 3/4, and the rest through one log2 shared by the stages of eq. (17)).

Joints: the step runs the joints side by side (substeps outside, joints inside); each joint's
result must be the one it gets alone, bit for bit, for every form and discretisation."""

from __future__ import annotations

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.observers import kernels

from .reference import sigma_powers

require_compiled_kernels()

POWERS = [0.0, 1.0, 0.5, 0.25, 0.75, 2 / 3, 0.95, 0.9, 0.85, 0.8, 1 / 3, 0.05]
FINITE = [
    0.0,
    5e-324,
    2.2250738585072014e-308,
    1e-300,
    1e-12,
    3.7e-6,
    0.1,
    1.0,
    1.0000000000000002,
    7.5,
    1e12,
    1e300,
    1.7976931348623157e308,
]


def _reference(e: np.ndarray, p: float) -> np.ndarray:
    """sig^p as reference.HoftoCore._injection computes it (eq17 form, numpy)."""
    if p == 0.0:
        return np.sign(e)
    return np.copysign(np.power(np.abs(e), p), e)


def _inject(z, y, neg_gains, powers, recursive, inj):
    """Injection terms of joint 0 into inj (s,) as hofto_step computes them (compiled)."""
    kernels._injection(z, 0, y, neg_gains, powers, recursive, inj, 0.0, False)


def _compiled(e: np.ndarray, powers: list[float], recursive: bool) -> np.ndarray:
    """sig^p_i(e) per stage through the kernel's injection (eq17, gains -L = -1: inj = sig(e);
    recursive, one stage per call, -L = 1: inj = sig(z - y))."""
    s = len(powers)
    out = np.empty((s, e.size))
    inj = np.empty(s)
    p = np.array(powers)
    for jj, x in enumerate(e):
        if recursive:
            for i in range(s):  # one stage at a time: z_0 - y = x
                z = np.zeros((1, 1))
                z[0, 0] = x
                _inject(z, 0.0, np.ones((1, 1)), p[i : i + 1], True, inj)
                out[i, jj] = inj[0]
        else:
            z = np.zeros((s, 1))
            _inject(z, x, -np.ones((s, 1)), p, False, inj)  # e = x - 0
            out[:, jj] = inj
    return out


#: eq. (17)'s powers 1 + i·sigma and other progressions (rising, coarse): one log2 shared by
#: the stages, one exp2 each
PROGRESSIONS = [
    list(sigma_powers(2, -0.05)),
    list(sigma_powers(3, -0.02)),
    [0.05, 0.1, 0.15],
    [0.9, 0.6, 0.3],
]


@pytest.mark.parametrize(
    ("recursive", "powers"),
    [(False, POWERS), (True, POWERS)] + [(False, p) for p in PROGRESSIONS],
)
def test_injection_powers_match_numpy_on_edge_values(recursive, powers):
    mags = np.array(FINITE + [np.inf])
    e = np.concatenate([mags, -mags, [np.nan, -0.0]])
    rng = np.random.default_rng(3)
    e = np.concatenate([e, rng.normal(0, 1, 200) * 10.0 ** rng.uniform(-300, 300, 200)])
    got = _compiled(e, powers, recursive)
    for i, p in enumerate(powers):
        ref = _reference(e, p)
        g = got[i]
        # NaN, infinities, zeros and their signs exactly as numpy gives them
        np.testing.assert_array_equal(np.isnan(g), np.isnan(ref), err_msg=f"p={p}")
        np.testing.assert_array_equal(np.isinf(g), np.isinf(ref), err_msg=f"p={p}")
        signed = ref != 0.0 if p == 0.0 else np.isfinite(e) | np.isinf(e)
        # (sign(-0) is -0 in the kernel, +0 in numpy, since before this formulation: a zero
        # injection either way)
        np.testing.assert_array_equal(np.signbit(g[signed]), np.signbit(ref[signed]), f"p={p}")
        np.testing.assert_array_equal(g == 0.0, ref == 0.0, err_msg=f"p={p}")
        ok = np.isfinite(ref) & (ref != 0.0)
        # rounding only: 2^(p·log2|e|) carries ~|p·log2|e||·2^-53 (< 1e-13 over the range)
        np.testing.assert_allclose(g[ok], ref[ok], rtol=1e-13, atol=0.0, err_msg=f"p={p}")
        if p in (0.0, 1.0, 0.5):  # sign, identity and sqrt: exact
            np.testing.assert_array_equal(g[ok], ref[ok], err_msg=f"p={p}")


@pytest.mark.parametrize("recursive", [False, True])
@pytest.mark.parametrize("taylor", [False, True])
@pytest.mark.parametrize("substeps", [1, 3])
def test_each_joint_steps_as_it_does_alone(recursive, taylor, substeps):
    rng = np.random.default_rng(8)
    s, n = 4, 6
    powers = np.array([0.95, 0.75, 0.5, 0.0] if recursive else [0.95, 0.9, 0.85, 0.8])
    neg_gains = -rng.uniform(5.0, 50.0, (s, n))
    h = 1e-3 / substeps
    T = np.eye(s)
    coef = 1.0
    for j in range(1, s if taylor else 2):
        coef *= h / j
        T += coef * np.eye(s, k=j)
    a_h2 = 0.5 * h * h if taylor else 0.0
    z = rng.normal(0, 1e-2, (s, n))
    alone = [np.ascontiguousarray(z[:, [j]]) for j in range(n)]
    y_prev = rng.normal(0, 1e-2, n)
    col = np.zeros((2, s))
    for _ in range(200):
        y = y_prev + rng.normal(0, 1e-3, n)
        acc = rng.normal(0, 1, n)
        args = (h, a_h2, recursive, taylor, substeps, col)
        kernels.hofto_step(z, neg_gains, powers, T, y, y_prev, acc, *args)
        for j in range(n):
            c = slice(j, j + 1)
            kernels.hofto_step(
                alone[j], neg_gains[:, c].copy(), powers, T, y[c], y_prev[c], acc[c], *args
            )
        y_prev = y
    assert np.all(np.isfinite(z)) and np.abs(z[2]).max() > 1e-3
    np.testing.assert_array_equal(z, np.hstack(alone))
