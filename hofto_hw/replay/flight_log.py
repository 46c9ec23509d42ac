"""Read a flight-recorder MCAP log (hofto_hw.recording) back into arrays for replay.

JointState topics are decoded through the fixed CDR layout the writer used (one numpy view
over all messages; a message of another size falls back to mcap_ros2's decoder), the safety
events with mcap_ros2's decoder. Ticks come from the messages' sequence numbers (tick mod
2³², unwrapped here). Times are the loop's t [s]: the stamps less the log's clock origin
(``hofto_hw.clock`` metadata; logs without it were stamped with t alone).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from numpy.typing import NDArray

from hofto_hw.errors import UserError
from hofto_hw.recording import cdr
from hofto_hw.recording import schemas as s
from hofto_hw.recording.reader import clock_origin_ns
from hofto_hw.recording.recover import check_magic

FloatArray = NDArray[np.float64]


@dataclass
class RecordedEvent:
    """A safety event as logged: ``tick``, ``t`` [s], ``kind`` code and name, ``joint``
    (0-based, -1 none), stop ``category`` (-1 none), ``value``."""

    tick: int
    t: float
    kind: int
    kind_name: str
    joint: int
    category: int
    value: float


@dataclass
class FlightLog:
    """A flight log: ``t`` (N,) [s], ``ticks`` (N,), ``q``/``qd``/``tau`` (N, n) from
    /joint_states, ``tau_ext`` observer name -> (N, n) [N·m], ``events``, ``metadata``,
    ``attachments`` name -> bytes."""

    path: Path
    t: FloatArray
    ticks: NDArray[np.int64]
    q: FloatArray
    qd: FloatArray
    tau: FloatArray
    joint_names: list[str]
    observers: list[str]
    tau_ext: dict[str, FloatArray] = field(default_factory=dict)
    events: list[RecordedEvent] = field(default_factory=list)
    metadata: dict[str, str] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    #: from /loop/status of logs by `hofto-hw run` (None in older logs): 1 where the
    #: collision monitor judged the tick, and the commanded acceleration (N, n) [rad/s²]
    monitored: NDArray[np.uint8] | None = None
    qdd_cmd: FloatArray | None = None
    #: (N,) [s] the interval the loop's observers integrated in each tick (the bus's sample
    #: interval with EtherCAT DC; 0 where they held over a lost sample); None in older logs
    sample_dt: FloatArray | None = None
    #: (N,) from /loop/status (None in older logs): controller mode code
    #: (hofto_hw.control.joint_motion), wake-up and compute time of the tick [µs]
    mode: NDArray[np.uint8] | None = None
    wakeup_us: FloatArray | None = None
    compute_us: FloatArray | None = None

    @property
    def n_ticks(self) -> int:
        return int(self.t.shape[0])


def flight_metadata(path: Path) -> dict[str, str] | None:
    """The flight-recorder metadata of ``path``, or None for any other MCAP/CSV file."""
    if path.suffix.lower() != ".mcap":
        return None
    check_magic(path)
    try:
        with path.open("rb") as f:
            for m in make_reader(f).iter_metadata():
                if m.name == s.FLIGHT_METADATA and m.metadata.get("format") == s.FLIGHT_FORMAT:
                    return dict(m.metadata)
    except Exception as exc:
        raise UserError(
            f"{path}: not a readable MCAP log ({type(exc).__name__}); if it was cut "
            f"short, run `hofto-hw log recover {path}`"
        ) from None
    return None


def _unwrap(seq: NDArray[np.int64]) -> NDArray[np.int64]:
    """Undo the 32-bit wrap of MCAP sequence numbers (ticks only increase)."""
    wraps = np.concatenate([[0], np.cumsum(np.diff(seq) < 0)])
    return seq + (wraps << 32)


def _joint_states(
    raws: list[bytes], names: list[str], path: Path, topic: str, *, full: bool
) -> np.ndarray:
    """Messages of one JointState topic as a structured array of the writer's layout."""
    dtype, _ = cdr.joint_state_layout(names, position=full, velocity=full, effort=True)
    if all(len(r) == dtype.itemsize for r in raws):
        return np.frombuffer(b"".join(raws), dtype=dtype)
    from mcap_ros2._dynamic import generate_dynamic

    dec = generate_dynamic(s.JOINT_STATE_TYPE, s.JOINT_STATE_MSGDEF)[s.JOINT_STATE_TYPE]
    out = np.zeros(len(raws), dtype=dtype)
    for i, raw in enumerate(raws):
        msg = dec(raw)
        if len(msg.effort) != len(names):
            raise UserError(f"{path}: {topic} message {i + 1}: {len(msg.effort)} joints")
        out[i]["effort"] = msg.effort
        if full:
            out[i]["position"], out[i]["velocity"] = msg.position, msg.velocity
    return out


