"""Wrench estimate F = (Jᵀ)⁺·tau at the tool: exact away from singularities, bounded near
one, payload weight taken off, no allocation per tick."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pinocchio as pin
import pytest

from hofto_hw.control.wrench import ToolJacobian, WrenchEstimator
from hofto_hw.errors import ModelError


def test_wrench_of_a_tool_force_is_that_force(er3a_model) -> None:
    jac = ToolJacobian(er3a_model)
    est = WrenchEstimator(jac)
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = er3a_model.home + rng.uniform(-0.3, 0.3, 6)
        jac.update(q)
        assert jac.w > jac.w0  # away from singularities: no damping
        w_true = rng.normal(0.0, 10.0, 6)
        tau = jac.J.T @ w_true
        np.testing.assert_allclose(est.update(tau), w_true, atol=1e-8)
        assert est.force_norm == pytest.approx(np.linalg.norm(w_true[:3]))


def test_manipulability_is_abs_det_and_damping_bounds_the_inverse(er3a_model) -> None:
    jac = ToolJacobian(er3a_model, w0=0.004, lambda0=0.05)
    q = np.array([0.0, 0.3, 0.9, 0.0, 1e-4, 0.0])  # wrist singularity: q5 ~ 0
    jac.update(q)
    assert jac.w == pytest.approx(abs(np.linalg.det(jac.J)), abs=1e-9)
    assert jac.lam2 > 0.0
    twist = np.array([0.0, 0.0, 0.0, 0.2, 0.0, 0.0])
    qd = np.zeros(6)
    jac.joint_velocity(twist, qd)
    # the undamped inverse would need joint speeds ~ 1/sin(q5); damped they stay bounded
    assert np.abs(qd).max() < 20.0
    assert np.all(np.isfinite(qd))


def test_payload_weight_is_taken_off(er3a_model) -> None:
    jac = ToolJacobian(er3a_model)
    mass, com = 2.0, (0.0, 0.0, 0.05)
    est = WrenchEstimator(jac, mass, com)
    q = er3a_model.home + 0.1
    jac.update(q)
    r = jac.rotation @ np.array(com)
    f = np.array([0.0, 0.0, -9.81 * mass])
    w_load = np.concatenate([f, np.cross(r, f)])
    np.testing.assert_allclose(est.update(jac.J.T @ w_load), 0.0, atol=1e-8)
    # without the payload setting the same torques read as the load's weight
    est0 = WrenchEstimator(jac)
    np.testing.assert_allclose(est0.update(jac.J.T @ w_load), w_load, atol=1e-8)


def test_unknown_tool_frame_is_refused(er3a_model) -> None:
    with pytest.raises(ModelError, match=r"drag\.tool_frame: frame 'nope'"):
        ToolJacobian(er3a_model, tool_frame="nope")


def test_other_tool_frame(er3a_model) -> None:
    jac = ToolJacobian(er3a_model, tool_frame="link_6")
    q = er3a_model.home
    jac.update(q)
    pm = er3a_model.pin_model
    d = pm.createData()
    ref = pin.computeFrameJacobian(pm, d, q, pm.getFrameId("link_6"), pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(jac.J, ref)


def test_no_allocation_per_tick(er3a_model) -> None:
    jac = ToolJacobian(er3a_model)
    est = WrenchEstimator(jac, 1.0, (0.0, 0.0, 0.05))
    q = er3a_model.home.copy()
    tau = np.ones(6)
    for _ in range(10):
        jac.update(q)
        est.update(tau)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for k in range(2000):
        q[4] = 0.6 + 1e-4 * k
        jac.update(q)
        est.update(tau)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert grown < 4000  # bytes: transient pinocchio/LAPACK temporaries, no array per tick
