"""Payload identification and the payload on the model."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from hofto_hw.cli import main
from hofto_hw.identify.payload import identify_payload
from hofto_hw.identify.pipeline import Samples
from hofto_hw.model.payload import Payload, apply_payload
from tests.conftest import CONFIGS, SHARED_DATA

LOAD = SHARED_DATA / "ur10e" / "identification" / "ur-20_01_31-load.csv"
LOAD2 = SHARED_DATA / "ur10e" / "identification" / "ur-20_02_19_14harm50secLoad.csv"


def test_identify_payload_recovers_mass_and_com(er3a_model) -> None:
    loaded = er3a_model.copy()
    apply_payload(loaded, Payload(3.0, (0.02, -0.01, 0.08)))
    rng = np.random.default_rng(0)
    N = 200
    q = rng.uniform(-1.5, 1.5, (N, 6))
    qd = rng.uniform(-1.0, 1.0, (N, 6))
    qdd = rng.uniform(-2.0, 2.0, (N, 6))
    data = loaded.create_data()
    tau = np.array([data.inverse_dynamics(q[k], qd[k], qdd[k]).copy() for k in range(N)])
    est = identify_payload(er3a_model, [Samples(q, qd, qdd, tau, "sim")])
    # (m, m·c) only: the load's inertia about the joint frame (m·|c|² ~ 0.02 kg·m²) is left out
    assert est.mass == pytest.approx(3.0, rel=1e-3)
    assert np.allclose(est.com, [0.02, -0.01, 0.08], atol=1e-3)
    assert np.max(est.rmse_after) < 0.02 * np.max(est.rmse_before)


def test_payload_survives_loading_a_parameters_file(er3a_model, tmp_path) -> None:
    from hofto_hw.identify.pipeline import identify  # noqa: F401
    from hofto_hw.model.parameters import apply_parameters, read_parameters, write_parameters

    m0 = er3a_model.copy()
    g_bare = m0.create_data().gravity(m0.home).copy()
    apply_payload(m0, Payload(2.0, (0.0, 0.0, 0.1)))
    g_load = m0.create_data().gravity(m0.home).copy()
    assert np.max(np.abs(g_load - g_bare)) > 0.5
    assert m0.payload is not None
    # re-applying arm parameters keeps the load on
    from hofto_hw.model.parameters import ParametersFile

    n = 6
    pf = ParametersFile(
        robot=er3a_model.name,
        joints=list(er3a_model.joint_names),
        urdf_sha256="",
        inertial=er3a_model.inertial_parameters().reshape(n, 10),
        rotor_inertia=er3a_model.rotor_inertia,
        coulomb=np.zeros(n),
        viscous=np.zeros(n),
        bias=np.zeros(n),
    )
    write_parameters(tmp_path / "p.yaml", pf)
    apply_parameters(m0, read_parameters(tmp_path / "p.yaml"))
    assert np.allclose(m0.create_data().gravity(m0.home), g_load)


@pytest.mark.skipif(not LOAD.is_file(), reason=f"UR10e recordings not found at {LOAD}")
def test_load_recording_replays_clean_with_the_identified_payload(tmp_path, capsys) -> None:
    shutil.copytree(CONFIGS / "ur10e", tmp_path / "ur10e")
    params = tmp_path / "ur10e" / "parameters.yaml"
    block = tmp_path / "payload.yaml"
    assert main(["payload", "identify", str(params), str(LOAD), str(LOAD2), "-o", str(block)]) == 0
    out = capsys.readouterr().out
    assert "mass" in out and "±" in out
    import yaml

    p = yaml.safe_load(block.read_text())["payload"]
    assert 2.6 < p["mass"] < 3.0  # the 2.805 kg load (calibrated drive gains)
    text = (CONFIGS / "ur10e.yaml").read_text()
    (tmp_path / "ur10e.yaml").write_text(text)  # without the payload
    assert main(["replay", str(params), str(LOAD), "--json"]) == 0
    import json

    bare = json.loads(capsys.readouterr().out)
    assert len(bare["episodes"]) >= 1  # the load's weight is reported as a contact
    payload = f"  payload: {{mass: {p['mass']}, com: {p['com']}}}\n"
    (tmp_path / "ur10e.yaml").write_text(
        text.replace("  tool_frame: tool0\n", "  tool_frame: tool0\n" + payload, 1)
    )
    assert main(["replay", str(params), str(LOAD), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == []


def _loaded_samples(model, payload, moving: bool, n_samples: int = 300):
    loaded = model.copy()
    apply_payload(loaded, payload)
    rng = np.random.default_rng(1)
    q = rng.uniform(-1.5, 1.5, (n_samples, 6))
    qd = rng.uniform(-1.5, 1.5, (n_samples, 6)) * moving
    qdd = rng.uniform(-4.0, 4.0, (n_samples, 6)) * moving
    data = loaded.create_data()
    tau = np.array([data.inverse_dynamics(q[k], qd[k], qdd[k]).copy() for k in range(n_samples)])
    tau += rng.normal(0.0, 0.01, tau.shape)  # a little noise: std devs are then finite
    return Samples(q, qd, qdd, tau, "sim")


def test_identify_payload_recovers_the_inertia_when_the_motion_excites_it(er3a_model) -> None:
    inertia = (0.06, 0.004, 0.09, -0.003, 0.002, 0.04)  # about the com, tool axes [kg·m²]
    payload = Payload(3.0, (0.02, -0.01, 0.08), inertia)
    est = identify_payload(er3a_model, [_loaded_samples(er3a_model, payload, True)], inertia=True)
    assert est.mass == pytest.approx(3.0, rel=1e-3)
    assert np.allclose(est.com, [0.02, -0.01, 0.08], atol=1e-3)
    assert np.allclose(est.inertia, inertia, atol=3e-3)
    assert est.inertia_std is not None and np.all(est.inertia_std < 3e-3)
    assert est.identifiable
    assert est.as_config()["inertia"] == pytest.approx(list(inertia), abs=3e-3)


def test_payload_inertia_is_not_identifiable_from_static_poses(er3a_model) -> None:
    payload = Payload(3.0, (0.02, -0.01, 0.08), (0.06, 0.0, 0.09, 0.0, 0.0, 0.04))
    est = identify_payload(er3a_model, [_loaded_samples(er3a_model, payload, False)], inertia=True)
    assert est.mass == pytest.approx(3.0, rel=1e-2)  # gravity alone still gives m and m·c
    assert not est.identifiable
    assert "inertia" not in est.as_config()


@pytest.mark.slow
@pytest.mark.skipif(not LOAD.is_file(), reason=f"UR10e recordings not found at {LOAD}")
def test_load_recording_inertia_is_reported_not_identifiable(tmp_path, capsys) -> None:
    """The UR10e load runs excite the inertia columns but the fit is the arm's model error
    (negative moments, 10x the std dev between runs): reported, not written."""
    block = tmp_path / "payload.yaml"
    params = CONFIGS / "ur10e" / "parameters.yaml"
    assert main(["payload", "identify", str(params), str(LOAD), "--inertia", "-o", str(block)]) == 0
    out = capsys.readouterr().out
    assert "Ixx" in out and "±" in out and "inertia identifiable: no" in out
    import yaml

    p = yaml.safe_load(block.read_text())["payload"]
    assert "inertia" not in p and 2.6 < p["mass"] < 3.0  # 2.805 kg on the calibrated gains
