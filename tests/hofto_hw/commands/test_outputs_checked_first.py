"""Every output a user names is checked before the work it follows, written atomically, and
a failure to write is one line whose handler does not fail again (hofto_hw/outputs.py).

Before: ``run --summary-json`` into /proc or under a file was a traceback after the whole
run; ``payload identify -o`` naming a folder or a missing folder a traceback after the fit;
``log recover`` beside a log on a read-only mount a traceback from the cleanup of the
failure; ``mode drag --record`` into /proc was accepted and failed when the drag ended.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from support.cli import one_line_error, read_only_reason, run_limited

from hofto_hw.cli import main
from hofto_hw.recording.writer import write_joint_states

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
PARAMS = CONFIGS / "ur10e" / "parameters.yaml"
PUSH = ROOT / "tests" / "data" / "ur10e" / "push_pose_1_rows100-600.csv"


def _run(capsys: pytest.CaptureFixture[str], *argv: object) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("where", ["under a file", "in /proc", "a folder"])
def test_run_summary_json_is_checked_before_the_run(where: str, tmp_path: Path) -> None:
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine\n")
    target = {
        "under a file": a_file / "summary.json",
        "in /proc": Path("/proc/hofto-hw-summary.json"),
        "a folder": tmp_path,
    }[where]
    needle = {
        "under a file": "is not a folder",
        "in /proc": "is not writable",
        "a folder": "is a folder",
    }[where]
    logs = tmp_path / "logs"
    argv = ["run", "--clock", "sim", "--duration", "0.2", "--log-dir", str(logs)]
    code, out, err, _ = run_limited([*argv, "--summary-json", str(target)], timeout=300)
    one_line_error(code, err, "--summary-json", str(target), needle)  # not "running (pid"
    assert out == ""
    assert not logs.exists()  # refused before the recorder started
    assert a_file.read_text() == "mine\n"


def test_run_summary_json_is_written_atomically(tmp_path: Path) -> None:
    out = tmp_path / "summary.json"
    out.write_text("old\n")
    argv = ["run", "--clock", "sim", "--duration", "0.2", "--no-log", "--no-collision"]
    code, stdout, err, _ = run_limited([*argv, "--summary-json", str(out)], timeout=300)
    assert code == 0, err
    assert out.read_text().startswith("{")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]  # no temp left


@pytest.mark.parametrize("where", ["a folder", "a missing folder"])
def test_payload_output_is_checked_before_the_fit(
    where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path if where == "a folder" else tmp_path / "no" / "payload.yaml"
    code, out, err = _run(capsys, "payload", "identify", PARAMS, PUSH, "-o", target)
    one_line_error(code, err, "--output", str(target))
    assert out == ""
    assert list(tmp_path.iterdir()) == []


def test_payload_output_may_not_be_an_input(tmp_path: Path, capsys) -> None:
    params = tmp_path / "parameters.yaml"
    params.write_bytes(PARAMS.read_bytes())
    code, out, err = _run(capsys, "payload", "identify", params, PUSH, "-o", params)
    one_line_error(code, err, "--output", str(params), "is an input")
    assert params.read_bytes() == PARAMS.read_bytes()


def _truncated_log(folder: Path) -> Path:
    t = np.arange(5000) * 1e-3
    q = np.random.default_rng(0).normal(size=(5000, 6))
    full = folder / "full.mcap"
    write_joint_states(full, t, q, q, q)
    cut = folder / "run.mcap"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    full.unlink()
    return cut


def test_log_recover_beside_a_log_on_a_read_only_mount(tmp_path: Path) -> None:
    reason = read_only_reason()
    if reason is not None:
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    folder = tmp_path / "ro"
    folder.mkdir()
    log = _truncated_log(folder)
    code, out, err, _ = run_limited(["log", "recover", str(log)], read_only=str(folder))
    dst = folder / "run.recovered.mcap"
    one_line_error(code, err, str(dst), "is not writable", "Read-only file system")
    assert sorted(p.name for p in folder.iterdir()) == ["run.mcap"]


def test_log_recover_output_is_checked_before_reading(tmp_path: Path, capsys) -> None:
    log = _truncated_log(tmp_path)
    code, out, err = _run(capsys, "log", "recover", log, "-o", tmp_path / "no" / "x.mcap")
    one_line_error(code, err, "-o", "does not exist")
    code, out, err = _run(capsys, "log", "recover", log, "-o", "/proc/x.mcap")
    one_line_error(code, err, "/proc/x.mcap", "is not writable")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]


def test_drag_record_into_an_unwritable_place_is_refused_when_requested() -> None:
    # hofto_hw.control_plane.server calls this when it accepts
    # `mode drag --record FILE`; before, os.access let root "write" into /proc
    from hofto_hw.errors import UserError
    from hofto_hw.runtime.teach import check_output

    with pytest.raises(UserError, match=r"^/proc/taught\.csv: folder '/proc' is not writable"):
        check_output("/proc/taught.csv", force=False)
