"""Bad input through the ``hofto-hw`` commands: exit code 2, one line naming the file, field
or value, no traceback, nothing written where the user did not ask."""

from __future__ import annotations

import errno
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from support.cli import one_line_error

from hofto_hw.cli import main

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
PARAMS = CONFIGS / "ur10e" / "parameters.yaml"
COLUMNS_31 = CONFIGS / "ur10e" / "columns_31.yaml"
SAMPLES = ROOT / "tests" / "data" / "ur10e"
PUSH = SAMPLES / "push_pose_1_rows100-600.csv"
EXCITATION = SAMPLES / "excitation_30sec_12harm_rows601-840.csv"


def _run(capsys: pytest.CaptureFixture[str], *argv: object) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# ------------------------------------------------------------------------- plot paths


@pytest.mark.parametrize(
    "argv",
    [
        ["replay", PARAMS, PUSH, "--plot", "{dir}"],
        ["validate", PARAMS, EXCITATION, "--plot", "{dir}"],
        ["demo", "--duration", "6", "--plot", "{dir}"],
    ],
    ids=["replay", "validate", "demo"],
)
def test_plot_path_that_is_a_folder_is_refused(argv, tmp_path, capsys) -> None:
    folder = tmp_path / "figs"
    folder.mkdir()
    argv = [str(a).replace("{dir}", str(folder)) for a in argv]
    code, out, err = _run(capsys, *argv)
    one_line_error(code, err, "--plot", str(folder), "is a folder")
    assert out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figs"]  # no figs.png beside it
    assert list(folder.iterdir()) == []


def test_plot_without_png_suffix_is_written_exactly_there(tmp_path, capsys) -> None:
    target = tmp_path / "figure"
    code, out, err = _run(capsys, "replay", PARAMS, PUSH, "--plot", target)
    assert code == 0, err
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"plot: {target}" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure"]


# ---------------------------------------------------------------- parameters files


@pytest.mark.parametrize(
    ("field", "index", "value", "needle"),
    [
        (("friction", "viscous"), 1, -0.5, "model.friction.viscous: joint 2"),
        (("friction", "coulomb"), 0, -3.0, "model.friction.coulomb: joint 1"),
        (("rotor_inertia",), 3, -0.01, "model.rotor_inertia: joint 4"),
        (("inertial",), 2, -1.0, "link mass): joint 3"),
    ],
)
def test_non_physical_parameters_are_refused(field, index, value, needle, tmp_path, capsys):
    data = yaml.safe_load(PARAMS.read_text())
    node = data["model"]
    for key in field[:-1]:
        node = node[key]
    if field[-1] == "inertial":
        node["inertial"][index][0] = value
    else:
        node[field[-1]][index] = value
    bad = tmp_path / "parameters.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False))
    code, _, err = _run(capsys, "replay", bad, PUSH, "--config", "ur10e")
    line = one_line_error(code, err, str(bad), needle, "not physical")
    assert f"{value:g}" in line


# ------------------------------------------------------------- column maps, robots


def test_column_map_of_another_robot_is_refused_by_identify(tmp_path, capsys) -> None:
    code, _, err = _run(
        capsys,
        "identify",
        "--config",
        "er3a",
        "-o",
        tmp_path / "p.yaml",
        "--columns",
        COLUMNS_31,
        EXCITATION,
    )
    one_line_error(code, err, str(COLUMNS_31), "robot 'ur10e'", "'er3a'")
    assert not (tmp_path / "p.yaml").exists()


@pytest.mark.parametrize("command", ["replay", "validate"])
def test_column_map_of_another_robot_is_refused(command, tmp_path, capsys) -> None:
    other = tmp_path / "columns_other.yaml"
    other.write_text(COLUMNS_31.read_text().replace("robot: ur10e", "robot: er3a"))
    extra = ["--no-plot"] if command == "validate" else []
    code, _, err = _run(capsys, command, PARAMS, PUSH, "--columns", other, *extra)
    one_line_error(code, err, str(other), "robot 'er3a'", "'ur10e'")