def read_flight_log(path: Path) -> FlightLog:
    """Read ``path``; raises UserError if it is not a (complete) flight-recorder log."""
    meta = flight_metadata(path)
    if meta is None:
        raise UserError(f"{path}: not a flight-recorder log (no {s.FLIGHT_METADATA} metadata)")
    names = meta.get("joint_names", "").split(",")
    observers = [o for o in meta.get("observers", "").split(",") if o]
    topics = [s.JOINT_STATE_TOPIC, s.SAFETY_TOPIC, s.TICK_STATUS_TOPIC]
    topics += [s.observer_topic(o) for o in observers]
    raw: dict[str, list[bytes]] = {t: [] for t in topics}
    seq: dict[str, list[int]] = {t: [] for t in topics}
    stamps: list[int] = []
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        origin = clock_origin_ns(reader)
        for _schema, channel, message in reader.iter_messages(topics=topics, log_time_order=True):
            raw[channel.topic].append(message.data)
            seq[channel.topic].append(message.sequence)
            if channel.topic == s.JOINT_STATE_TOPIC:
                stamps.append(message.log_time)
    states = raw[s.JOINT_STATE_TOPIC]
    if len(states) < 2:
        raise UserError(f"{path}: {len(states)} joint states on {s.JOINT_STATE_TOPIC}")
    js = _joint_states(states, names, path, s.JOINT_STATE_TOPIC, full=True)
    ticks = _unwrap(np.asarray(seq[s.JOINT_STATE_TOPIC], dtype=np.int64))
    log = FlightLog(
        path=path,
        t=(np.asarray(stamps, dtype=np.int64) - origin) * 1e-9,  # the loop's t, exactly
        ticks=ticks,
        q=np.array(js["position"]),
        qd=np.array(js["velocity"]),
        tau=np.array(js["effort"]),
        joint_names=names,
        observers=observers,
        metadata=meta,
        attachments=attachments,
    )
    for o in observers:
        topic = s.observer_topic(o)
        est = _joint_states(raw[topic], names, path, topic, full=False)
        if len(est) != log.n_ticks:
            raise UserError(f"{path}: {topic}: {len(est)} messages for {log.n_ticks} ticks")
        log.tau_ext[o] = np.array(est["effort"])
    _tick_status(log, raw[s.TICK_STATUS_TOPIC])
    kinds = json.loads(meta.get("event_kinds", "{}") or "{}")
    dec = DecoderFactory().decoder_for("cdr", _event_schema())
    assert dec is not None
    for data in raw[s.SAFETY_TOPIC]:
        ev = dec(data)
        log.events.append(
            RecordedEvent(
                tick=int(ev.tick),
                t=(ev.header.stamp.sec * 1_000_000_000 + ev.header.stamp.nanosec - origin) * 1e-9,
                kind=int(ev.kind),
                kind_name=ev.kind_name or kinds.get(str(ev.kind), ""),
                joint=int(ev.joint),
                category=int(ev.category),
                value=float(ev.value),
            )
        )
    return log


def _tick_status(log: FlightLog, raws: list[bytes]) -> None:
    """Fill ``monitored``/``qdd_cmd`` (and ``sample_dt``) when every status message has the
    current layout or the one before ``sample_dt`` was logged."""
    if len(raws) != log.n_ticks:
        return  # a cut log: replay falls back
    for with_dt in (True, False):
        dtype, _ = cdr.tick_status_layout(len(log.joint_names), sample_dt=with_dt)
        if all(len(r) == dtype.itemsize for r in raws):
            break
    else:
        return  # an older log (no such fields): replay falls back
    st = np.frombuffer(b"".join(raws), dtype=dtype)
    log.monitored = np.array(st["monitored"], dtype=np.uint8)
    log.qdd_cmd = np.array(st["qdd_cmd"], dtype=float).reshape(log.n_ticks, -1)
    log.mode = np.array(st["mode"], dtype=np.uint8)
    log.wakeup_us = np.array(st["wakeup_us"], dtype=float)
    log.compute_us = np.array(st["compute_us"], dtype=float)
    if with_dt:
        log.sample_dt = np.array(st["sample_dt"], dtype=float)


def _event_schema():
    from mcap.records import Schema

    return Schema(
        id=1,
        name=s.SAFETY_EVENT_TYPE,
        encoding="ros2msg",
        data=s.SAFETY_EVENT_MSGDEF.encode(),
    )
