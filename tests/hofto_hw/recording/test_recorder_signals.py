"""A loop process with a flight recorder, ended by SIGTERM (complete file) and by SIGKILL of
the whole process group (truncated file, `log recover` salvages every flushed record)."""

from __future__ import annotations

import json
import signal
import time

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hofto_hw.cli import main as cli_main
from hofto_hw.recording.reader import clock_origin_ns
from hofto_hw.recording.schemas import (
    JOINT_STATE_TOPIC,
    SAFETY_TOPIC,
    TICK_STATUS_TOPIC,
    observer_topic,
)

N_TICKS = 3000


def decode_all(path, topic):
    """(sequences, decoded messages) on ``topic`` with the independent mcap_ros2 decoder."""
    seqs, msgs = [], []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _s, _c, message, msg in reader.iter_decoded_messages(topics=[topic]):
            seqs.append(message.sequence)
            msgs.append(msg)
    return np.array(seqs), msgs


def origin_of(path) -> int:
    """The log's wall-clock origin [ns]: the loop's t = 0 happened while this test ran."""
    with open(path, "rb") as f:
        origin = clock_origin_ns(make_reader(f))
    assert abs(origin - time.time_ns()) < 600 * 10**9
    return origin


def check_joint_states(seqs, msgs, n, origin):
    """Ticks 0..n-1 once each, with the values flight_child.py pushed, stamped from the
    wall clock of the run's start plus the loop's t."""
    order = np.argsort(seqs)
    assert np.array_equal(seqs[order], np.arange(n))
    for k in (0, n // 2, n - 1):
        msg = msgs[order[k]]
        assert msg.name == [f"joint_{j + 1}" for j in range(6)]
        assert np.allclose(msg.position, k * 1e-3 + np.arange(6))
        assert np.allclose(msg.velocity, 0.5) and np.allclose(msg.effort, -1.0)
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == origin + round(k * 1e6)


def test_sigterm_gives_a_complete_file_with_every_tick(tmp_path, child_factory):
    out = tmp_path / "run.mcap"
    child = child_factory(out, N_TICKS)
    child.expect("ready")
    child.expect("done")
    child.proc.send_signal(signal.SIGTERM)
    health = json.loads(child.expect("closed")[len("closed ") :])
    assert child.proc.wait() == 0
    assert health["dropped"] == 0 and health["write_errors"] == 0
    assert health["state"] == "finished"
    seqs, msgs = decode_all(out, JOINT_STATE_TOPIC)
    assert len(msgs) == N_TICKS
    check_joint_states(seqs, msgs, N_TICKS, origin_of(out))
    for name in ("hofto", "momentum", "eso"):
        seqs, msgs = decode_all(out, observer_topic(name))
        assert len(msgs) == N_TICKS and np.allclose(msgs[-1].effort, 0.25)
    seqs, status = decode_all(out, TICK_STATUS_TOPIC)
    assert sorted(seqs) == list(range(N_TICKS))
    assert all(m.faults == m.tick % 7 and m.wakeup_us == 1.5 for m in status)
    _, events = decode_all(out, SAFETY_TOPIC)
    assert [(e.tick, e.kind_name, e.joint, e.category) for e in events] == [
        (500, "collision", 2, 1)
    ]
    with open(out, "rb") as f:
        reader = make_reader(f)
        att = {a.name: a.data for a in reader.iter_attachments()}
    assert att["config.yaml"] == b"robot: {name: test}\n"
    assert set(att) == {"config.yaml", "parameters.yaml", "thresholds.yaml"}


def test_sigkill_then_recover_keeps_every_flushed_tick(tmp_path, child_factory, capsys):
    out = tmp_path / "run.mcap"
    child = child_factory(out, 0)
    child.expect("ready")
    flushed = 0
    while flushed < 2000:  # state: the writer has closed chunks holding >= 2000 records
        _, pushed, flushed, t = child.expect("pushed").split()
        flushed = int(flushed)
    child.kill_group()
    with pytest.raises(Exception):  # noqa: B017 - any reader error: no summary
        with open(out, "rb") as f:
            list(make_reader(f).iter_messages())
    fixed = tmp_path / "fixed.mcap"
    assert cli_main(["log", "recover", str(out), "-o", str(fixed)]) == 0
    assert "truncated" in capsys.readouterr().out
    seqs, msgs = decode_all(fixed, JOINT_STATE_TOPIC)
    # Records count ticks + events + diags; this child pushes one event and no diags.
    assert len(msgs) >= flushed - 1
    check_joint_states(seqs, msgs, len(msgs), origin_of(fixed))
    with open(fixed, "rb") as f:
        assert {a.name for a in make_reader(f).iter_attachments()} == {
            "config.yaml",
            "parameters.yaml",
            "thresholds.yaml",
        }


def test_sigkill_of_the_loop_alone_lets_the_writer_finish_the_file(tmp_path, child_factory):
    out = tmp_path / "run.mcap"
    child = child_factory(out, 0)
    writer_pid = int(child.expect("ready").split()[1])
    flushed = 0
    while flushed < 1000:
        flushed = int(child.expect("pushed").split()[2])
    child.proc.send_signal(signal.SIGKILL)  # the loop only: its writer sees the owner gone
    child.proc.wait()
    deadline = time.monotonic() + 120
    while pid_alive(writer_pid):
        assert time.monotonic() < deadline, "writer did not finish after its owner died"
        time.sleep(0.05)
    seqs, msgs = decode_all(out, JOINT_STATE_TOPIC)  # the indexed reader: file is complete
    assert len(msgs) >= flushed - 1
    check_joint_states(seqs, msgs, len(msgs), origin_of(out))


def pid_alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie waiting for its reaper counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False
