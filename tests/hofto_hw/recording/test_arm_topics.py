"""What lets Foxglove draw the arm: /robot_description, /tf_static, /tf from the logged q,
frame ids, wall-clock stamps, and /diagnostics timing measured by the writer."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hofto_hw.config import load_config
from hofto_hw.recording import schemas as s
from hofto_hw.recording.attachments import run_attachments
from hofto_hw.recording.flight_file import FlightFile, LogSpec
from hofto_hw.recording.record import DIAG_DTYPE, new_record, tick_dtype
from hofto_hw.recording.recorder import FlightRecorder
from hofto_hw.replay.flight_log import read_flight_log

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"
RATE = 1000
N = 1000  # 1 s of ticks


@pytest.fixture(scope="module")
def cfg():
    return load_config(CONFIG)


def joint_path(k: np.ndarray) -> np.ndarray:
    """q (len(k), 6) [rad]: every joint moving."""
    t = k[:, None] * 1e-3
    return 0.3 * np.sin(2.0 * np.pi * 0.7 * t + np.arange(6)) + np.array([0, 0.3, 0.9, 0, 0.6, 0])


def ticks_of(n: int) -> np.ndarray:
    ticks = np.zeros(n, dtype=tick_dtype(6, 1))
    k = np.arange(n)
    ticks["t"], ticks["tick"] = k / RATE, k
    ticks["q"] = joint_path(k)
    ticks["wrench"] = np.nan
    ticks["wrench"][n // 2 :] = [1.0, 2.0, 3.0, 0.1, 0.2, 0.3]
    return ticks


def decoded(path: Path, topic: str) -> list:
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(m, msg) for _s, _c, m, msg in reader.iter_decoded_messages(topics=[topic])]


@pytest.fixture(scope="module")
def log(cfg, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("arm") / "arm.mcap"
    spec = LogSpec(
        path,
        list(cfg.robot.joints),
        ["momentum"],
        attachments=run_attachments(CONFIG, cfg),
        tool_frame=cfg.robot.tool_frame,
    )
    f = FlightFile(spec, path, 0, origin_ns=1_795_000_000_123_456_789)
    for part in np.array_split(ticks_of(N), 7):  # batches as the writer drains them
        f.write_ticks(part)
    f.finish()
    return path


def test_robot_description_and_fixed_frames_are_latched_at_the_start(log, cfg) -> None:
    (m, urdf), = decoded(log, s.ROBOT_DESCRIPTION_TOPIC)  # fmt: skip
    assert urdf.data == cfg.robot.urdf.read_text()
    assert m.log_time == 1_795_000_000_123_456_789  # the first tick's time
    (_, static), = decoded(log, s.TF_STATIC_TOPIC)  # fmt: skip
    (tf,) = static.transforms
    assert (tf.header.frame_id, tf.child_frame_id) == ("link_6", "tool0")


def test_tf_is_bounded_and_chains_to_pinocchio_s_tool_pose(log, cfg) -> None:
    msgs = decoded(log, s.TF_TOPIC)
    assert len(msgs) == 50  # 50 Hz over 1 s of 1 kHz ticks, whatever the batches
    model = pin.buildModelFromUrdf(str(cfg.robot.urdf))
    data = model.createData()
    tool = model.getFrameId("tool0")
    (_, static), = decoded(log, s.TF_STATIC_TOPIC)  # fmt: skip
    flange = _se3(static.transforms[0].transform)
    for m, msg in msgs[::7]:
        k = m.sequence
        chain = {(t.header.frame_id, t.child_frame_id): t for t in msg.transforms}
        assert all(t.header.stamp.sec * 10**9 + t.header.stamp.nanosec == m.log_time
                   for t in msg.transforms)  # fmt: skip
        pose = pin.SE3.Identity()
        for j in range(1, 7):
            parent = "base_link" if j == 1 else f"link_{j - 1}"
            pose = pose * _se3(chain[(parent, f"link_{j}")].transform)
        pose = pose * flange
        q = joint_path(np.array([k]))[0]
        pin.framesForwardKinematics(model, data, q)
        assert np.allclose(pose.homogeneous, data.oMf[tool].homogeneous, atol=1e-9)
        aligned = chain[("base_link", "tool0_aligned")].transform
        assert np.allclose(_se3(aligned).translation, data.oMf[tool].translation, atol=1e-9)
        assert np.allclose(_se3(aligned).rotation, np.eye(3))


def test_wrench_carries_its_frame_and_stamps_are_wall_clock(log) -> None:
    msgs = decoded(log, s.WRENCH_TOPIC)
    assert len(msgs) == N - N // 2
    assert {msg.header.frame_id for _m, msg in msgs} == {"tool0_aligned"}
    m, msg = msgs[0]
    assert m.log_time == 1_795_000_000_123_456_789 + (N // 2) * 1_000_000
    assert msg.header.stamp.sec == 1_795_000_000


def test_replay_reads_the_loop_s_time_back_exactly(log) -> None:
    flight = read_flight_log(log)
    assert np.array_equal(flight.t, (np.arange(N) * 1_000_000) * 1e-9)
    assert flight.metadata["wrench_frame"] == "tool0_aligned"


def test_the_writer_stamps_from_the_wall_clock_and_fills_diagnostics_timing(tmp_path) -> None:
    """A recorder run (the writer process): origin near now, and /diagnostics carries the
    p99 of the ticks' compute/wake-up times although nobody set them in the diag record."""
    spec = LogSpec(tmp_path / "run.mcap", ["j1", "j2"], ["momentum"])
    before = time.time_ns()
    rec = FlightRecorder(spec).start()
    tick, diag = new_record(rec.tick_dtype), new_record(DIAG_DTYPE)
    for k in range(1000):
        tick["t"], tick["tick"] = k * 1e-3, k
        tick["compute_us"], tick["wakeup_us"] = k % 100, 2 * (k % 100)
        while not rec.push_tick(tick):
            time.sleep(0.001)
    diag["t"], diag["ticks"] = 1.0, 1000
    rec.push_diag(diag)
    health = rec.close()
    after = time.time_ns()
    assert health.records_written == 1001
    (m, msg), = decoded(spec.path, s.DIAGNOSTICS_TOPIC)  # fmt: skip
    assert before <= m.log_time - 1_000_000_000 <= after
    loop = {kv.key: float(kv.value) for kv in msg.status[0].values}
    assert loop["compute_p99_us"] == 99.0  # the 99 µs bin, capped at the max
    assert loop["wakeup_p99_us"] == 197.0  # 99 % of the ticks are at most 196 µs


