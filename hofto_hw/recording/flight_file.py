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
- ``/safety/events`` hofto_hw_msgs/SafetyEvent (see schemas.py for why a custom message).
"""

from __future__ import annotations

import errno
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer
from mcap_ros2._dynamic import serialize_dynamic

from hofto_hw.recording import cdr
from hofto_hw.recording import schemas as s

CHUNK_BYTES = 64 * 1024
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


@dataclass
class LogSpec:
    """What the writer process needs to know (picklable; sent once at start).

    ``joint_names`` (n,), ``observers`` the tau_ext rows' names in order, ``attachments``
    (name, media type, bytes) e.g. the config, parameters and thresholds files,
    ``metadata`` extra strings, ``event_kinds`` event code -> name (the safety fault classes).
    Rotation starts a new file after ``rotate_bytes`` or ``rotate_seconds`` (0 = never).
    ``flush_seconds`` bounds what a SIGKILL can lose (a chunk is closed at least that often).
    ``fail_after_bytes`` is a fault hook for tests: writes raise ENOSPC past that total.
    """

    path: Path
    joint_names: list[str]
    observers: list[str]
    attachments: list[tuple[str, str, bytes]] = field(default_factory=list)
    metadata: dict[str, str] = field(default_factory=dict)
    event_kinds: dict[int, str] = field(default_factory=dict)
    wrench_frame: str = ""
    compression: str = "zstd"
    chunk_bytes: int = CHUNK_BYTES
    rotate_bytes: int = 0
    rotate_seconds: float = 0.0
    flush_seconds: float = 0.25
    retry_seconds: float = 2.0
    fail_after_bytes: int | None = None


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


def rotated_path(path: Path, index: int) -> Path:
    """File ``index`` of a rotated log: the path itself, then ``<stem>.1<suffix>``, ..."""
    return path if index == 0 else path.with_name(f"{path.stem}.{index}{path.suffix}")


class FlightFile:
    """An open MCAP file of a flight-recorder log. Every write may raise OSError (disk
    full): the caller then abandons this file (:meth:`abandon`)."""

    def __init__(self, spec: LogSpec, path: Path, index: int) -> None:
        self.path = path
        self.spec = spec
        self.messages = 0
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
        meta.update(spec.metadata)
        self.w.add_metadata(s.FLIGHT_METADATA, meta)
        for name, media_type, data in spec.attachments:
            self.w.add_attachment(0, 0, name, media_type, data)

    def _channels(self, spec: LogSpec) -> None:
        names = spec.joint_names

        def channel(topic: str, type_name: str, msgdef: str) -> int:
            sid = self.w.register_schema(type_name, "ros2msg", msgdef.encode())
            return self.w.register_channel(topic, "cdr", sid)

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
        self.lay_state = cdr.joint_state_layout(names, position=True, velocity=True, effort=True)
        self.lay_cmd = cdr.joint_state_layout(names, position=True, velocity=False, effort=False)
        self.lay_obs = cdr.joint_state_layout(names, position=False, velocity=False, effort=True)
        self.lay_wrench = cdr.wrench_stamped_layout(spec.wrench_frame)
        self.lay_status = cdr.tick_status_layout(len(names))
        self.enc_diag = serialize_dynamic(s.DIAGNOSTIC_ARRAY_TYPE, s.DIAGNOSTIC_ARRAY_MSGDEF)[
            s.DIAGNOSTIC_ARRAY_TYPE
        ]
        self.enc_event = serialize_dynamic(s.SAFETY_EVENT_TYPE, s.SAFETY_EVENT_MSGDEF)[
            s.SAFETY_EVENT_TYPE
        ]

    @property
    def bytes(self) -> int:
        return self.file.written

    # ------------------------------------------------------------------ records
    def _emit(self, channel: int, batch: np.ndarray, ns: np.ndarray, seq: np.ndarray) -> None:
        raw = batch.tobytes()
        size = batch.dtype.itemsize
        add = self.w.add_message
        for i, (t_ns, k) in enumerate(zip(ns.tolist(), seq.tolist(), strict=True)):
            add(channel, t_ns, raw[i * size : (i + 1) * size], t_ns, k)
        self.messages += len(batch)

    def write_ticks(self, ticks: np.ndarray) -> None:
        """Ticks (N,) of the tick dtype -> joint states, commands, observers, wrench."""
        n = len(ticks)
        seq = ticks["tick"] & 0xFFFFFFFF
        b = cdr.fill_batch(*self.lay_state, n)
        ns = cdr.set_stamps(b, ticks["t"])
        b["position"], b["velocity"], b["effort"] = ticks["q"], ticks["qd"], ticks["tau"]
        self._emit(self.ch_state, b, ns, seq)
        b = cdr.fill_batch(*self.lay_cmd, n)
        cdr.set_stamps(b, ticks["t"])
        b["position"] = ticks["q_cmd"]
        self._emit(self.ch_cmd, b, ns, seq)
        b = cdr.fill_batch(*self.lay_obs, n)
        cdr.set_stamps(b, ticks["t"])
        for i, ch in enumerate(self.ch_obs):
            b["effort"] = ticks["tau_ext"][:, i]
            self._emit(ch, b, ns, seq)
        b = cdr.fill_batch(*self.lay_status, n)
        cdr.set_stamps(b, ticks["t"])
        for name in _STATUS_FIELDS:
            b[name] = ticks[name]
        self._emit(self.ch_status, b, ns, seq)
        have = np.isfinite(ticks["wrench"]).all(axis=1)
        if have.any():
            w = ticks[have]
            b = cdr.fill_batch(*self.lay_wrench, len(w))
            cdr.set_stamps(b, w["t"])
            b["force"], b["torque"] = w["wrench"][:, :3], w["wrench"][:, 3:]
            self._emit(self.ch_wrench, b, ns[have], seq[have])

    def write_events(self, events: np.ndarray) -> None:
        """Safety events (N,) of EVENT_DTYPE."""
        for ev in events:
            ns = round(float(ev["t"]) * 1e9)
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
            self.w.add_message(
                self.ch_event, ns, self.enc_event(msg), ns, int(ev["tick"]) & 0xFFFFFFFF
            )
            self.messages += 1

    def write_diags(self, diags: np.ndarray, recorder: dict[str, int]) -> None:
        """Diagnostics (N,) of DIAG_DTYPE plus the writer's own counters ``recorder``."""
        for d in diags:
            ns = round(float(d["t"]) * 1e9)
            self.w.add_message(self.ch_diag, ns, self.enc_diag(diag_message(d, recorder)), ns, 0)
            self.messages += 1

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


def _header(ns: int, frame_id: str) -> dict[str, Any]:
    return {
        "stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000},
        "frame_id": frame_id,
    }


def _kv(values: dict[str, Any]) -> list[dict[str, str]]:
    return [{"key": k, "value": str(v)} for k, v in values.items()]


def diag_message(d: np.ndarray, recorder: dict[str, int]) -> dict[str, Any]:
    """A DiagnosticArray dict: loop, bus and recorder status from one diag record."""
    ns = round(float(d["t"]) * 1e9)
    loop = {k: d[k].item() for k in ("ticks", "overruns", "wakeup_p99_us", "compute_p99_us")}
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
