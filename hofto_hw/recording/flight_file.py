"""One flight-recorder MCAP file: channels, attachments, metadata, and batches of records
turned into ROS 2 messages. Runs in the writer process (never in the loop).

Topics (log time = publish time = the record's ``t`` in ns, sequence = tick mod 2³²):

- ``/joint_states`` sensor_msgs/JointState: position q [rad], velocity qd [rad/s], effort
  tau [N·m] (motor torque, joint side), one per tick;
- ``/joint_commands`` JointState: position = commanded q [rad];
- ``/observers/<name>/tau_ext`` JointState: effort = that observer's tau_ext_hat [N·m];
- ``/tool/wrench_estimate`` geometry_msgs/WrenchStamped [N, N·m] (ticks where it is computed);
- ``/loop/status`` hofto_hw_msgs/TickStatus: mode, latched fault bits, bus status, wake-up
  and compute time [µs], one per tick;
- ``/diagnostics`` diagnostic_msgs/DiagnosticArray (loop, bus, recorder health, 10 Hz);
- ``/safety/events`` hofto_hw_msgs/SafetyEvent (see schemas.py for why a custom message);
- when the log carries the URDF (attachment ``robot.urdf``): ``/robot_description``
  std_msgs/String (the URDF, once per file), ``/tf_static`` (fixed joints, once per file) and
  ``/tf`` tf2_msgs/TFMessage (each movable joint's link transform and the tool's aligned frame,
  from the logged q at ``tf_rate_hz``), computed here with pinocchio (:mod:`frames`);
- with the run's config attached and its two-level monitor: ``/safety/thresholds``
  hofto_hw_msgs/CollisionThresholds, the contact/collision thresholds [N·m] the monitor
  applied, re-computed from the records (hofto_hw.replay.levels_track), on judged ticks.

Times: log time = stamp = ``origin_ns`` + the record's t [ns]; the writer process sets
``origin_ns`` to the wall clock of the loop's t = 0 (metadata record ``hofto_hw.clock``), so a
sim-clock run is stamped from its real start time.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer
from mcap_ros2._dynamic import serialize_dynamic

from hofto_hw.recording import cdr
from hofto_hw.recording import schemas as s
from hofto_hw.recording.frames import ArmFrames, aligned_frame
from hofto_hw.recording.log_spec import CHUNK_BYTES as CHUNK_BYTES  # re-exported
from hofto_hw.recording.log_spec import LogSpec
from hofto_hw.recording.log_spec import rotated_path as rotated_path  # re-exported

_AUTO = object()  # FlightFile(frames=...) not given: built from the URDF attachment
#: tick-record fields copied into /loop/status
_STATUS_FIELDS = (
    "tick",
    "mode",
    "faults",
    "bus_status",
    "wakeup_us",
    "compute_us",
    "monitored",
    "qdd_cmd",
    "sample_dt",
)


class CountingFile:
    """Unbuffered new file (FileExistsError if it exists) that counts the bytes written
    (``written``, and a process-wide total for the ``fail_after_bytes`` fault hook). Data
    reaches the kernel at each write: a killed writer loses nothing it wrote."""

    total = 0

    def __init__(self, path: Path, fail_after: int | None = None) -> None:
        self._f = open(path, "xb", buffering=0)  # never overwrite a log
        self.written = 0
        self._fail_after = fail_after

    def write(self, data: bytes | bytearray | memoryview) -> int:
        n = len(data)
        if self._fail_after is not None and CountingFile.total + n > self._fail_after:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        view = memoryview(data)
        while view:
            k = self._f.write(view)
            view = view[k:]
        self.written += n
        CountingFile.total += n
        return n

    def tell(self) -> int:
        return self.written

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._f.close()


class FlightFile:
    """An open MCAP file of a flight-recorder log. Every write may raise OSError (disk
    full): the caller then abandons this file (:meth:`abandon`).

    ``origin_ns``: wall-clock ns of the loop's t = 0 (settable until the first write; 0 keeps
    the loop's t). ``frames``: the arm's frames for /tf (built from the URDF attachment when
    not given; None: no /tf). ``live``: a sink also offered the last message of each batch per topic
    (:class:`hofto_hw.recording.live.LiveView`), or None."""

    def __init__(
        self,
        spec: LogSpec,
        path: Path,
        index: int,
        *,
        origin_ns: int = 0,
        frames: Any = _AUTO,
        live: Any = None,
        thresholds: Any = None,
    ) -> None:
        self.path = path
        self.spec = spec
        self.messages = 0
        self.origin_ns = origin_ns
        self.live = live
        #: hofto_hw.replay.levels_track.ThresholdTrack of the run (state carried across files)
        self.track = thresholds
        self._begun = False
        self.urdf = urdf_text(spec)
        if frames is _AUTO:
            frames = None
            if self.urdf is not None:
                frames = ArmFrames(self.urdf, spec.joint_names, spec.tool_frame)
        self.frames: ArmFrames | None = frames
        self._tf_bucket = -1  # /tf decimation: the last tf_rate_hz period written
        self.file = CountingFile(path, spec.fail_after_bytes)
        comp = CompressionType.LZ4 if spec.compression == "lz4" else CompressionType.ZSTD
        self.w = Writer(self.file, chunk_size=spec.chunk_bytes, compression=comp)
        self.w.start(profile="ros2", library="hofto-hw flight recorder")
        self._channels(spec)
        meta = {
            "format": s.FLIGHT_FORMAT,
            "version": "1",
            "joint_names": ",".join(spec.joint_names),
            "observers": ",".join(spec.observers),
            "event_kinds": json.dumps({str(k): v for k, v in spec.event_kinds.items()}),
            "file_index": str(index),
        }
        if spec.tool_frame:
            meta["tool_frame"] = spec.tool_frame
        meta["wrench_frame"] = self.wrench_frame
        meta.update(spec.metadata)
        self.w.add_metadata(s.FLIGHT_METADATA, meta)
        for name, media_type, data in spec.attachments:
            self.w.add_attachment(0, 0, name, media_type, data)

    @property
    def wrench_frame(self) -> str:
        spec = self.spec
        if spec.wrench_frame or not spec.tool_frame:
            return spec.wrench_frame
        return aligned_frame(spec.tool_frame)

    def _channels(self, spec: LogSpec) -> None:
        names = spec.joint_names
        self.topics: dict[int, str] = {}

        def channel(topic: str, type_name: str, msgdef: str) -> int:
            sid = self.w.register_schema(type_name, "ros2msg", msgdef.encode())
            cid = self.w.register_channel(topic, "cdr", sid)
            self.topics[cid] = topic
            if self.live is not None:
                self.live.declare(topic, type_name, msgdef)
            return cid

        js = (s.JOINT_STATE_TYPE, s.JOINT_STATE_MSGDEF)
        self.ch_state = channel(s.JOINT_STATE_TOPIC, *js)
        self.ch_cmd = channel(s.COMMAND_TOPIC, *js)
        self.ch_obs = [channel(s.observer_topic(o), *js) for o in spec.observers]
        self.ch_wrench = channel(s.WRENCH_TOPIC, s.WRENCH_STAMPED_TYPE, s.WRENCH_STAMPED_MSGDEF)
        self.ch_diag = channel(
            s.DIAGNOSTICS_TOPIC, s.DIAGNOSTIC_ARRAY_TYPE, s.DIAGNOSTIC_ARRAY_MSGDEF
        )
        self.ch_event = channel(s.SAFETY_TOPIC, s.SAFETY_EVENT_TYPE, s.SAFETY_EVENT_MSGDEF)
        self.ch_status = channel(s.TICK_STATUS_TOPIC, s.TICK_STATUS_TYPE, s.TICK_STATUS_MSGDEF)
        if self.frames is not None:
            self.ch_urdf = channel(s.ROBOT_DESCRIPTION_TOPIC, s.STRING_TYPE, s.STRING_MSGDEF)
            tf = (s.TF_MESSAGE_TYPE, s.TF_MESSAGE_MSGDEF)
            self.ch_tf_static = channel(s.TF_STATIC_TOPIC, *tf)
            self.ch_tf = channel(s.TF_TOPIC, *tf)
            self.lay_tf = cdr.tf_message_layout(self.frames.moving_pairs)
        if self.track is not None:
            self.ch_thr = channel(
                s.THRESHOLDS_TOPIC, s.COLLISION_THRESHOLDS_TYPE, s.COLLISION_THRESHOLDS_MSGDEF
            )
            two = len(self.track.levels) == 2
            self.lay_thr = cdr.thresholds_layout(self.track.observer, len(names), two)
        self.lay_state = cdr.joint_state_layout(names, position=True, velocity=True, effort=True)
        self.lay_cmd = cdr.joint_state_layout(names, position=True, velocity=False, effort=False)
        self.lay_obs = cdr.joint_state_layout(names, position=False, velocity=False, effort=True)
        self.lay_wrench = cdr.wrench_stamped_layout(self.wrench_frame)
        self.lay_status = cdr.tick_status_layout(len(names))
        self.enc_diag = serialize_dynamic(s.DIAGNOSTIC_ARRAY_TYPE, s.DIAGNOSTIC_ARRAY_MSGDEF)[
            s.DIAGNOSTIC_ARRAY_TYPE
        ]
        self.enc_event = serialize_dynamic(s.SAFETY_EVENT_TYPE, s.SAFETY_EVENT_MSGDEF)[
            s.SAFETY_EVENT_TYPE
        ]
        self.enc_tf = serialize_dynamic(s.TF_MESSAGE_TYPE, s.TF_MESSAGE_MSGDEF)[s.TF_MESSAGE_TYPE]

    @property
    def bytes(self) -> int:
        return self.file.written

    # ------------------------------------------------------------------ records
    def _begin(self, ns: int) -> None:
        """Once per file, at the first record's time ``ns``: the clock origin, and the
        latched topics (the URDF, the fixed joints' transforms)."""
        self._begun = True
        self.w.add_metadata(s.CLOCK_METADATA, {"origin_ns": str(int(self.origin_ns))})
        if self.frames is None or self.urdf is None:
            return
        self._add(self.ch_urdf, ns, cdr.string_message(self.urdf), 0)
        msg = {
            "transforms": [
                {
                    "header": _header(ns, parent),
                    "child_frame_id": child,
                    "transform": {
                        "translation": dict(zip("xyz", xyz.tolist(), strict=True)),
                        "rotation": dict(zip("xyzw", quat.tolist(), strict=True)),
                    },
                }
                for parent, child, xyz, quat in self.frames.static()
            ]
        }
        self._add(self.ch_tf_static, ns, self.enc_tf(msg), 0)

    def _add(self, channel: int, ns: int, data: bytes, seq: int) -> None:
        self.w.add_message(channel, ns, data, ns, seq)
        self.messages += 1
        if self.live is not None:
            self.live.offer(self.topics[channel], data, ns)

    def _emit(self, channel: int, batch: np.ndarray, ns: np.ndarray, seq: np.ndarray) -> None:
        raw = batch.tobytes()
        size = batch.dtype.itemsize
        add = self.w.add_message
        for i, (t_ns, k) in enumerate(zip(ns.tolist(), seq.tolist(), strict=True)):
            add(channel, t_ns, raw[i * size : (i + 1) * size], t_ns, k)
        self.messages += len(batch)
        if self.live is not None and len(batch):
            self.live.offer(self.topics[channel], raw[-size:], int(ns[-1]))

    def write_ticks(self, ticks: np.ndarray) -> None:
        """Ticks (N,) of the tick dtype -> joint states, commands, observers, wrench, /tf."""
        n = len(ticks)
        if n == 0:
            return
        origin = self.origin_ns
        if not self._begun:
            self._begin(origin + round(float(ticks["t"][0]) * 1e9))
        seq = ticks["tick"] & 0xFFFFFFFF
        b = cdr.fill_batch(*self.lay_state, n)
        ns = cdr.set_stamps(b, ticks["t"], origin)
        b["position"], b["velocity"], b["effort"] = ticks["q"], ticks["qd"], ticks["tau"]
        self._emit(self.ch_state, b, ns, seq)
        b = cdr.fill_batch(*self.lay_cmd, n)
        cdr.set_stamps(b, ticks["t"], origin)
        b["position"] = ticks["q_cmd"]
        self._emit(self.ch_cmd, b, ns, seq)
        b = cdr.fill_batch(*self.lay_obs, n)
        cdr.set_stamps(b, ticks["t"], origin)
        for i, ch in enumerate(self.ch_obs):
            b["effort"] = ticks["tau_ext"][:, i]
            self._emit(ch, b, ns, seq)
        b = cdr.fill_batch(*self.lay_status, n)
        cdr.set_stamps(b, ticks["t"], origin)
        for name in _STATUS_FIELDS:
            b[name] = ticks[name]
        self._emit(self.ch_status, b, ns, seq)
        have = np.isfinite(ticks["wrench"]).all(axis=1)
        if have.any():
            w = ticks[have]
            b = cdr.fill_batch(*self.lay_wrench, len(w))
            cdr.set_stamps(b, w["t"], origin)
            b["force"], b["torque"] = w["wrench"][:, :3], w["wrench"][:, 3:]
            self._emit(self.ch_wrench, b, ns[have], seq[have])
        if self.frames is not None and self.spec.tf_rate_hz > 0:
            self._write_tf(ticks, ns, seq)
        if self.track is not None:
            self._write_thresholds(ticks, ns, seq)

    def _write_thresholds(self, ticks: np.ndarray, ns: np.ndarray, seq: np.ndarray) -> None:
        """/safety/thresholds on the ticks the monitor judged."""
        assert self.track is not None
        thr = self.track.update(ticks)
        judged = ticks["monitored"] != 0
        if not judged.any():
            return
        b = cdr.fill_batch(*self.lay_thr, int(judged.sum()))
        cdr.set_stamps(b, ticks["t"][judged], self.origin_ns)
        b["collision"] = thr[judged, -1]
        if len(self.track.levels) == 2:
            b["contact"] = thr[judged, 0]
        self._emit(self.ch_thr, b, ns[judged], seq[judged])

    def _write_tf(self, ticks: np.ndarray, ns: np.ndarray, seq: np.ndarray) -> None:
        """/tf for the first tick of each 1/tf_rate_hz period of the loop's t."""
        assert self.frames is not None
        bucket = np.floor(ticks["t"] * self.spec.tf_rate_hz).astype(np.int64)
        prev = np.concatenate([[self._tf_bucket], bucket[:-1]])
        keep = bucket != prev
        self._tf_bucket = int(bucket[-1])
        if not keep.any():
            return
        trans, quat = self.frames.moving(ticks["q"][keep])
        b = cdr.fill_batch(*self.lay_tf, len(trans))
        cdr.set_tf_stamps(b, len(self.frames.moving_pairs), ns[keep])
        for i in range(len(self.frames.moving_pairs)):
            b[f"translation{i}"] = trans[:, i]
            b[f"rotation{i}"] = quat[:, i]
        self._emit(self.ch_tf, b, ns[keep], seq[keep])

    def write_events(self, events: np.ndarray) -> None:
        """Safety events (N,) of EVENT_DTYPE."""
        for ev in events:
            ns = self.origin_ns + round(float(ev["t"]) * 1e9)
            if not self._begun:
                self._begin(ns)
            kind = int(ev["kind"])
            msg = {
                "header": _header(ns, ""),
                "tick": int(ev["tick"]),
                "kind": kind,
                "kind_name": self.spec.event_kinds.get(kind, f"kind_{kind}"),
                "joint": int(ev["joint"]),
                "category": int(ev["category"]),
                "value": float(ev["value"]),
            }
            self._add(self.ch_event, ns, self.enc_event(msg), int(ev["tick"]) & 0xFFFFFFFF)

    def write_diags(
        self, diags: np.ndarray, recorder: dict[str, int], timing: dict[str, float] | None = None
    ) -> None:
        """Diagnostics (N,) of DIAG_DTYPE plus the writer's own counters ``recorder`` and the
        loop's timing the writer measured from the ticks (``timing``, see diag_message)."""
        for d in diags:
            ns = self.origin_ns + round(float(d["t"]) * 1e9)
            if not self._begun:
                self._begin(ns)
            self._add(self.ch_diag, ns, self.enc_diag(diag_message(d, recorder, timing, ns)), 0)

    def flush(self) -> None:
        """Close the chunk in progress (bounds what a SIGKILL loses)."""
        self.w.flush()

    def finish(self) -> None:
        """Write the summary and close: the file is complete."""
        self.w.finish()
        self.file.close()

    def abandon(self) -> None:
        """Close without a summary (after a write error); `log recover` can salvage it."""
        try:
            self.file.close()
        except OSError:
            pass


def urdf_text(spec: LogSpec) -> str | None:
    """The URDF attachment of ``spec`` as text, or None."""
    from hofto_hw.recording.attachments import URDF

    for name, _media, data in spec.attachments:
        if name == URDF:
            return data.decode()
    return None


def _header(ns: int, frame_id: str) -> dict[str, Any]:
    return {
        "stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000},
        "frame_id": frame_id,
    }


def _kv(values: dict[str, Any]) -> list[dict[str, str]]:
    return [{"key": k, "value": str(v)} for k, v in values.items()]


def diag_message(
    d: np.ndarray,
    recorder: dict[str, int],
    timing: dict[str, float] | None = None,
    ns: int | None = None,
) -> dict[str, Any]:
    """A DiagnosticArray dict: loop, bus and recorder status from one diag record, stamped
    ``ns`` (default: the record's t). ``timing`` (``wakeup_p99_us``, ``compute_p99_us``):
    the loop's timing over the ticks logged so far, which the writer measures from the tick
    records whether or not systemd supervises the run; the record's own values otherwise."""
    ns = round(float(d["t"]) * 1e9) if ns is None else ns
    loop = {k: d[k].item() for k in ("ticks", "overruns", "wakeup_p99_us", "compute_p99_us")}
    if timing:
        loop.update(timing)
    bus_errors = int(d["bus_errors"])
    rec = dict(recorder, dropped_records=int(d["dropped_records"]))
    rec_level = 2 if recorder.get("failing") else (1 if rec["dropped_records"] else 0)
    status = [
        _status(1 if loop["overruns"] else 0, "hofto_hw: loop", "overruns", loop),
        _status(1 if bus_errors else 0, "hofto_hw: bus", "errors", {"bus_errors": bus_errors}),
        _status(rec_level, "hofto_hw: recorder", "failing" if rec_level == 2 else "", rec),
    ]
    return {"header": _header(ns, ""), "status": status}


def _status(level: int, name: str, bad: str, values: dict[str, Any]) -> dict[str, Any]:
    return {
        "level": level,
        "name": name,
        "message": bad if level else "ok",
        "hardware_id": "",
        "values": _kv(values),
    }
