"""Theorem 1 and eq. (10): HOFTO of order n recovers polynomial torques of degree n-1 exactly
after a finite time; the ESO keeps a steady-state error on a ramp."""

from __future__ import annotations

import numpy as np
import pytest
from support.observers import levant_gains, levant_powers, run_hold

from hofto_hw.observers import EsoCore, EsoObserver, HoftoCore, HoftoObserver
from hofto_hw.observers.eso import error_matrices

CASES = [
    # order n, external torque kind and its coefficients (N·m, N·m/s, N·m/s²)
    (1, "constant", {"amplitude": [5.0, -8.0, 4.0, 1.0, -1.0, 0.5]}),
    (
        2,
        "ramp",
        {"amplitude": [1.0, -2.0, 1.0, 0.2, 0.0, 0.1], "slope": [2.0, 3.0, -1.5, 0.4, -0.4, 0.2]},
    ),
    (
        3,
        "parabola",
        {
            "amplitude": [0.0] * 6,
            "slope": [1.0, -1.0, 0.5, 0.2, 0.2, -0.1],
            "curvature": [0.8, 1.2, -0.6, 0.15, -0.15, 0.08],
        },
    ),
]


@pytest.mark.parametrize(("order", "kind", "coef"), CASES)
def test_hofto_recovers_polynomial_torque_on_the_arm(er3a_model, ext, order, kind, coef):
    gains = levant_gains(order, 200.0)
    obs = HoftoObserver(er3a_model, gains, levant_powers(order), "recursive")
    t, truth, est = run_hold(er3a_model, obs, ext(kind, start=0.5, **coef), duration=5.0)
    late = t > 3.0
    err = np.abs(est[late] - truth[late]).max(axis=0)
    scale = np.abs(truth[late]).max(axis=0)
    if order == 1:
        # n = 1: z3 is the sign stage itself; sampled, it moves by L3·dt per step
        m_diag = np.diag(er3a_model.create_data().mass_matrix(er3a_model.home))
        tol = 1.5 * m_diag * gains[-1] * 1e-3
    else:
        tol = 2e-3 * scale + 0.01
    assert np.all(err < tol), (err, tol)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_finite_time_exact_on_pure_chain(order):
    """On x1'' = x3 with x3 a polynomial of degree n-1, sampled at 1 kHz, the error reaches
    the sampling floor in finite time and stays there (no growth with t)."""
    coeffs = [3.0, 2.0, -1.0][:order]  # x3(t) = sum c_i t^i, degree n - 1
    gains = levant_gains(order, 100.0, joints=1)
    core = HoftoCore(gains, levant_powers(order), "recursive")
    dt = 1e-3
    core.reset(np.zeros(1), np.zeros(1))

    # exact position: integrate x3 twice analytically
    def q_of(t: float) -> float:
        return sum(c * t ** (i + 2) / ((i + 1) * (i + 2)) for i, c in enumerate(coeffs))

    errors = []
    for k in range(1, 8001):
        t = k * dt
        z3 = core.step(np.array([q_of(t)]), np.zeros(1), dt)[0]
        errors.append(z3 - sum(c * t**i for i, c in enumerate(coeffs)))
    errors = np.abs(np.array(errors))
    assert errors[:200].max() > 0.1  # it does start wrong
    late = errors[-3000:].max()  # the last 3 s
    if order == 1:
        assert late < gains[-1, 0] * dt  # the sampled sign stage's own step (0.11 here)
    else:
        assert late < 1e-2  # measured 4.4e-3 (n = 2) and 1.6e-4 (n = 3) at 1 kHz


def test_eso_keeps_the_eq10_steady_state_error_on_a_ramp():
    k1, k2, k3 = 30.0, 300.0, 1000.0
    zeta = 4.0  # x3 = zeta·t
    core = EsoCore(np.array([k1]), np.array([k2]), np.array([k3]))
    dt = 1e-4
    core.reset(np.zeros(1), np.zeros(1))
    for k in range(1, 60001):
        t = k * dt
        z3 = core.step(np.array([zeta * t**3 / 6.0]), np.zeros(1), dt)[0]
    e3 = zeta * t - z3
    A, B = error_matrices(k1, k2, k3)
    bound = np.linalg.norm(np.linalg.solve(A, B)) * zeta
    predicted = -(np.linalg.solve(A, B) * zeta)[2, 0]  # e(inf) = -A^-1 B zeta
    assert e3 == pytest.approx(predicted, rel=1e-2)
    assert abs(e3) > 1e-2  # a real, non-vanishing error ...
    assert abs(e3) <= bound * 1.001  # ... within eq. (10)'s bound


def test_eso_on_the_arm_lags_a_ramp_that_hofto_tracks(er3a_model, ext):
    coef = {"amplitude": [0.0] * 6, "slope": [4.0, 4.0, 2.0, 0.5, 0.5, 0.2]}
    k = np.full(6, 1.0)
    eso = EsoObserver(er3a_model, 30 * k, 300 * k, 1000 * k)
    t, truth, est_eso = run_hold(er3a_model, eso, ext("ramp", start=0.5, **coef), duration=4.0)
    hofto = HoftoObserver(er3a_model, levant_gains(2, 200.0), levant_powers(2), "recursive")
    _, _, est_h = run_hold(er3a_model, hofto, ext("ramp", start=0.5, **coef), duration=4.0)
    late = t > 3.0
    err_eso = np.abs(est_eso[late] - truth[late]).mean(axis=0)
    err_h = np.abs(est_h[late] - truth[late]).mean(axis=0)
    assert np.all(err_eso[:3] > 0.05)
    assert np.all(err_h < 0.2 * err_eso)


def test_paper_gains_in_eq17_form_are_unstable_but_recursive_are_not():
    L = np.array([[22.3607], [22.101], [30.0], [440.0]])
    powers = np.array([0.75, 2 / 3, 0.5, 0.0])
    results = {}
    for form in ("eq17", "recursive"):
        core = HoftoCore(L, powers, form)
        core.reset(np.zeros(1), np.array([-5 / (2 * np.pi)]))
        dt = 1e-3
        err = []
        for k in range(1, 8001):
            t = k * dt
            w = 2 * np.pi
            z3 = core.step(np.array([-5 / w**2 * np.sin(w * t)]), np.zeros(1), dt)[0]
            if t > 3:
                err.append(z3 - 5 * np.sin(w * t))
        results[form] = float(np.sqrt(np.mean(np.square(err))))
    assert results["recursive"] < 0.05
    assert results["eq17"] > 50.0
