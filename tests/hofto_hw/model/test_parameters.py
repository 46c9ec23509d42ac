"""The identified-parameters file: round trip, application to RobotModel, refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.errors import ModelError
from hofto_hw.model import RobotModel
from hofto_hw.model.parameters import (
    BaseParameterEntry,
    ParametersFile,
    apply_parameters,
    apply_parameters_file,
    read_parameters,
    urdf_sha256,
    write_parameters,
)

CONFIGS = Path(__file__).resolve().parents[3] / "configs"


@pytest.fixture()
def model() -> RobotModel:
    return RobotModel.from_config(load_config(CONFIGS / "er3a.yaml").robot)


def _file(model: RobotModel, scale: float = 1.1) -> ParametersFile:
    n = model.n
    return ParametersFile(
        robot=model.name,
        joints=list(model.joint_names),
        urdf_sha256=urdf_sha256(model.urdf_path),
        inertial=model.inertial_parameters().reshape(n, 10) * scale,
        rotor_inertia=np.full(n, 0.2),
        coulomb=np.arange(1.0, n + 1),
        viscous=np.full(n, 0.5),
        bias=np.full(n, -0.1),
        smooth_velocity=0.03,
        stribeck_static=np.arange(1.0, n + 1) + 0.5,
        stribeck_velocity=np.full(n, 0.05),
        method="consistent",
        base=[
            BaseParameterEntry("joint_1.Izz", 1.5, 0.01, {"joint_1.Izz": 1.0, "joint_1.Ia": 1.0})
        ],
        fit={"rmse": np.ones(n), "samples": 10},
    )


def test_round_trip_and_apply(model: RobotModel, tmp_path: Path) -> None:
    pf = _file(model)
    path = tmp_path / "params.yaml"
    write_parameters(path, pf)
    back = read_parameters(path)
    np.testing.assert_allclose(back.inertial, pf.inertial)
    np.testing.assert_allclose(back.stribeck_static, pf.stribeck_static)
    assert back.base[0].definition == {"joint_1.Izz": 1.0, "joint_1.Ia": 1.0}
    assert back.base[0].relative_std_percent == pytest.approx(100 * 0.01 / 1.5)
    q = model.home + 0.1
    M_before = model.create_data().mass_matrix(q).copy()
    apply_parameters_file(model, path)
    np.testing.assert_allclose(model.inertial_parameters(), pf.inertial.ravel())
    np.testing.assert_allclose(model.rotor_inertia, 0.2)
    assert model.friction.smooth_velocity == 0.03
    assert not np.allclose(model.create_data().mass_matrix(q), M_before)
    # friction torque follows the file: at high speed Fc + Fv·qd + B
    f = model.create_data().friction_torque(np.full(model.n, 10.0)).copy()
    np.testing.assert_allclose(f, pf.coulomb + 5.0 - 0.1, rtol=1e-6)


def test_config_parameters_field_loads_the_file(tmp_path: Path) -> None:
    cfg = load_config(CONFIGS / "er3a.yaml")
    base_model = RobotModel.from_config(cfg.robot)
    path = tmp_path / "p.yaml"
    write_parameters(path, _file(base_model, 1.2))
    cfg.robot.parameters = path
    loaded = RobotModel.from_config(cfg.robot)
    np.testing.assert_allclose(loaded.inertial_parameters(), base_model.inertial_parameters() * 1.2)


def test_other_urdf_robot_or_joints_are_refused(model: RobotModel, tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    pf = _file(model)
    pf.urdf_sha256 = "0" * 64
    write_parameters(path, pf)
    with pytest.raises(ModelError, match="different URDF"):
        apply_parameters_file(model, path)
    pf = _file(model)
    pf.robot = "ur10e"
    with pytest.raises(ModelError, match="robot 'ur10e'"):
        apply_parameters(model, pf, "p.yaml")
    pf = _file(model)
    pf.joints = pf.joints[::-1]
    with pytest.raises(ModelError, match="joints"):
        apply_parameters(model, pf, "p.yaml")


def test_non_physical_mass_matrix_is_refused_and_model_kept(model: RobotModel) -> None:
    before = model.inertial_parameters().copy()
    pf = _file(model)
    pf.inertial[1, 4:] *= -50.0  # link 2 rotational inertia hugely negative
    pf.rotor_inertia[:] = 0.0
    with pytest.raises(ModelError, match="not positive definite"):
        apply_parameters(model, pf, "bad.yaml")
    np.testing.assert_array_equal(model.inertial_parameters(), before)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("format: something-else\n", "not a hofto-hw parameters file"),
        ("format: hofto-hw/parameters\nversion: 7\n", "version"),
        ("[unclosed", "not valid YAML"),
    ],
)
def test_malformed_files_name_the_problem(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ModelError, match=match):
        read_parameters(path)


def test_wrong_field_shape_names_the_field(model: RobotModel, tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    write_parameters(path, _file(model))
    text = path.read_text().replace(
        "rotor_inertia: [0.2, 0.2, 0.2, 0.2, 0.2, 0.2]", "rotor_inertia: [0.2, 0.2]"
    )
    path.write_text(text)
    with pytest.raises(ModelError, match=r"model\.rotor_inertia: expected shape \(6,\)"):
        read_parameters(path)
    with pytest.raises(ModelError, match="not found"):
        read_parameters(tmp_path / "missing.yaml")
