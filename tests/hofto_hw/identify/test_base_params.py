"""Base parameters: counts on known arms, and H_b·mu == H_s·theta for any theta."""

from __future__ import annotations

import numpy as np

from hofto_hw.identify.base_params import find_base_parameters, random_samples
from hofto_hw.identify.regressor import Regressor


def test_ur10e_count_matches_dataset_authors(ur10e_model) -> None:
    reg = Regressor(ur10e_model.pin_model, 0.02)
    base = find_base_parameters(reg, ur10e_model.joint_names)
    friction = [nm for nm in base.names if nm.rsplit(".", 1)[1] in ("Fc", "Fv", "B")]
    # 36 rigid-body + 4 rotor (Ia1, Ia2 regroup with link inertias) = 40, as Mamedov et al.
    # report, plus 3 friction parameters per joint.
    assert len(friction) == 18
    assert base.p - len(friction) == 40
    rotors = [nm for nm in base.names if nm.endswith(".Ia")]
    assert rotors == [f"{j}.Ia" for j in ur10e_model.joint_names[2:]]


def test_regrouping_reproduces_torques(er3a_base) -> None:
    reg, base = er3a_base
    rng = np.random.default_rng(5)
    H = reg.stack(*random_samples(reg.n, 40, rng))
    for _ in range(3):
        theta = rng.normal(0.0, 1.0, reg.n_std)
        mu = base.from_standard(theta)
        np.testing.assert_allclose(H[:, base.columns] @ mu, H @ theta, rtol=1e-9, atol=1e-9)
        prior = rng.normal(0.0, 1.0, reg.n_std)
        theta2 = base.to_standard(mu, prior)
        np.testing.assert_allclose(base.from_standard(theta2), mu, rtol=1e-9, atol=1e-10)
        dropped = np.setdiff1d(np.arange(reg.n_std), base.columns)
        np.testing.assert_array_equal(theta2[dropped], prior[dropped])


def test_definition_is_readable(er3a_base) -> None:
    _, base = er3a_base
    ex = base.expressions()
    assert len(ex) == base.p
    # every base parameter contains the standard parameter it is named after, coefficient 1
    for name, terms in zip(base.names, ex, strict=True):
        assert dict(terms)[name] == 1.0
    # a regrouped first-link parameter also carries the first rotor inertia
    first = base.names.index("joint_1.Izz")
    assert "joint_1.Ia" in dict(ex[first])


def test_stribeck_adds_one_base_parameter_per_joint(er3a_model, er3a_base) -> None:
    _, base = er3a_base
    reg = Regressor(er3a_model.pin_model, 0.02, np.full(6, 0.05))
    base_s = find_base_parameters(reg, er3a_model.joint_names)
    assert base_s.p == base.p + 6
    assert base_s.names[-1] == "joint_6.S"
