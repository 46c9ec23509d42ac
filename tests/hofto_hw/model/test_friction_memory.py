"""Held friction (friction with memory): the held sign lives in the caller's workspace."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.model import FrictionParams
from hofto_hw.model.parameters import read_parameters, write_parameters


def _held(n: int = 2) -> FrictionParams:
    return FrictionParams(
        np.full(n, 1.0),
        np.zeros(n),
        np.zeros(n),
        smooth_velocity=0.02,
        held=np.array([2.0, 0.5])[:n],
        held_velocity=0.01,
        quadratic=np.array([0.3, 0.0])[:n],
    )


def test_held_sign_keeps_last_direction_at_rest() -> None:
    f = _held()
    out, scratch, state = np.zeros(2), f.workspace(), np.zeros(2)
    f.torque(np.array([0.5, -0.5]), out, scratch, state)  # moving: + and -
    assert state.tolist() == [1.0, -1.0]
    at_rest = f.torque(np.array([1e-4, 1e-4]), out, scratch, state).copy()
    # joint 2 rests after moving negative: its held friction stays negative even though the
    # creeping velocity is positive; tanh alone would give +0.005·Fc
    assert at_rest[0] == pytest.approx(2.0 + np.tanh(1e-4 / 0.02), rel=1e-3)
    assert at_rest[1] == pytest.approx(-0.5 + np.tanh(1e-4 / 0.02), rel=1e-3)
    # idempotent for a repeated sample
    again = f.torque(np.array([1e-4, 1e-4]), out, scratch, state)
    assert np.allclose(again, at_rest)
    # in motion the held term vanishes and the quadratic term acts
    fast = f.torque(np.array([2.0, -2.0]), out, scratch, state)
    assert fast[0] == pytest.approx(np.tanh(100.0) + 0.3 * 4.0)
    assert fast[1] == pytest.approx(-np.tanh(100.0))


def test_without_state_there_is_no_memory() -> None:
    f = _held()
    out = np.zeros(2)
    f.torque(np.array([0.5, 0.5]), out)
    assert f.torque(np.zeros(2), out).tolist() == [0.0, 0.0]


def test_workspaces_keep_their_own_memory(er3a_model) -> None:
    er3a_model.friction = FrictionParams(
        np.zeros(6), np.zeros(6), np.zeros(6), held=np.full(6, 1.5), held_velocity=0.01
    )
    a, b = er3a_model.create_data(), er3a_model.create_data()
    a.friction_torque(np.full(6, 0.3))
    b.friction_torque(np.full(6, -0.3))
    assert np.allclose(a.friction_torque(np.zeros(6)), 1.5)
    assert np.allclose(b.friction_torque(np.zeros(6)), -1.5)
    a.reset_friction_state()
    assert np.allclose(a.friction_torque(np.zeros(6)), 0.0)


def test_parameters_file_round_trip(tmp_path, er3a_model) -> None:
    from hofto_hw.identify.pipeline import identify  # noqa: F401  (module import check)
    from hofto_hw.model.parameters import ParametersFile

    n = 6
    pf = ParametersFile(
        robot="er3a",
        joints=list(er3a_model.joint_names),
        urdf_sha256="",
        inertial=er3a_model.inertial_parameters().reshape(n, 10),
        rotor_inertia=er3a_model.rotor_inertia,
        coulomb=np.ones(n),
        viscous=np.ones(n),
        bias=np.zeros(n),
        held=np.arange(n, dtype=float),
        held_velocity=0.01,
        quadratic=np.full(n, -0.1),
    )
    write_parameters(tmp_path / "p.yaml", pf)
    back = read_parameters(tmp_path / "p.yaml")
    assert back.held.tolist() == list(range(n))
    assert back.held_velocity == 0.01
    assert back.quadratic.tolist() == [-0.1] * n
    assert back.friction().held is not None
