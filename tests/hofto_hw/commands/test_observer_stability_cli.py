"""Unstable observer gains are refused by config check, demo, replay and thresholds with one
line and exit code 2 (issue 7: 200 1/s on 100 Hz data gave 1e83 N·m; 5000 at 1 kHz gave nan)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hofto_hw.cli import main

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
PARAMS = CONFIGS / "ur10e" / "parameters.yaml"
PUSH = ROOT / "tests" / "data" / "ur10e" / "push_pose_1_rows100-600.csv"


def _er3a_with_momentum_gain(tmp_path: Path, gain: float) -> Path:
    text = (CONFIGS / "er3a.yaml").read_text()
    text = text.replace("gain: [30.0, 30.0, 30.0, 30.0, 30.0, 30.0]", f"gain: [{gain}] * 6")
    text = text.replace(f"gain: [{gain}] * 6", "gain: [" + ", ".join([str(gain)] * 6) + "]")
    text = text.replace("urdf: er3a/er3a.urdf", f"urdf: {CONFIGS}/er3a/er3a.urdf")
    path = tmp_path / "er3a_fast_momentum.yaml"
    path.write_text(text)
    return path


def _one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def test_config_check_refuses_momentum_5000_at_1khz(tmp_path, capsys) -> None:
    path = _er3a_with_momentum_gain(tmp_path, 5000.0)
    assert main(["config", "check", str(path)]) == 2
    err = _one_line_error(capsys)
    assert str(path) in err and "observers.momentum.gain[0] = 5000 1/s" in err
    assert "1000 Hz" in err and "gain < 2000 1/s" in err
    ok = _er3a_with_momentum_gain(tmp_path, 1500.0)
    assert main(["config", "check", str(ok)]) == 0


def test_demo_refuses_momentum_5000_at_1khz(tmp_path, capsys) -> None:
    path = _er3a_with_momentum_gain(tmp_path, 5000.0)
    assert main(["demo", "--config", str(path), "--json", "--no-plot"]) == 2
    err = _one_line_error(capsys)
    assert "observers.momentum.gain[0] = 5000 1/s" in err and "1000 Hz" in err


def test_replay_refuses_momentum_200_on_100hz_data(tmp_path, capsys) -> None:
    text = (CONFIGS / "ur10e.yaml").read_text()
    text = text.replace("urdf: ur10e/ur10e.urdf", f"urdf: {CONFIGS}/ur10e/ur10e.urdf")
    text += (
        "\nobservers:\n  momentum:\n    type: momentum\n    gain: [200, 200, 200, 200, 200, 200]\n"
    )
    cfg = tmp_path / "ur10e.yaml"
    cfg.write_text(text)
    cols = CONFIGS / "ur10e" / "columns_31.yaml"
    args = ["replay", str(PARAMS), str(PUSH), "--config", str(cfg), "--columns", str(cols)]
    args.append("--no-thresholds")
    assert main(args) == 2
    err = _one_line_error(capsys)
    assert PUSH.name in err and "observers.momentum.gain[0] = 200 1/s" in err
    assert "100 Hz" in err and "gain < 200 1/s" in err


def test_thresholds_calibrate_refuses_and_writes_nothing(tmp_path, capsys) -> None:
    text = (CONFIGS / "ur10e.yaml").read_text()
    text = text.replace("urdf: ur10e/ur10e.urdf", f"urdf: {CONFIGS}/ur10e/ur10e.urdf")
    text += "\nobservers:\n  momentum:\n    type: momentum\n    gain: [20, 20, 20, 20, 20, 300]\n"
    cfg = tmp_path / "ur10e.yaml"
    cfg.write_text(text)
    out = tmp_path / "thresholds.yaml"
    cols = CONFIGS / "ur10e" / "columns_31.yaml"
    args = ["thresholds", "calibrate", "--params", str(PARAMS), "-o", str(out)]
    args += ["--observer", "momentum", "--config", str(cfg), "--columns", str(cols), str(PUSH)]
    assert main(args) == 2
    err = _one_line_error(capsys)
    assert "observers.momentum.gain[5] = 300 1/s (joint 6 (wrist_3_joint))" in err
    assert not out.exists()
