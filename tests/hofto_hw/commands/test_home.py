"""``hofto-hw home``: CiA 402 homing of the incremental axes over the simulated bus."""

from __future__ import annotations

import shutil
from pathlib import Path

import yaml

from hofto_hw.cli import main
from tests.conftest import CONFIGS


def _config(tmp_path: Path, homing: dict | str) -> Path:
    shutil.copytree(CONFIGS / "er3a", tmp_path / "er3a")
    doc = yaml.safe_load((CONFIGS / "er3a.yaml").read_text())
    doc["bus"]["drives"][1]["homing"] = homing
    path = tmp_path / "er3a.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_home_with_method_35_and_back(tmp_path, capsys) -> None:
    cfg = _config(
        tmp_path,
        {"method": 35, "speeds": [0.2, 0.02], "acceleration": 2.0, "offset": 0.25, "timeout": 1.0},
    )
    code, out, err = _run(capsys, "home", "--config", cfg)
    assert code == 0, err
    assert out.strip() == "home: joint_2 homed (method 35) at 0.2500 rad"


def test_absolute_joint_is_not_homed(tmp_path, capsys) -> None:
    cfg = _config(tmp_path, "none")
    code, out, err = _run(capsys, "home", "--config", cfg, "--joint", "2")
    assert code != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "homing: none: joint_2 has an absolute encoder" in lines[0]
    code, out, _ = _run(capsys, "home", "--config", cfg)
    assert code == 0 and "nothing to home" in out


def test_home_that_times_out_is_one_line(tmp_path, capsys) -> None:
    # method 17 on the simulated arm, whose joint 2 has no home switch, slowly: the timeout
    cfg = _config(
        tmp_path, {"method": 17, "speeds": [0.02, 0.01], "acceleration": 1.0, "timeout": 0.3}
    )
    code, _, err = _run(capsys, "home", "--config", cfg)
    assert code != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "joint_2: homing (method 17) did not end within" in lines[0]
