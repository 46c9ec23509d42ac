"""The model's kernels (hofto_hw.model.kernels) against the numpy reference
(tests/hofto_hw/model/reference.py, friction_torque): friction eq. (12) with every
optional term and its held-friction memory, the snapshot (held friction included) and the
feed-forward inverse dynamics, each compiled (native and not) and as the kernels' Python
source (backend python)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.model import FrictionParams
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from tests.hofto_hw.model.reference import ReferenceData, ReferenceSnapshot, friction_torque

require_compiled_kernels()

from hofto_hw.model import kernels as mk  # noqa: E402  (needs numba: after the skip)

ALL = Needs.MASS | Needs.GRAVITY | Needs.NLE | Needs.CORIOLIS_T | Needs.FRICTION | Needs.ACCEL


def _frictions(n: int, rng: np.random.Generator) -> list[FrictionParams]:
    """Every combination of the optional terms, with random coefficients."""

    def pos(lo: float, hi: float) -> np.ndarray:
        return rng.uniform(lo, hi, n)

    out = []
    for smooth in (0.0, 0.02):
        for stribeck in (False, True):
            for quadratic in (False, True):
                for held, passive in ((False, False), (True, False), (True, True)):
                    fr = FrictionParams(
                        pos(0.5, 6.0),
                        pos(0.1, 8.0),
                        rng.normal(0.0, 0.3, n),
                        stribeck_static=pos(6.0, 9.0) if stribeck else None,
                        stribeck_velocity=pos(0.02, 0.1) if stribeck else None,
                        smooth_velocity=smooth,
                        held=pos(0.2, 2.5) if held else None,
                        held_velocity=0.01,
                        quadratic=pos(0.01, 0.5) if quadratic else None,
                    )
                    fr.held_passive = passive
                    out.append(fr)
    return out


def _velocity(n: int, rng: np.random.Generator) -> np.ndarray:
    """Joint speeds that visit standstill, the held band's edge and fast motion."""
    kind = rng.integers(5)
    if kind == 0:
        qd = rng.normal(0.0, 1.5, n)
    elif kind == 1:
        qd = rng.normal(0.0, 0.01, n)  # inside / around the held band
    elif kind == 2:
        qd = rng.choice([0.0, -0.0, 0.01, -0.01, 1e-300], n)  # signs, zeros, the band's edge
    elif kind == 3:
        qd = rng.normal(0.0, 0.05, n)
    else:
        qd = rng.normal(0.0, 1.0, n)
        qd[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
    return qd


@pytest.mark.parametrize("backend", ["numba", "python"])
def test_friction_kernel_equals_the_numpy_friction_with_its_memory(backend) -> None:
    from hofto_hw.jit import compiled_or_python

    kernel = compiled_or_python(mk.friction, backend)
    rng = np.random.default_rng(11)
    n = 6
    for fr in _frictions(n, rng):
        W = mk.workspace(n)
        mk.pack_friction(fr, W)
        ref_out, scratch, ref_state = np.zeros(n), np.zeros((3, n)), np.zeros(n)
        for _ in range(300):
            qd = _velocity(n, rng)
            friction_torque(fr, qd, ref_out, scratch, ref_state)
            kernel(qd, W)
            np.testing.assert_allclose(W[mk.F], ref_out, rtol=1e-12, atol=1e-12, equal_nan=True)
            np.testing.assert_array_equal(W[mk.STATE], ref_state)
            if np.isnan(ref_state).any():  # a NaN velocity poisons the memory in both
                ref_state.fill(0.0)
                W[mk.STATE].fill(0.0)


def test_friction_params_torque_is_the_kernel_and_equals_the_numpy_friction() -> None:
    """FrictionParams.torque (the product's entry, the kernel in the caller's workspace)
    against the numpy formula: with and without memory, every optional term, zero, NaN and
    infinite velocities; allocation-free with a workspace."""
    rng = np.random.default_rng(21)
    n = 6
    for fr in _frictions(n, rng):
        W = fr.workspace()
        out, ref_out, scratch = np.zeros(n), np.zeros(n), np.zeros((3, n))
        state, ref_state = np.zeros(n), np.zeros(n)
        for _ in range(300):
            qd = _velocity(n, rng)
            assert fr.torque(qd, out, W, state) is out
            friction_torque(fr, qd, ref_out, scratch, ref_state)
            np.testing.assert_allclose(out, ref_out, rtol=1e-12, atol=1e-12, equal_nan=True)
            np.testing.assert_array_equal(state, ref_state)
            fr.torque(qd, out)  # no memory, a workspace of its own
            friction_torque(fr, qd, ref_out)
            np.testing.assert_allclose(out, ref_out, rtol=1e-12, atol=1e-12, equal_nan=True)
            if np.isnan(ref_state).any():
                ref_state.fill(0.0)
                state.fill(0.0)
        qd = _velocity(n, rng)
        qd[~np.isfinite(qd)] = 0.0
        fr.torque(qd, out, W, state)
        tracemalloc.start()
        try:
            for _ in range(50):
                fr.torque(qd, out, W, state)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 1024, f"FrictionParams.torque allocated {peak} bytes"


def test_friction_params_torque_refuses_a_foreign_workspace() -> None:
    fr = FrictionParams.zeros(3)
    with pytest.raises(ValueError, match=r"friction workspace has shape \(3, 3\)"):
        fr.torque(np.zeros(3), np.zeros(3), np.zeros((3, 3)))


def _sequence(n: int, rng: np.random.Generator, N: int = 400) -> np.ndarray:
    """(N, n) finite joint speeds in time order (standstill, the held band, fast motion)."""
    qd = np.array([_velocity(n, rng) for _ in range(N)])
    qd[~np.isfinite(qd)] = 0.0
    return qd


def _linear_parameters(fr: FrictionParams) -> np.ndarray:
    """(n, 6) the coefficients of eq. (12) in FEATURES order, 0 for an absent term."""
    from hofto_hw.model.friction import FEATURES

    z = np.zeros_like(fr.coulomb)
    gap = z if fr.stribeck_static is None else fr.stribeck_static - fr.coulomb
    values = {"coulomb": fr.coulomb, "stribeck_gap": gap, "viscous": fr.viscous}
    values |= {"bias": fr.bias, "quadratic": z if fr.quadratic is None else fr.quadratic}
    values["held"] = z if fr.held is None else fr.held
    return np.stack([values[name] for name in FEATURES], axis=1)


def test_friction_features_times_the_parameters_is_the_torque() -> None:
    """The features (FrictionParams.features: the regressor's friction columns) times the
    coefficients give the numpy formula's torque over a recording, held memory included, for
    every combination of terms; held_signs is the formula's memory sample by sample."""
    rng = np.random.default_rng(31)
    n = 6
    for fr in _frictions(n, rng):
        qd = _sequence(n, rng)
        held = fr.held_signs(qd)
        phi = fr.features(qd)
        np.testing.assert_array_equal(phi, fr.features(qd, held))
        tau = np.einsum("kji,ji->kj", phi, _linear_parameters(fr))
        ref, state = np.zeros(n), np.zeros(n)
        for k in range(qd.shape[0]):
            friction_torque(fr, qd[k], ref, None, state)
            np.testing.assert_allclose(tau[k], ref, rtol=1e-12, atol=1e-12)
            if fr.held is not None:  # the formula keeps a memory only with the term
                np.testing.assert_array_equal(held[k], state)
        assert not phi[:, :, 1].any() if fr.stribeck_static is None else phi[:, :, 1].any()
        assert not phi[:, :, 4].any() if fr.quadratic is None else phi[:, :, 4].any()
        assert not phi[:, :, 5].any() if fr.held is None else phi[:, :, 5].any()


def test_held_signs_start_from_the_given_memory() -> None:
    fr = FrictionParams.structure(2, held_velocity=0.01)
    qd = np.array([[0.001, 0.02], [-0.5, 0.0], [0.0, -0.0]])
    h = fr.held_signs(qd, initial=np.array([-1.0, 1.0]))
    np.testing.assert_array_equal(h, [[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]])
    np.testing.assert_array_equal(fr.held_signs(qd), [[0.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]])


def test_friction_features_refuse_wrong_shapes() -> None:
    fr = FrictionParams.structure(3, 0.02)
    with pytest.raises(ValueError, match=r"velocities must have shape \(N, 3\), got \(4, 2\)"):
        fr.features(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"held has shape \(2, 3\), qd \(4, 3\)"):
        fr.features(np.zeros((4, 3)), np.zeros((2, 3)))


#: (backend, native) of the product's paths: one compiled call, pinocchio's Python calls and
#: the compiled kernel, pinocchio's Python calls and the kernel's Python source
PATHS = [("numba", True), ("numba", False), ("python", True)]


@pytest.mark.parametrize(("backend", "native"), PATHS)
def test_inverse_dynamics_equals_the_numpy_one(er3a_model, backend, native) -> None:
    rng = np.random.default_rng(12)
    n = er3a_model.n
    ref = ReferenceData(er3a_model)
    fast = er3a_model.create_data(backend=backend)
    if not native:
        fast = type(fast)(er3a_model, backend, native=False)
    assert fast.backend == backend and fast.native == (native and backend == "numba")
    for fr in _frictions(n, rng)[::3]:
        er3a_model.friction = fr  # a new parameter set: the compiled copy must follow
        ref.reset_friction_state()
        fast.reset_friction_state()
        for _ in range(200):
            q = er3a_model.home + rng.uniform(-1.0, 1.0, n)
            qd, qdd = _velocity(n, rng), rng.normal(0.0, 3.0, n)
            qd[~np.isfinite(qd)] = 0.0
            a = ref.inverse_dynamics(q, qd, qdd)
            out = np.zeros(n)
            b = fast.inverse_dynamics(q, qd, qdd, out=out)
            assert b is out
            np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * (1.0 + np.abs(a).max()))
            np.testing.assert_array_equal(fast.friction_state, ref.friction_state)
            assert fast.inverse_dynamics(q, qd, qdd) is fast.inverse_dynamics(q, qd, qdd)


