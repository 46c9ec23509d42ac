"""The flight log of the real `hofto-hw run` process: SIGTERM during a real-clock run leaves a
complete file holding every tick; SIGKILL of the process group leaves a file the normal
reader refuses and `hofto-hw log recover` restores to within 1 s of the last tick."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hofto_hw.cli import main
from hofto_hw.recording.schemas import JOINT_STATE_TOPIC
from hofto_hw.runtime.control_client import request
from tests.hofto_hw.runtime.conftest import CONFIG

ROOT = Path(__file__).resolve().parents[3]


def _start(tmp: Path, *extra: str) -> tuple[subprocess.Popen, Path]:
    sock = tmp / "ctl.sock"
    cmd = [sys.executable, "-m", "hofto_hw.cli", "run", "--config", str(CONFIG)]
    cmd += ["--clock", "real", "--duration", "120", "--no-collision"]
    cmd += ["--log-dir", str(tmp / "logs"), "--socket", str(sock), *extra]
    proc = subprocess.Popen(
        cmd,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: the writer is in it too
    )
    assert proc.stderr is not None
    for line in proc.stderr:  # wait for the state, not for a time
        if line.startswith("hofto-hw run: running"):
            break
    else:
        raise AssertionError(f"hofto-hw run did not start: {proc.communicate()}")
    return proc, sock


def _status_when(sock: Path, cond, limit: float = 60.0) -> dict:
    """Poll the control socket until ``cond(status)`` (a state); fail after ``limit`` s."""
    end = time.monotonic() + limit
    while True:
        s = request(sock, "status")
        if cond(s) or time.monotonic() > end:
            assert cond(s), s
            return s
        time.sleep(0.05)


def _flushed(s: dict) -> bool:
    rec = s.get("recorder") or {}
    return s["ticks"] >= 1500 and rec.get("records_flushed", 0) > 0


def _joint_state_stamps(path: Path) -> np.ndarray:
    """Stamps [s] of every /joint_states message, decoded by mcap_ros2's own decoder."""
    out = []
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _s, _c, _m, msg in reader.iter_decoded_messages(topics=[JOINT_STATE_TOPIC]):
            assert len(msg.position) == len(msg.velocity) == len(msg.effort) == 6
            out.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
    return np.array(out)


def test_sigterm_gives_a_complete_log_with_every_tick(tmp_path: Path) -> None:
    summary = tmp_path / "summary.json"
    proc, sock = _start(tmp_path, "--summary-json", str(summary))
    try:
        _status_when(sock, _flushed)
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    assert "records dropped" not in stderr
    s = json.loads(summary.read_text())
    stamps = _joint_state_stamps(Path(s["log"]))
    assert len(stamps) == s["ticks"] > 1500
    assert np.all(np.diff(stamps) > 0)


def test_sigkill_log_is_recovered_to_within_a_second(tmp_path: Path, capsys) -> None:
    proc, sock = _start(tmp_path)
    try:
        s = _status_when(sock, _flushed)
        s = request(sock, "status")  # the last state before the kill
        maps = Path(f"/proc/{proc.pid}/maps").read_text()
        rings = {
            ln.rsplit("/dev/shm/", 1)[1].split()[0] for ln in maps.splitlines() if "/dev/shm/" in ln
        }
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        proc.kill()
    for name in rings:  # what the unit's RemoveIPC=yes does after such a kill
        Path("/dev/shm", name).unlink(missing_ok=True)
    (log,) = (tmp_path / "logs").glob("*.mcap")
    try:
        complete = len(_joint_state_stamps(log)) == s["ticks"]
    except Exception:
        complete = False
    assert not complete  # the normal reader fails, or the file lacks the last ticks
    out = tmp_path / "recovered.mcap"
    assert main(["log", "recover", str(log), "-o", str(out)]) == 0
    stamps = _joint_state_stamps(out)
    rate = 1000.0
    t_last_written = s["ticks"] / rate  # loop time of the last tick before the status answer
    assert len(stamps) > 0 and t_last_written - stamps[-1] < 1.0, (t_last_written, stamps[-1])
    print(f"recovered {len(stamps)} ticks, last t {stamps[-1]:.3f} s, status t {t_last_written}")
