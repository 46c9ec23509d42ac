"""``hofto-hw brake test`` over the simulated bus."""

from __future__ import annotations

import shutil
from pathlib import Path

import yaml

from hofto_hw.cli import main
from tests.conftest import CONFIGS


def _config(tmp_path: Path, brake: dict | str) -> Path:
    shutil.copytree(CONFIGS / "er3a", tmp_path / "er3a")
    doc = yaml.safe_load((CONFIGS / "er3a.yaml").read_text())
    doc["bus"]["drives"][1]["brake"] = brake
    path = tmp_path / "er3a.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


BRAKE = {"control": "output", "release_delay": 0.05, "engage_delay": 0.05, "holding_torque": 60.0}


def test_a_good_brake_holds(tmp_path, capsys) -> None:
    code, out, err = _run(capsys, "brake", "test", "--config", _config(tmp_path, BRAKE))
    assert code == 0, err
    assert out.startswith("brake test: joint_2 held 80% of 60 N·m (largest motion")


def test_drive_controlled_brake_is_skipped_and_bad_fraction_refused(tmp_path, capsys) -> None:
    cfg = _config(tmp_path, {**BRAKE, "control": "drive"})
    code, out, _ = _run(capsys, "brake", "test", "--config", cfg)
    assert code == 0 and "the drive controls its brake" in out
    code, _, err = _run(capsys, "brake", "test", "--config", cfg, "--torque", "1.5")
    assert code != 0 and len(err.strip().splitlines()) == 1 and "in (0, 1], got 1.5" in err
    code, _, err = _run(capsys, "brake", "test", "--config", cfg, "--joint", "1")
    assert code != 0 and "joint_1 has no brake" in err
