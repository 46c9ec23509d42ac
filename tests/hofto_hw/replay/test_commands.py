"""`hofto-hw replay` and `hofto-hw thresholds` end to end on the UR10e samples in the repo."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hofto_hw.cli import main

ROOT = Path(__file__).resolve().parents[3]
PARAMS = ROOT / "configs" / "ur10e" / "parameters.yaml"
SAMPLES = ROOT / "tests" / "data" / "ur10e"
PUSH = SAMPLES / "push_pose_1_rows100-600.csv"
EXCITATION = SAMPLES / "excitation_30sec_12harm_rows601-840.csv"


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _write(tmp_path: Path, name: str, lines: list[str]) -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_replay_lists_the_two_pushes(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    png = tmp_path / "push.png"
    assert main(["replay", str(PARAMS), str(PUSH), "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "2 contact episode(s)" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_replay_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(PARAMS), str(PUSH), "--json", "--observer", "hofto"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["observer"] == "hofto" and d["samples"] == 501
    assert len(d["episodes"]) == 2
    first, second = d["episodes"]
    assert first["joints"] == [1]  # the first push turns the base only
    assert 2 in second["joints"] and second["peak"][1] > 40.0
    assert [j["joint"] for j in d["joints"]] == [1, 2, 3, 4, 5, 6]
    assert all(j["max_ratio"] < 1.0 for j in d["joints"][5:])


def test_observer_without_thresholds(capsys: pytest.CaptureFixture[str]) -> None:
    # sta has no calibrated thresholds: refused, naming the observer
    assert main(["replay", str(PARAMS), str(PUSH), "--observer", "sta"]) == 2
    assert "no thresholds for observer 'sta'" in capsys.readouterr().err
    # ... unless only statistics are asked for
    assert main(["replay", str(PARAMS), str(PUSH), "--observer", "sta", "--no-thresholds"]) == 0
    out = capsys.readouterr().out
    assert "statistics only" in out and "episode" not in out


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("nan", r"row 7: column 9 \(qd\): NaN"),
        ("backwards", r"row 31: column time: .* does not advance"),
        ("columns19", r"19 columns and no column map .*columns_19\.yaml"),
        ("columns25", r"rows have 25 columns, column map 'ur10e-31' expects 31"),
        ("short", r"too short: 3 rows"),
    ],
)
def test_bad_recordings_fail_with_one_clear_line(
    edit: str, message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    lines = _lines(EXCITATION)
    extra: list[str] = []
    if edit == "nan":
        f = lines[6].split(",")
        f[8] = "nan"
        lines[6] = ",".join(f)
    elif edit == "backwards":
        lines[29], lines[30] = lines[30], lines[29]
    elif edit == "columns19":
        lines = [",".join(ln.split(",")[:19]) for ln in lines]
    elif edit == "columns25":
        lines = [",".join(ln.split(",")[:25]) for ln in lines]
        extra = ["--columns", str(ROOT / "configs" / "ur10e" / "columns_31.yaml")]
    elif edit == "short":
        lines = lines[:3]
    p = _write(tmp_path, f"{edit}.csv", lines)
    assert main(["replay", str(PARAMS), str(p), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"{edit}.csv" in err
    import re

    assert re.search(message, err), err


def test_unknown_robot_and_foreign_urdf(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    text = PARAMS.read_text()
    other = _write(tmp_path, "foo_params.yaml", [text.replace("robot: ur10e", "robot: foo")])
    assert main(["replay", str(other), str(PUSH)]) == 2
    assert "unknown robot 'foo'" in capsys.readouterr().err
    sha = next(ln for ln in text.splitlines() if ln.startswith("urdf_sha256:"))
    foreign = _write(tmp_path, "foreign.yaml", [text.replace(sha, "urdf_sha256: " + "ab" * 32)])
    cfg = ROOT / "configs" / "ur10e.yaml"
    assert main(["replay", str(foreign), str(PUSH), "--config", str(cfg)]) == 2
    assert "different URDF" in capsys.readouterr().err


def test_calibrate_then_check(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out = tmp_path / "th.yaml"
    args = ["thresholds", "calibrate", "--params", str(PARAMS), "-o", str(out)]
    assert main([*args, "--observer", "momentum", str(EXCITATION)]) == 0
    assert "momentum" in capsys.readouterr().out
    check = ["thresholds", "check", "--params", str(PARAMS), "--thresholds", str(out), "--json"]
    assert main([*check, str(EXCITATION), str(PUSH)]) == 0
    res = {Path(r["file"]).name: r for r in json.loads(capsys.readouterr().out)}
    assert res[EXCITATION.name]["episodes"] == []  # calibrated on it: covered with margin
    assert res[EXCITATION.name]["max_ratio"] < 1.0 / 1.6 + 1e-6
    assert len(res[PUSH.name]["episodes"]) >= 1
    wrong = _write(tmp_path, "wrong.yaml", [out.read_text().replace("robot: ur10e", "robot: x")])
    assert main(["replay", str(PARAMS), str(PUSH), "--thresholds", str(wrong)]) == 2
    assert "thresholds are for robot 'x'" in capsys.readouterr().err
