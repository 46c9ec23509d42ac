"""Contact isolation: a hand at the tool matches the tool hypothesis; a contact on link 3
(alone or on top of the hand) does not, and is named."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from hofto_hw.control.isolation import ContactIsolation
from hofto_hw.control.wrench import ToolJacobian


def _link_point_jacobian(model, q, link):
    pm = model.pin_model
    d = pm.createData()
    pin.computeJointJacobians(pm, d, q)
    J = pin.getJointJacobian(pm, d, link, pin.LOCAL_WORLD_ALIGNED)
    o = d.oMi[link].translation
    r = 0.5 * (d.oMi[link + 1].translation - o)
    skew = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    return J[:3] - skew @ J[3:]


@pytest.fixture()
def setup(er3a_model):
    jac = ToolJacobian(er3a_model)
    iso = ContactIsolation(er3a_model, jac, threshold=1.0, lookback=5)
    q = er3a_model.home + np.array([0.2, -0.1, 0.1, 0.3, 0.2, 0.1])
    jac.update(q)
    return er3a_model, jac, iso, q


def test_tool_force_matches(setup) -> None:
    model, jac, iso, q = setup
    tau = jac.J[:3].T @ np.array([20.0, -10.0, 5.0])
    assert not iso.check(tau)
    assert iso.mismatch < 1e-6
    np.testing.assert_allclose(iso.tool_force, [20.0, -10.0, 5.0], atol=1e-6)


@pytest.mark.parametrize("link", [2, 3])
def test_link_contact_is_named(setup, link) -> None:
    model, jac, iso, q = setup
    Jp = _link_point_jacobian(model, q, link)
    tau_link = Jp.T @ np.array([30.0, 10.0, 30.0])
    tau_hand = jac.J[:3].T @ np.array([20.0, 0.0, 0.0])
    assert iso.check(tau_link)
    assert iso.isolate(q, tau_link) == link
    # dragging at the tool, then the contact: the hand's force before it is taken off, also
    # when the fit has absorbed part of the contact while it was building up
    for _ in range(5):
        assert not iso.check(tau_hand)
    for s in (0.02, 0.05):
        assert not iso.check(tau_hand + s * tau_link)
    assert iso.check(tau_hand + tau_link)
    assert iso.isolate(q, tau_hand + tau_link) == link


def test_rotation_unlocked_tool_hypothesis_includes_a_moment(setup) -> None:
    model, jac, _, q = setup
    iso = ContactIsolation(model, jac, threshold=1.0, rotation=True)
    tau = jac.J.T @ np.array([10.0, 0.0, 0.0, 0.0, 0.0, 2.0])
    assert not iso.check(tau)