# ---------------------------------------------------------------- numeric options


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-1", "0", "abc"])
@pytest.mark.parametrize(
    "argv",
    [
        ["demo", "--no-plot", "--duration"],
        ["excite", "--config", "er3a", "-o", "{tmp}/x.csv", "--period"],
        ["identify", "--config", "er3a", "-o", "{tmp}/p.yaml", str(EXCITATION), "--cutoff"],
        ["validate", str(PARAMS), str(EXCITATION), "--cutoff"],
        ["thresholds", "calibrate", "--params", str(PARAMS), "-o", "{tmp}/t.yaml", "--debounce"],
    ],
    ids=["demo-duration", "excite-period", "identify-cutoff", "validate-cutoff", "debounce"],
)
def test_non_finite_or_non_positive_numbers_are_refused(argv, value, tmp_path, capsys) -> None:
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    option = argv.pop()
    extra = [str(EXCITATION)] if argv[0] == "thresholds" else []
    code, out, err = _run(capsys, *argv, f"{option}={value}", *extra)  # = lets "-inf" through
    one_line_error(code, err, f"argument {option}", repr(value))
    assert out == ""
    assert list(tmp_path.iterdir()) == []


# -------------------------------------------------------------------------- outputs


def test_identify_into_a_missing_folder_fails_before_the_fit(tmp_path, capsys) -> None:
    target = tmp_path / "missing" / "p.yaml"
    code, out, err = _run(capsys, "identify", "--config", "er3a", "-o", target, EXCITATION)
    one_line_error(code, err, "--output", str(target.parent), "does not exist")
    assert "loaded" not in err and out == ""  # refused before reading anything
    assert not target.parent.exists()  # and nothing created


@pytest.fixture
def full_disk(monkeypatch):
    """Every figure write fails as on a full disk (root ignores permissions, so no chmod)."""
    import matplotlib.figure

    def no_space(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", no_space)


@pytest.mark.usefixtures("full_disk")
def test_validate_prints_numbers_then_reports_a_failed_figure(tmp_path, capsys):
    png = tmp_path / "fit.png"
    code, out, err = _run(capsys, "validate", PARAMS, EXCITATION, "--plot", png)
    one_line_error(code, err, str(png), "cannot write figure", "No space left on device")
    assert "all files" in out and "shoulder_pan_joint" in out  # the numbers came first
    assert not png.exists()


@pytest.mark.usefixtures("full_disk")
def test_replay_prints_report_then_reports_a_failed_figure(tmp_path, capsys):
    png = tmp_path / "push.png"
    code, out, err = _run(capsys, "replay", PARAMS, PUSH, "--plot", png)
    one_line_error(code, err, str(png), "cannot write plot")
    assert "contact episode(s)" in out


def test_output_that_is_an_input_is_refused(tmp_path, capsys) -> None:
    params = tmp_path / "parameters.yaml"
    params.write_bytes(PARAMS.read_bytes())
    before = params.read_bytes()
    code, _, err = _run(
        capsys,
        "thresholds",
        "calibrate",
        "--params",
        params,
        "--config",
        "ur10e",
        "-o",
        params,
        EXCITATION,
    )
    one_line_error(code, err, "--output", str(params), "refusing to overwrite")
    assert params.read_bytes() == before
    rec = tmp_path / "push.csv"
    rec.write_bytes(PUSH.read_bytes())
    code, _, err = _run(capsys, "replay", PARAMS, rec, "--plot", rec)
    one_line_error(code, err, "--plot", str(rec), "refusing to overwrite")
    assert rec.read_bytes() == PUSH.read_bytes()


# ------------------------------------------------------------------ broken pipes


def test_closed_stdout_exits_quietly() -> None:
    """`hofto-hw config schema | head -c 1`: the reader is gone before the writer writes."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "hofto_hw.cli", "config", "schema"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=ROOT,
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the schema (37 kB) is written after this: EPIPE for certain
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert err == ""


# ------------------------------------------------------------- binary recordings


@pytest.mark.parametrize("kind", ["binary", "latin1"])
@pytest.mark.parametrize("command", ["replay", "validate", "identify"])
def test_binary_or_non_utf8_recording_is_refused(kind, command, tmp_path, capsys) -> None:
    rec = tmp_path / f"{kind}.csv"
    text = EXCITATION.read_bytes()
    if kind == "binary":
        rec.write_bytes(bytes(range(256)) * 40)
        needle = "binary file"
    else:
        lines = text.splitlines()
        lines[4] = lines[4].replace(b",", b",\xe9", 1)  # 'é' in Latin-1
        rec.write_bytes(b"\n".join(lines) + b"\n")
        needle = "is not UTF-8"
    argv = {
        "replay": ["replay", PARAMS, rec],
        "validate": ["validate", PARAMS, rec, "--no-plot"],
        "identify": ["identify", "--config", "ur10e", "-o", tmp_path / "p.yaml", rec],
    }[command]
    code, _, err = _run(capsys, *argv)
    one_line_error(code, err, str(rec), needle)
