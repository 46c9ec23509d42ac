"""``hofto-hw excite / identify / validate`` end to end on simulated ER3A recordings, and
their one-line errors (no traceback) for bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.cli import main
from hofto_hw.identify.excitation import trajectory_from_vector
from hofto_hw.identify.simulate import simulate_tracking

from .conftest import CONFIGS

COLUMNS = """name: sim-19
columns: 19
time: 1
q: [2, 3, 4, 5, 6, 7]
qd: [8, 9, 10, 11, 12, 13]
torque: [14, 15, 16, 17, 18, 19]
"""


def _write_run(path: Path, model, sim, seed: int, duration: float, frozen: int | None = None):
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 0.5, (6, 8)) / np.tile(np.arange(1, 5), 2)
    if frozen is not None:
        X[frozen] = 0.0
    X = np.hstack([model.home[:, None], X])
    traj = trajectory_from_vector(X.ravel(), 6, 5, duration)
    rec = simulate_tracking(model, sim, traj, 200.0, duration).measured
    np.savetxt(path, np.column_stack([rec.t, rec.q, rec.qd, rec.tau]), delimiter=",", fmt="%.8g")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory, er3a_config, er3a_model):
    root = tmp_path_factory.mktemp("cli")
    text = (CONFIGS / "er3a.yaml").read_text()
    urdf = root / "er3a.urdf"
    urdf.write_bytes((CONFIGS / "er3a" / "er3a.urdf").read_bytes())
    (root / "er3a.yaml").write_text(text.replace("urdf: er3a/er3a.urdf", f"urdf: {urdf}"))
    (root / "columns_19.yaml").write_text(COLUMNS)
    sim = er3a_config.simulation.model_copy(deep=True)
    sim.external = []
    _write_run(root / "train.csv", er3a_model, sim, 0, 20.0)
    _write_run(root / "test.csv", er3a_model, sim, 5, 10.0)
    _write_run(root / "frozen.csv", er3a_model, sim, 1, 10.0, frozen=5)
    return root


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _identify(capsys, workspace: Path, output: Path, *args: object) -> tuple[int, str, str]:
    """``hofto-hw identify`` with the workspace's config writing ``output``."""
    return _run(capsys, "identify", "--config", workspace / "er3a.yaml", "-o", output, *args)


def test_identify_then_validate(workspace: Path, capsys) -> None:
    params = workspace / "params.yaml"
    code, out, err = _identify(
        capsys,
        workspace,
        params,
        "--columns",
        workspace / "columns_19.yaml",
        workspace / "train.csv",
    )
    assert code == 0, err
    assert "joint_6" in out and "rel. RMSE" in out and "condition number" in out
    assert "samples" in err  # progress on stderr
    # validate finds the config by robot name and the column map by row width
    code, out, err = _run(
        capsys,
        "validate",
        params,
        workspace / "test.csv",
        "--json",
        "--plot",
        workspace / "fit.png",
    )
    assert code == 0, err
    report = json.loads(out)
    overall = report["overall"]["params"]
    assert len(overall["rmse"]) == 6
    assert max(overall["relative_rmse_percent"][:3]) < 10.0
    assert (workspace / "fit.png").stat().st_size > 10_000
    code, out, _ = _run(capsys, "validate", params, workspace / "test.csv", "--no-plot")
    assert code == 0 and "all files" in out


def _one_line_error(code: int, err: str, match: str) -> None:
    assert code == 2
    assert "Traceback" not in err
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("hofto-hw")]
    assert len(lines) == 1 and match in lines[0], err


def test_bad_inputs_fail_clearly(workspace: Path, capsys) -> None:
    code, _, err = _identify(capsys, workspace, workspace / "x.yaml", workspace / "train.csv@1:30")
    _one_line_error(code, err, "too")
    code, _, err = _identify(capsys, workspace, workspace / "x.yaml", workspace / "frozen.csv")
    _one_line_error(code, err, "joint_6")
    # a parameters file for an unknown robot
    params = workspace / "params_other.yaml"
    code, _, err = _identify(capsys, workspace, params, "--method", "wls", workspace / "train.csv")
    assert code == 0, err
    params.write_text(params.read_text().replace("robot: er3a", "robot: robot9000"))
    code, _, err = _run(capsys, "validate", params, workspace / "test.csv", "--no-plot")
    _one_line_error(code, err, "unknown robot 'robot9000'")
    # a parameters file identified for another URDF
    params.write_text(params.read_text().replace("robot: robot9000", "robot: er3a"))
    urdf = workspace / "er3a.urdf"
    original = urdf.read_bytes()
    try:
        urdf.write_bytes(original + b"\n<!-- edited -->\n")
        code, _, err = _run(capsys, "validate", params, workspace / "test.csv", "--no-plot")
        _one_line_error(code, err, "different URDF")
    finally:
        urdf.write_bytes(original)


def test_excite_writes_trajectory_and_plot(workspace: Path, capsys) -> None:
    out_csv = workspace / "exc.csv"
    code, out, err = _run(
        capsys,
        "excite",
        "--config",
        workspace / "er3a.yaml",
        "-o",
        out_csv,
        "--harmonics",
        "3",
        "--period",
        "6",
        "--iterations",
        "3",
        "--rate",
        "50",
        "--no-torque-limits",
    )
    assert code == 0, err
    assert "condition number" in out and "iteration" in err
    data = np.loadtxt(out_csv, delimiter=",", skiprows=1)
    assert out_csv.read_text().startswith("t,q1,")
    assert data.shape == (301, 19)
    np.testing.assert_allclose(data[[0, -1], 7:], 0.0, atol=1e-9)  # rest at both ends
    assert out_csv.with_suffix(".png").stat().st_size > 10_000
    code, _, err = _run(
        capsys, "excite", "--config", workspace / "er3a.yaml", "-o", out_csv, "--period", "0"
    )
    _one_line_error(code, err, "--period")
