"""FlightRecorder with its writer process: rotation, full disk, dead writer, flush policy."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader

from hofto_hw.errors import UserError
from hofto_hw.recording import shared as sh
from hofto_hw.recording.flight_file import LogSpec, rotated_path
from hofto_hw.recording.record import new_record, tick_dtype
from hofto_hw.recording.recorder import FlightRecorder
from hofto_hw.recording.schemas import JOINT_STATE_TOPIC
from hofto_hw.recording.writer_process import _Writer

STATE_TIMEOUT = 120.0
JOINTS = ["j1", "j2", "j3"]


def spec(path: Path, **kw) -> LogSpec:
    return LogSpec(path, JOINTS, ["momentum"], **kw)


def wait_for(pred, what: str) -> None:
    """Poll ``pred`` until true (a state, not a time goal)."""
    deadline = time.monotonic() + STATE_TIMEOUT
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"never reached: {what}")
        time.sleep(0.01)


def pusher(rec: FlightRecorder):
    tick = new_record(rec.tick_dtype)
    k = [0]

    def push(n: int) -> None:
        for _ in range(n):
            tick["t"], tick["tick"] = k[0] * 1e-3, k[0]
            tick["q"][:] = k[0]
            rec.push_tick(tick)
            k[0] += 1

    return push, k


def joint_state_ticks(path: Path) -> list[int]:
    with path.open("rb") as f:
        return [m.sequence for _s, _c, m in make_reader(f).iter_messages([JOINT_STATE_TOPIC])]


def test_rotates_by_size_into_complete_files_that_together_hold_every_tick(tmp_path):
    old = tmp_path / "run.1.mcap"  # a file of an earlier run: skipped, never overwritten
    old.write_bytes(b"earlier run")
    rec = FlightRecorder(spec(tmp_path / "run.mcap", rotate_bytes=100_000)).start()
    push, k = pusher(rec)
    while rec.health().files < 3:
        push(100)
        wait_for(lambda: rec.health().pending == 0, "ring drained")
    assert rec.health().current_file == rotated_path(tmp_path / "run.mcap", rec.health().files)
    health = rec.close()
    assert health.dropped == 0 and health.write_errors == 0
    assert old.read_bytes() == b"earlier run"
    files = [tmp_path / "run.mcap"] + [
        rotated_path(tmp_path / "run.mcap", i) for i in range(2, health.files + 1)
    ]
    assert all(p.is_file() for p in files)
    assert files[1].name == "run.2.mcap"
    ticks = [t for p in files for t in joint_state_ticks(p)]  # each opens with the indexed reader
    assert sorted(ticks) == list(range(k[0]))
    assert all(p.stat().st_size < 100_000 + 200_000 for p in files[:-1])


def test_full_disk_is_counted_and_reported_and_the_producer_goes_on(tmp_path):
    rec = FlightRecorder(spec(tmp_path / "run.mcap", fail_after_bytes=150_000)).start()
    push, k = pusher(rec)
    while rec.health().write_errors == 0:
        push(100)
        wait_for(lambda: rec.health().pending == 0, "ring drained")
    h = rec.health()
    assert h.disk_failing and h.state == "failed" and h.writer_alive and not h.ok
    before = k[0]
    push(500)  # the loop keeps pushing; the writer keeps draining and counts the loss
    wait_for(lambda: rec.health().records_lost >= 500, "records counted as lost")
    assert k[0] == before + 500 and rec.dropped == 0
    final = rec.close()
    assert final.write_errors >= 1 and final.records_lost >= 500
    assert final.records_written + final.records_lost == k[0]


def test_a_dead_writer_is_reported_and_a_full_ring_drops_without_blocking(tmp_path):
    rec = FlightRecorder(spec(tmp_path / "run.mcap"), sh.Capacities(tick=64)).start()
    push, k = pusher(rec)
    os.kill(rec.writer_pid, signal.SIGKILL)
    wait_for(lambda: not rec.health().writer_alive, "writer seen dead")
    push(200)
    assert rec.dropped >= 200 - 64
    h = rec.health()
    assert not h.ok and h.dropped == rec.dropped
    rec.close()


def test_a_chunk_is_on_disk_within_flush_seconds_of_its_drain(tmp_path):
    """The SIGKILL bound without a process or a clock: step() takes the time as an argument."""
    dtype = tick_dtype(3, 1)
    block = sh.SharedBlock(dtype, sh.Capacities(), create=True)
    path = tmp_path / "run.mcap"
    try:
        w = _Writer(block, spec(path, flush_seconds=0.25))
        rec = new_record(dtype)
        for k in range(20):
            rec["t"], rec["tick"] = k * 1e-3, k
            block.ticks.push(rec)
        w.step(100.0)  # opens the file at t = 100 s and drains 20 ticks
        w.step(100.1)
        assert on_disk(path) == 0  # still in the open chunk
        w.step(100.26)
        assert on_disk(path) == 20  # flushed by the policy, readable without a summary
        assert int(block.control[sh.FLUSHED]) == 20
        w.finish()
    finally:
        block.close()


def on_disk(path: Path) -> int:
    """JointState messages a stream reader finds in what is on disk now."""
    n = 0
    with path.open("rb") as f:
        try:
            for r in StreamReader(f).records:
                n += isinstance(r, Message) and r.channel_id == 1
        except Exception:
            pass
    return n


def test_ticks_are_written_with_tick_as_sequence(tmp_path):
    rec = FlightRecorder(spec(tmp_path / "run.mcap")).start()
    push, _ = pusher(rec)
    push(10)
    rec.close()
    assert joint_state_ticks(tmp_path / "run.mcap") == list(range(10))
    assert np.dtype(rec.tick_dtype) == tick_dtype(3, 1)


def test_a_real_file_size_limit_is_a_counted_write_error(tmp_path):
    """RLIMIT_FSIZE (inherited by the writer): the kernel refuses the write with EFBIG."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    small = sh.Capacities(tick=64, event=16, diag=16)  # the segment is under the limit too
    resource.setrlimit(resource.RLIMIT_FSIZE, (120_000, hard))
    try:
        rec = FlightRecorder(spec(tmp_path / "run.mcap", retry_seconds=3600.0), small).start()
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    push, k = pusher(rec)
    while rec.health().write_errors == 0:
        push(50)
        wait_for(lambda: rec.health().pending == 0, "ring drained")
    h = rec.health()
    assert h.writer_alive and h.disk_failing and rec.dropped == 0
    assert (tmp_path / "run.mcap").stat().st_size <= 120_000
    final = rec.close()
    assert final.records_written + final.records_lost == k[0]