@pytest.mark.parametrize(("backend", "native"), PATHS)
def test_snapshot_with_held_friction_equals_the_numpy_one(er3a_model, backend, native) -> None:
    """A model with held friction and a quadratic term runs every snapshot path (its memory
    in the snapshot's workspace), with the numpy reference's terms and memory."""
    rng = np.random.default_rng(13)
    n = er3a_model.n
    fr = _frictions(n, rng)[-1]  # smooth sign, Stribeck, quadratic, held, passive
    assert fr.held is not None and fr.quadratic is not None
    er3a_model.friction = fr
    ref = ReferenceSnapshot(er3a_model, ALL)
    fast = DynamicsSnapshot(er3a_model, ALL, backend=backend, native=native)
    assert fast.backend == backend and fast.native == (native and backend == "numba")
    for k in range(2000 if backend == "numba" else 500):
        q = er3a_model.home + rng.uniform(-1.0, 1.0, n)
        qd, tau = _velocity(n, rng), rng.normal(0.0, 20.0, n)
        assert ref.compute(q, qd, tau) == fast.compute(q, qd, tau) == bool(np.isfinite(qd).all())
        np.testing.assert_array_equal(fast.data.friction_state, ref.data.friction_state)
        if not ref.finite:
            continue
        np.testing.assert_array_equal(fast.M, ref.M)
        np.testing.assert_array_equal(fast.g, ref.g)
        np.testing.assert_array_equal(fast.nle, ref.nle)
        pairs = ((ref.f, fast.f), (ref.ct_qd, fast.ct_qd), (ref.accel, fast.accel))
        pairs += ((ref.total, tau - fast.f),)
        for a, b in pairs:
            np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * (1.0 + np.abs(a).max()))
        if k % 500 == 0:
            ref.reset_memory()
            fast.reset_memory()
            assert not fast.data.friction_state.any()


