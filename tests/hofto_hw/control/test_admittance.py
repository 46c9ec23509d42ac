"""Admittance (eq. 34) in open loop: the command integrates M·v' + B·v = F with its limits;
the per-tick DragController allocates nothing."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from hofto_hw.config.drag import DragConfig
from hofto_hw.control.admittance import CartesianAdmittance, JointAdmittance
from hofto_hw.control.drag import DragController, DragReason
from hofto_hw.control.wrench import ToolJacobian

DT = 1e-3


def _drive(adm, jac, q0, wrench, seconds):
    """Integrate the command for ``seconds`` with a constant wrench; returns q history and
    tool positions."""
    q = q0.copy()
    qs, ps = [], []
    for _ in range(round(seconds / DT)):
        jac.update(q)
        qd = adm.update(wrench, q, DT)
        q += qd * DT
        qs.append(q.copy())
        ps.append(jac.position.copy())
    return np.array(qs), np.array(ps)


def test_steady_twist_is_force_over_damping_on_unlocked_axes(er3a_model) -> None:
    cfg = DragConfig(unlock={"x": True, "y": False, "z": True, "rotation": False})
    jac = ToolJacobian(er3a_model)
    adm = CartesianAdmittance(cfg, er3a_model, jac)
    w = np.array([20.0, 30.0, 0.0, 0.0, 2.0, 0.0])
    _drive(adm, jac, er3a_model.home, w, 0.3)
    np.testing.assert_allclose(adm.twist, [0.1, 0.0, 0.0, 0.0, 0.0, 0.0], atol=1e-6)


def test_deadband_and_release_braking(er3a_model) -> None:
    cfg = DragConfig()
    jac = ToolJacobian(er3a_model)
    adm = CartesianAdmittance(cfg, er3a_model, jac)
    _drive(adm, jac, er3a_model.home, np.array([4.9, 0, 0, 0, 0, 0.0]), 0.2)
    assert np.abs(adm.twist).max() == 0.0  # inside the 5 N band: no motion
    _drive(adm, jac, er3a_model.home, np.array([7.5, 0, 0, 0, 0, 0.0]), 0.3)
    assert adm.twist[0] == pytest.approx(2 * (7.5 - 5.0) / 200.0, rel=1e-6)  # half-way ramp
    _drive(adm, jac, er3a_model.home, np.zeros(6), 0.02)
    # k-fold damping while nobody pushes: after 20 ms, exp(-20/5) of the speed is left
    assert adm.twist[0] < 0.03 * 0.025


def test_tool_speed_limit(er3a_model) -> None:
    cfg = DragConfig()
    jac = ToolJacobian(er3a_model)
    adm = CartesianAdmittance(cfg, er3a_model, jac)
    _, p = _drive(adm, jac, er3a_model.home, np.array([0, 100.0, 0, 0, 0, 0]), 0.5)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / DT
    assert speed.max() <= 0.25 * 1.01
    assert speed[-100:].mean() > 0.2  # it does move at the limit


def test_soft_joint_limit_is_approached_never_crossed(er3a_model) -> None:
    cfg = DragConfig(space="joint", joint_deadband=0.5)
    jac = ToolJacobian(er3a_model)
    adm = JointAdmittance(cfg, er3a_model, jac)
    q0 = er3a_model.home.copy()
    q0[0] = 2.80
    soft = er3a_model.limits.position_upper[0] - cfg.soft_limit_margin
    qs, _ = _drive(adm, jac, q0, np.array([30.0, 0, 0, 0, 0, 0]), 2.0)
    assert qs[:, 0].max() <= soft
    assert qs[-1, 0] > soft - 0.01  # it got there
    assert adm.shaping.limited & 1


def test_workspace_box(er3a_model) -> None:
    jac = ToolJacobian(er3a_model)
    jac.update(er3a_model.home)
    p0 = jac.position.copy()
    box = {"lower": (p0 - 0.2).tolist(), "upper": (p0 + [0.05, 0.2, 0.2]).tolist()}
    cfg = DragConfig(workspace=box)
    adm = CartesianAdmittance(cfg, er3a_model, jac)
    _, p = _drive(adm, jac, er3a_model.home, np.array([40.0, 0, 0, 0, 0, 0]), 2.0)
    assert p[:, 0].max() <= p0[0] + 0.05 + 1e-4
    assert p[-1, 0] > p0[0] + 0.045


def test_near_wrist_singularity_joint_speeds_stay_bounded(er3a_model) -> None:
    cfg = DragConfig(unlock={"rotation": True})
    jac = ToolJacobian(er3a_model, None, cfg.singular_manipulability, cfg.dls_damping)
    adm = CartesianAdmittance(cfg, er3a_model, jac)
    q0 = np.array([0.0, 0.3, 0.9, 0.0, 0.02, 0.0])
    qs, _ = _drive(adm, jac, q0, np.array([0, 30.0, 0, 0, 0, 3.0]), 1.0)
    qd = np.diff(qs, axis=0) / DT
    vmax = er3a_model.limits.velocity * cfg.joint_speed_scale
    assert np.all(np.abs(qd) <= vmax * 1.001)
    assert adm.scale < 1.0  # slowed down near the singularity


def test_controller_does_not_move_without_press_and_allocates_nothing(er3a_model) -> None:
    ctl = DragController(DragConfig(), er3a_model)
    q = er3a_model.home.copy()
    zero = np.zeros(6)
    ctl.start(q)
    jac = ToolJacobian(er3a_model)
    jac.update(q)
    tau = jac.J.T @ np.array([20.0, 0, 0, 0, 0, 0])
    for _ in range(200):
        ctl.update(q, zero, tau, DT, False, False)
    np.testing.assert_array_equal(ctl.q_cmd, q)
    # press with the push already there: the tare takes it as zero, so push on top of it
    ctl.update(q, zero, tau, DT, True, False)
    tau2 = 2.0 * tau
    for _ in range(10):
        ctl.update(q, zero, tau2, DT, True, False)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for _ in range(2000):
        ctl.update(q, zero, tau2, DT, True, False)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert ctl.active and ctl.qd_cmd.any()
    assert grown < 4000  # bytes: transient temporaries only, no array per tick
    ctl.update(q, zero, tau, DT, False, False)
    assert ctl.reason == DragReason.ENABLE_RELEASED and ctl.category == 2