def test_an_existing_log_is_never_overwritten(tmp_path):
    path = tmp_path / "run.mcap"
    path.write_bytes(b"earlier run")
    with pytest.raises(UserError, match="never overwritten"):
        FlightRecorder(spec(path)).start()
    assert path.read_bytes() == b"earlier run"


def test_the_writer_leaves_the_pinned_loops_cpu(tmp_path):
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        pytest.skip("one CPU: nowhere else to put the writer")
    os.sched_setaffinity(0, {cpus[-1]})  # the loop pins itself before starting the recorder
    try:
        rec = FlightRecorder(spec(tmp_path / "run.mcap")).start()
    finally:
        os.sched_setaffinity(0, set(cpus))
    try:
        assert rec.health().state == "running"  # affinity is set before the writer runs
        assert cpus[-1] not in os.sched_getaffinity(rec.writer_pid)
    finally:
        rec.close()


def test_a_writer_that_cannot_start_leaves_no_segment(tmp_path: Path, monkeypatch) -> None:
    """The writer process fails to start (an interpreter the user may not execute, as a
    service user met): the error reaches the caller and the ring's segment is unlinked."""
    import hofto_hw.recording.recorder as recorder_module
    from hofto_hw.recording import shared

    made: list[shared.SharedBlock] = []
    real_block = shared.SharedBlock

    def block(*args, **kw):
        made.append(real_block(*args, **kw))
        return made[-1]

    def no_exec(*args, **kw):
        raise PermissionError(13, "Permission denied", args[0][0])

    monkeypatch.setattr(recorder_module.sh, "SharedBlock", block)
    monkeypatch.setattr(recorder_module.subprocess, "Popen", no_exec)
    rec = FlightRecorder(spec(tmp_path / "run.mcap"))
    with pytest.raises(PermissionError):
        rec.start()
    assert len(made) == 1
    assert not Path("/dev/shm", made[0].name.lstrip("/")).exists()