@pytest.mark.parametrize(("backend", "native"), PATHS)
def test_snapshot_follows_a_replaced_friction_model(er3a_model, backend, native) -> None:
    rng = np.random.default_rng(14)
    fast = DynamicsSnapshot(er3a_model, ALL, backend=backend, native=native)
    ref = ReferenceSnapshot(er3a_model, ALL)
    q, qd, tau = er3a_model.home, rng.normal(0.0, 1.0, 6), rng.normal(0.0, 5.0, 6)
    er3a_model.friction = _frictions(6, rng)[5]
    fast.compute(q, qd, tau)
    ref.compute(q, qd, tau)
    np.testing.assert_allclose(fast.f, ref.f, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fast.accel, ref.accel, rtol=1e-12, atol=1e-12)


def test_compiled_snapshot_and_feedforward_allocate_nothing(er3a_model) -> None:
    rng = np.random.default_rng(15)
    snap = DynamicsSnapshot(er3a_model, ALL, backend="numba")
    ff = er3a_model.create_data(backend="numba")
    out = np.zeros(6)
    samples = [
        (er3a_model.home + rng.uniform(-1, 1, 6), rng.normal(0, 1, 6), rng.normal(0, 9, 6))
        for _ in range(16)
    ]
    for q, qd, tau in samples:  # warm-up
        snap.compute(q, qd, tau)
        ff.inverse_dynamics(q, qd, tau, out=out)
    many = samples * 200
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for q, qd, tau in many:
            snap.compute(q, qd, tau)
            ff.inverse_dynamics(q, qd, tau, out=out)
        grown, peak = (m - before for m in tracemalloc.get_traced_memory())
    finally:
        tracemalloc.stop()
    # nothing kept per call (3200 x one (6,) array would be > 300 kB); pinocchio's returned
    # copies are dropped at once (one at a time)
    assert grown < 1000, grown
    assert peak < 1000, peak


@pytest.mark.parametrize("needs", [Needs.GRAVITY, Needs.CORIOLIS_T, Needs.ACCEL, ALL])
def test_compiled_snapshot_computes_only_what_is_needed(er3a_model, needs) -> None:
    rng = np.random.default_rng(16)
    snap = DynamicsSnapshot(er3a_model, needs, backend="numba")
    ref = DynamicsSnapshot(er3a_model, needs)
    q, qd, tau = er3a_model.home + 0.3, rng.normal(0.0, 1.0, 6), rng.normal(0.0, 5.0, 6)
    assert snap.compute(q, qd, tau) and ref.compute(q, qd, tau)
    for name in ("M", "g", "nle", "f", "accel", "ct_qd"):
        a, b = getattr(ref, name), getattr(snap, name)
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)
        assert np.any(b) == np.any(a)
