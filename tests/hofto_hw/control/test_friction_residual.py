"""The friction model's error learned from contact-free motion (hofto_hw/control/
friction_residual.py): recovered from a synthetic estimate, zero without motion, bounded."""

from __future__ import annotations

import numpy as np

from hofto_hw.config.loader import load_config
from hofto_hw.control.friction_residual import FrictionResidual
from hofto_hw.experiments.drag_sim import ER3A
from hofto_hw.model.robot import RobotModel


def _model() -> RobotModel:
    return RobotModel.from_config(load_config(ER3A).robot)


def test_learns_the_coulomb_and_viscous_error_of_a_moving_arm() -> None:
    model = _model()
    fr = FrictionResidual(model.friction, time_constant=5.0)
    d_c = np.array([-0.3, 0.2, -0.2, 0.1, -0.05, 0.0])  # the estimate's error [N·m]
    d_v = np.array([-0.4, 0.3, -0.1, -0.05, 0.05, -0.02])  # [N·m·s/rad]
    bias = np.array([0.0, -0.25, -0.3, 0.0, 0.02, 0.0])
    rng = np.random.default_rng(1)
    v_s = model.friction.smooth_velocity
    dt = 1e-3
    for k in range(4000):
        t = k * dt
        qd = np.array([1.2, 0.9, 1.1, 1.5, 1.3, 1.7]) * np.sin(
            t * np.array([1.6, 1.8, 2.1, 2.5, 2.2, 2.9])
        )
        est = bias + d_c * np.tanh(qd / v_s) + d_v * qd + rng.normal(0.0, 0.05, 6)
        fr.learn(qd, est, dt)
    c = fr.solve()
    np.testing.assert_allclose(c[:, 1], d_c, atol=0.03)
    np.testing.assert_allclose(c[:, 2], d_v, atol=0.03)
    qd = np.array([0.18, 0.27, -0.31, 0.08, -0.08, 0.1])  # a drag's joint speeds
    out = np.zeros(6)
    fr.correction(qd, out)
    np.testing.assert_allclose(out, d_c * np.tanh(qd / v_s) + d_v * qd, atol=0.02)


def test_no_motion_learns_nothing_and_the_correction_is_bounded() -> None:
    model = _model()
    fr = FrictionResidual(model.friction, min_speed=0.05, limit=0.25)
    still = np.full(6, 0.01)
    for _ in range(2000):  # below min_speed: an arm at rest (a hand may push it)
        assert not fr.learn(still, np.full(6, 3.0), 1e-3)
    fr.solve()
    out = np.ones(6)
    fr.correction(np.full(6, 0.2), out)
    assert fr.seconds == 0.0
    np.testing.assert_array_equal(out, np.zeros(6))
    # a wild fit cannot become a push: at most a quarter of the model's own friction
    fr.coef[:, 1] = 50.0
    qd = np.full(6, 0.2)
    f = np.zeros(6)
    model.friction.torque(qd, f)
    fr.correction(qd, out)
    np.testing.assert_allclose(out, 0.25 * np.abs(f))


def test_compiled_learning_agrees_with_its_source_and_the_numpy_reference() -> None:
    """The kernel compiled (one call per tick) and run as Python source (backend python), bit
    for bit, and the numpy reference of tests/hofto_hw/control/reference.py over 6000 ticks of
    random speeds (some below min_speed, signed zeros, NaN in the estimate): same counts,
    sums to 1e-12 (numpy's tanh may differ from libm's by an ulp), same coefficients and
    correction; no allocation per tick."""
    from support.compiled import require_compiled_kernels

    from . import reference

    require_compiled_kernels()
    model = _model()
    slow = FrictionResidual(model.friction, time_constant=0.5, backend="python")
    fast = FrictionResidual(model.friction, time_constant=0.5, backend="numba")
    assert fast.backend == "numba" and fast._use_kernel
    assert slow.backend == "python" and not slow._use_kernel
    ref = reference.FrictionLearning(6, fast.v_s, 0.5, fast.min_speed, fast.every)
    rng = np.random.default_rng(7)
    for k in range(6000):
        qd = rng.normal(0.0, 0.3, 6) * (k % 7 != 0)  # every 7th tick: an arm at rest
        if k % 11 == 0:
            qd[rng.integers(6)] = -0.0
        est = rng.normal(0.0, 1.0, 6)
        if k == 4321:
            est[2] = np.nan  # reaches the sums in all paths alike
        dt = 1e-3 * (1.0 + (k % 5 == 0))
        moved = ref.learn(qd, est, dt)
        assert fast.learn(qd, est, dt) == moved
        assert slow.learn(qd, est, dt) == moved
        if k == 4320:
            np.testing.assert_allclose(fast.S, ref.S, rtol=0, atol=1e-12)
            np.testing.assert_allclose(fast.b, ref.b, rtol=0, atol=1e-12)
            coef = fast.solve().copy()
            np.testing.assert_array_equal(slow.solve(), coef)
            fit = FrictionResidual(model.friction)
            fit.S[:], fit.b[:] = ref.S, ref.b
            np.testing.assert_allclose(coef, fit.solve(), rtol=0, atol=1e-9)
        assert fast.record.tobytes() == slow.record.tobytes(), k  # to the bit, NaN included
    assert fast.seconds == slow.seconds == ref.seconds > 1.0
    np.testing.assert_array_equal(np.isnan(fast.b), np.isnan(ref.b))
    fast.reset()
    assert fast.seconds == 0.0 and not fast.S.any()

    import tracemalloc

    qd, est = np.full(6, 0.2), np.zeros(6)
    for _ in range(100):
        fast.learn(qd, est, 1e-3)
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for _ in range(2000):
        fast.learn(qd, est, 1e-3)
    grown = sum(
        s.size_diff
        for s in tracemalloc.take_snapshot().compare_to(before, "filename")
        if s.size_diff > 0
    )
    tracemalloc.stop()
    assert grown < 1024, grown


def test_correction_is_the_learning_feature_and_equals_the_numpy_one() -> None:
    """FrictionResidual.correction compiled and as the kernels' source, bit for bit, and the
    numpy reference (numpy's tanh, eq. (12) in numpy) to 1e-12, over random learned
    coefficients and velocities (zeros, the smooth sign's band, fast motion)."""
    from support.compiled import require_compiled_kernels

    from hofto_hw.control.kernels import friction_feature
    from tests.hofto_hw.model.reference import friction_torque

    from . import reference

    require_compiled_kernels()
    model = _model()
    slow = FrictionResidual(model.friction, backend="python")
    fast = FrictionResidual(model.friction, backend="numba")
    rng = np.random.default_rng(17)
    a, b, f = np.zeros(6), np.zeros(6), np.zeros(6)
    for k in range(2000):
        coef = rng.normal(0.0, 0.5, (6, 3))
        fast.coef[:], slow.coef[:] = coef, coef
        qd = rng.normal(0.0, (0.01, 0.3, 2.0)[k % 3], 6)
        if k % 7 == 0:
            qd[rng.integers(6)] = rng.choice([0.0, -0.0])
        fast.correction(qd, a)
        slow.correction(qd, b)
        np.testing.assert_array_equal(a, b)
        friction_torque(model.friction, qd, f)
        ref = reference.friction_correction(coef, fast.v_s, fast.limit, f, qd)
        np.testing.assert_allclose(a, ref, rtol=0, atol=1e-12)
        # the feature is the one the learning regresses on (libm's tanh, the same bits)
        s = np.array([friction_feature.py_func(v, fast.v_s) for v in qd])
        fast._features(qd, fast.v_s, f)
        np.testing.assert_array_equal(f, s)
