"""``hofto-hw mode drag --record FILE``, ``mode replay FILE``, ``mode move --joints`` against a
running loop (simulated arm, sim clock in a thread, the control socket): bad input is one line
and exit 2 and changes nothing; good input plays through the loop."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from support.cli import one_line_error

from hofto_hw.cli import main
from hofto_hw.client import Robot
from hofto_hw.config.loader import load_config
from hofto_hw.control.joint_motion import HOLD
from hofto_hw.control.taught_path import (
    TaughtPath,
    TaughtPathRecorder,
    load_taught_path,
    save_taught_path,
)
from hofto_hw.control_plane.channel import PLAN_CAP
from hofto_hw.control_plane.process import InProcessControl
from hofto_hw.runtime.compose import build

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


def _wait(cond, seconds: float = 60.0) -> None:
    end = time.monotonic() + seconds
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not reached")
        time.sleep(0.01)


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory):
    """The loop running back to back in a thread with the control socket served."""
    cfg = load_config(CONFIG)
    enable = cfg.drag.enable_input.model_copy(update={"source": "socket"})
    cfg = cfg.model_copy(update={"drag": cfg.drag.model_copy(update={"enable_input": enable})})
    system = build(cfg, clock="sim", contact=False)
    sock = tmp_path_factory.mktemp("sock") / "control.sock"
    server = InProcessControl(sock, system)
    server.start()
    done = threading.Event()
    runner = threading.Thread(target=lambda: system.loop.run(should_stop=done.is_set))
    runner.start()
    try:
        _wait(lambda: system.loop.ticks > 300)
        yield system, sock
    finally:
        done.set()
        runner.join()
        server.close()
        system.close()


def _path(model, seconds: float = 2.0, offset: np.ndarray | None = None) -> TaughtPath:
    """A smooth taught path from the home pose (at rest at both ends)."""
    rec = TaughtPathRecorder(model.n, 10000)
    t = np.arange(0.0, seconds, 1e-3)
    s = 0.5 * (1.0 - np.cos(np.pi * t / seconds))
    d = np.array([0.15, -0.1, 0.1, 0.2, -0.1, 0.2]) if offset is None else offset
    for tk, sk in zip(t, s, strict=True):
        rec.push(tk, model.home + sk * d)
    return rec.path(model)


def _run(capsys, sock: Path, *argv: object) -> tuple[int, str, str]:
    code = main(["mode", *[str(a) for a in argv], "--socket", str(sock)])
    out, err = capsys.readouterr()
    return code, out, err


def _bad_files(model, folder: Path) -> dict[str, tuple[Path, str]]:
    good = save_taught_path(_path(model), folder / "good.csv")
    text = good.read_text()
    files = {}
    cut = folder / "cut.csv"
    cut.write_text(text[: len(text) // 2 - 7])
    files["truncated"] = (cut, "truncated")
    binary = folder / "bin.csv"
    binary.write_bytes(b"\x89MCAP0\r\n\x00\x00\x01" * 10)
    files["binary"] = (binary, "binary data")
    other = folder / "other.csv"
    other.write_text(text.replace("# robot: er3a", "# robot: ur10e", 1))
    files["other robot"] = (other, "taught on robot 'ur10e'")
    far = folder / "far.csv"
    save_taught_path(_path(model, offset=np.array([0, 0, 0, 0, 0, 9.0])), far)
    files["out of limits"] = (far, "outside its limits")
    files["missing"] = (folder / "nothing.csv", "not found")
    return files


BAD_COMMANDS = [
    (("hold", "--record", "x.csv"), "--record: only with mode drag"),
    (("drag", "--force"), "--force: only with --record"),
    (("replay",), "needs the taught-path FILE"),
    (("hold", "some.csv"), "takes no FILE"),
    (("move", "--degrees"), "--degrees: only with --joints"),
    (("drag", "--joints", "0,0,0,0,0,0"), "--joints: only with mode move"),
    (("move", "--joints", "0.1,0.2,0.3"), "3 values, er3a has 6 joints"),
    (("move", "--joints", "0,0.3,0.9,nan,0.6,0"), "joint_4: nan is not a finite number"),
    (("move", "--joints", "0,0.3,0.9,0,0.6,inf"), "not a finite number"),
    (("move", "--joints", "0,0.3,9,0,0.6,0"), "joint_3: 9.0000 rad outside its limits"),
    (("move", "--joints", "0,0.3,0.9,0,600,0", "--degrees"), "outside its limits"),
    (("move", "--joints", "0,zero,0,0,0,0"), "expected comma-separated numbers"),
]


@pytest.mark.parametrize(("argv", "needle"), BAD_COMMANDS)
def test_bad_command_line_is_one_line_and_changes_nothing(service, capsys, argv, needle) -> None:
    system, sock = service
    code, _, err = _run(capsys, sock, *argv)
    one_line_error(code, err, needle)
    assert system.tick.motion.mode == HOLD and system.tick.playback is None


def test_bad_taught_path_files(service, capsys, tmp_path: Path) -> None:
    system, sock = service
    for what, (file, needle) in _bad_files(system.model, tmp_path).items():
        code, _, err = _run(capsys, sock, "replay", file)
        one_line_error(code, err, str(file), needle)
        assert system.tick.motion.mode == HOLD and system.tick.playback is None, what


def test_record_refuses_existing_file_folder_and_missing_folder(
    service, capsys, tmp_path: Path
) -> None:
    system, sock = service
    existing = tmp_path / "mine.csv"
    existing.write_text("the user's own data\n")
    code, _, err = _run(capsys, sock, "drag", "--record", existing)
    one_line_error(code, err, str(existing), "exists; not overwriting it", "--force")
    assert existing.read_text() == "the user's own data\n"
    code, _, err = _run(capsys, sock, "drag", "--record", tmp_path)
    one_line_error(code, err, "is a folder")
    missing = tmp_path / "no" / "such" / "x.csv"
    code, _, err = _run(capsys, sock, "drag", "--record", missing)
    one_line_error(code, err, str(missing), "does not exist")
    under_file = existing / "x.csv"  # a "folder" that is a file
    code, _, err = _run(capsys, sock, "drag", "--record", under_file)
    one_line_error(code, err, "does not exist")
    assert system.tick.motion.mode == HOLD and system.tick.recording is None


def test_drag_record_with_nothing_taught_writes_no_file(service, capsys, tmp_path: Path) -> None:
    system, sock = service
    out = tmp_path / "taught.csv"
    code, stdout, err = _run(capsys, sock, "drag", "--record", out)
    assert code == 0, err
    assert f"recording the taught path to {out}" in stdout
    assert system.tick.recording is not None
    # the enabling input is never pressed: leaving drag saves nothing
    code, stdout, err = _run(capsys, sock, "hold")
    assert code == 0, err
    assert "nothing was taught" in stdout
    assert not out.exists()
    _wait(lambda: system.tick.motion.mode == HOLD)


def test_move_joints_and_replay_play_through_the_loop(service, capsys, tmp_path: Path) -> None:
    system, sock = service
    tick, model = system.tick, system.model
    target = model.home + np.array([0.2, -0.1, 0.15, 0.3, -0.2, 0.4])
    code, stdout, err = _run(
        capsys,
        sock,
        "move",
        "--joints",
        ",".join(f"{np.degrees(v):.10f}" for v in target),
        "--degrees",
    )
    assert code == 0, err
    assert "moving to the joint target" in stdout
    _wait(lambda: tick.playback is not None and tick.playback.completed)
    _wait(lambda: np.abs(system.group.qd).max() < 0.01)
    assert np.abs(system.group.q - target).max() < 2e-3
    # replay: first the move back to the path's start (home), then the path
    # 6 s of path: more rows than the plan ring holds (streamed while it plays)
    taught = _path(model, seconds=6.0)
    file = save_taught_path(taught, tmp_path / "taught.csv")
    code, stdout, err = _run(capsys, sock, "replay", file)
    assert code == 0, err
    assert f"replaying {file}" in stdout and "to its start" in stdout
    pb = tick.playback
    assert pb.kind == "replay"
    code, stdout, err = _run(capsys, sock, "replay", file)  # while replaying: refused, exit 1
    assert code == 1 and "mode hold first" in stdout, (stdout, err)
    _wait(lambda: pb.completed)
    _wait(lambda: tick.motion.mode == HOLD)
    assert pb.completed and pb.player.rows > PLAN_CAP
    _wait(lambda: np.abs(system.group.qd).max() < 0.01)
    assert np.abs(system.group.q - taught.q[-1]).max() < 2e-3  # at the path's end
    assert main(["status", "--socket", str(sock)]) == 0
    assert f"last trajectory: replay of {file}, " in capsys.readouterr().out


def test_drag_record_then_hold_saves_the_taught_path(service, capsys, tmp_path: Path) -> None:
    system, sock = service
    tick = system.tick
    _wait(lambda: tick.motion.mode == HOLD and np.abs(system.group.qd).max() < 0.01)
    out = tmp_path / "held.csv"
    with Robot.connect(socket=sock) as robot:
        with robot.drag(record=out):  # the enabling lease held by the client
            _wait(lambda: tick.recording.recorder.count > 500)  # held, no push: it records
        assert f"saved to {out}" in robot.last_drag_message, robot.last_drag_message
    capsys.readouterr()
    path = load_taught_path(out, system.model)
    assert path.t.shape[0] == tick.recording.recorder.count > 500
    np.testing.assert_allclose(path.q[0], path.q[-1], atol=1e-3)  # no push: no motion
    assert main(["status", "--socket", str(sock)]) == 0
    assert "taught path: saved" in capsys.readouterr().out
    # the same name again: refused, the file kept
    before = out.read_bytes()
    _wait(lambda: tick.motion.mode == HOLD)
    code, _, err = _run(capsys, sock, "drag", "--record", out)
    one_line_error(code, err, "exists; not overwriting it")
    assert out.read_bytes() == before


def test_enable_on_holds_the_lease_for_its_seconds_then_lets_go(service, capsys) -> None:
    system, sock = service
    tick = system.tick
    _wait(lambda: tick.motion.mode == HOLD and np.abs(system.group.qd).max() < 0.01)
    assert main(["enable", "on", "--seconds", "0.6", "--socket", str(sock)]) == 0
    out = capsys.readouterr().out
    assert "enabling input held (lease 0.25 s, renewed)" in out and "enabling input off" in out
    _wait(lambda: not tick.enable_input.pressed)
    code = main(["enable", "off", "--seconds", "1", "--socket", str(sock)])
    one_line_error(code, capsys.readouterr().err, "--seconds: only with enable on")