def _se3(tf) -> pin.SE3:
    r = tf.rotation
    quat = pin.Quaternion(r.w, r.x, r.y, r.z)
    return pin.SE3(quat.matrix(), np.array([tf.translation.x, tf.translation.y, tf.translation.z]))


def test_a_log_from_before_the_wall_clock_still_reads(log, tmp_path) -> None:
    """An older log: stamps from the loop's t, no clock metadata, no /tf topics."""
    from mcap.writer import Writer

    old = tmp_path / "old.mcap"
    drop = {s.TF_TOPIC, s.TF_STATIC_TOPIC, s.ROBOT_DESCRIPTION_TOPIC}
    with log.open("rb") as f, old.open("wb") as out:
        reader = make_reader(f)
        w = Writer(out)
        w.start(profile="ros2")
        ids: dict[int, int] = {}
        origin = 0
        for meta in reader.iter_metadata():
            if meta.name == s.CLOCK_METADATA:
                origin = int(meta.metadata["origin_ns"])
            else:
                w.add_metadata(meta.name, meta.metadata)
        for a in reader.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for schema, channel, m in reader.iter_messages(log_time_order=True):
            if channel.topic in drop:
                continue
            if channel.id not in ids:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = w.register_channel(channel.topic, "cdr", sid)
            t = m.log_time - origin
            w.add_message(ids[channel.id], t, m.data, t, m.sequence)
        w.finish()
    flight = read_flight_log(old)
    assert np.array_equal(flight.t, read_flight_log(log).t)
    assert np.array_equal(flight.q, read_flight_log(log).q)
