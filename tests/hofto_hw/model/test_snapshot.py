"""DynamicsSnapshot: the model terms of one sample, computed once, read by every observer."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.model.snapshot import DynamicsSnapshot, Needs, pinocchio_traits
from tests.hofto_hw.model.reference import ReferenceSnapshot


def _sample(model, rng):
    q = model.home + rng.uniform(-0.8, 0.8, model.n)
    return q, rng.normal(0, 1.0, model.n), rng.normal(0, 10.0, model.n)


ALL = Needs.MASS | Needs.GRAVITY | Needs.NLE | Needs.CORIOLIS_T | Needs.FRICTION | Needs.ACCEL


def test_terms_match_the_model_data_methods(er3a_model):
    rng = np.random.default_rng(1)
    snap = DynamicsSnapshot(er3a_model, ALL)
    ref = er3a_model.create_data()
    for _ in range(20):
        q, qd, tau = _sample(er3a_model, rng)
        assert snap.compute(q, qd, tau)
        np.testing.assert_array_equal(snap.M, ref.mass_matrix(q))
        np.testing.assert_array_equal(snap.g, ref.gravity(q))
        np.testing.assert_array_equal(snap.nle, ref.nonlinear_effects(q, qd))
        # the snapshot's friction is the kernel's (hofto_hw.model.kernels), the workspace's
        # FrictionParams.torque: the same eq. (12) to the last bit or two
        tol = {"rtol": 1e-12, "atol": 1e-12}
        np.testing.assert_allclose(snap.f, ref.friction_torque(qd), **tol)
        np.testing.assert_allclose(snap.accel, ref.forward_dynamics(q, qd, tau), **tol)
        np.testing.assert_allclose(
            snap.ct_qd, ref.coriolis_matrix(q, qd).T @ qd, rtol=1e-12, atol=1e-12
        )
        assert snap.q is q and snap.qd is qd and snap.tau is tau


def test_only_the_needed_terms_are_computed(er3a_model):
    rng = np.random.default_rng(2)
    snap = DynamicsSnapshot(er3a_model, Needs.GRAVITY)
    q, qd, tau = _sample(er3a_model, rng)
    snap.compute(q, qd, tau)
    assert np.any(snap.g != 0.0)
    for unused in (snap.M, snap.nle, snap.f, snap.accel, snap.ct_qd):
        assert not np.any(unused)
    # ACCEL implies the friction it subtracts
    assert DynamicsSnapshot(er3a_model, Needs.ACCEL).needs & Needs.FRICTION


def test_terms_are_views_of_pinocchio_storage_when_pinocchio_allows(er3a_model):
    traits = pinocchio_traits(er3a_model)
    snap = DynamicsSnapshot(er3a_model, ALL)
    rng = np.random.default_rng(3)
    q, qd, tau = _sample(er3a_model, rng)
    snap.compute(q, qd, tau)
    if not traits.stable_views:
        pytest.skip(f"pinocchio {traits.version} returns no stable views; snapshot copies")
    assert np.shares_memory(snap.g, snap.pin_data.g)
    assert np.shares_memory(snap.accel, snap.pin_data.ddq)
    if traits.full_mass_matrix:
        assert np.shares_memory(snap.M, snap.pin_data.M)
    np.testing.assert_array_equal(snap.M, snap.M.T)


def _backends():
    from hofto_hw import jit

    return ["python"] + (["numba"] if jit.available() else [])


# numpy warns when it sums +inf and -inf (the NaN the numpy path's finiteness check relies on)
@pytest.mark.filterwarnings("ignore:invalid value encountered in reduce:RuntimeWarning")
@pytest.mark.parametrize("backend", _backends())
def test_nonfinite_sample_is_not_evaluated_and_terms_keep_their_values(er3a_model, backend):
    rng = np.random.default_rng(4)
    snap = DynamicsSnapshot(er3a_model, ALL, backend=backend)
    assert snap.backend == backend
    q, qd, tau = _sample(er3a_model, rng)
    assert snap.compute(q, qd, tau)
    before = [a.copy() for a in (snap.M, snap.g, snap.nle, snap.f, snap.accel, snap.ct_qd)]
    for bad in ("q", "qd", "tau"):
        sample = {"q": q.copy(), "qd": qd.copy(), "tau": tau.copy()}
        sample[bad][2] = np.inf if bad == "tau" else np.nan
        if bad == "qd":  # two infinities of opposite sign in q: still refused
            sample["q"][0], sample["q"][1] = np.inf, -np.inf
        assert not snap.compute(sample["q"], sample["qd"], sample["tau"])
        assert not snap.finite
        after = (snap.M, snap.g, snap.nle, snap.f, snap.accel, snap.ct_qd)
        for x, y in zip(before, after, strict=True):
            np.testing.assert_array_equal(x, y)
    assert snap.compute(q, qd, tau) and snap.finite


@pytest.mark.parametrize("backend", ["numba", "python"])
def test_terms_agree_with_the_numpy_reference(er3a_model, backend):
    rng = np.random.default_rng(5)
    ref = ReferenceSnapshot(er3a_model, ALL)
    fast = DynamicsSnapshot(er3a_model, ALL, backend=backend)
    assert fast.backend == backend
    for _ in range(2000):
        q, qd, tau = _sample(er3a_model, rng)
        qd[rng.integers(6)] = 0.0  # friction's sign at standstill
        ref.compute(q, qd, tau)
        fast.compute(q, qd, tau)
        for a, b in ((ref.f, fast.f), (ref.ct_qd, fast.ct_qd), (ref.accel, fast.accel)):
            np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * np.abs(a).max())
        np.testing.assert_array_equal(fast.M, ref.M)


def test_a_pinocchio_without_stable_views_is_refused_in_one_line(er3a_model, monkeypatch):
    """The snapshot and the workspaces read pinocchio's Data storage in place: a pinocchio
    that returns copies (or half of M) is refused naming its version, not run differently."""
    from hofto_hw.errors import ModelError
    from hofto_hw.model import snapshot

    version = pinocchio_traits(er3a_model).version
    for stable, full, what in ((False, True, "stable Data views"), (True, False, "full")):
        monkeypatch.setattr(snapshot, "_TRAITS", snapshot.PinocchioTraits(version, stable, full))
        with pytest.raises(ModelError, match=f"pinocchio {version} does not give .*{what}") as e:
            er3a_model.create_data()
        assert "\n" not in str(e.value) and "pin>=4.1,<5" in str(e.value)
        with pytest.raises(ModelError):
            DynamicsSnapshot(er3a_model, ALL)
