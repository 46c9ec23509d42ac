"""Read joint-state MCAP logs written by :mod:`hofto_hw.recording.writer` into arrays."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import McapReader, make_reader
from mcap_ros2.decoder import DecoderFactory
from numpy.typing import NDArray

from hofto_hw.errors import UserError
from hofto_hw.recording.schemas import CLOCK_METADATA, JOINT_STATE_TOPIC, JOINT_STATE_TYPE


@dataclass
class JointStates:
    """Joint states of one log: ``t`` (N,) [s] from the message stamps (less a flight log's
    wall-clock origin: the loop's t), ``q`` (N, n) [rad],
    ``qd`` (N, n) [rad/s], ``tau`` (N, n) [N·m], ``names`` the n joint names."""

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    tau: NDArray[np.float64]
    names: list[str]


def clock_origin_ns(reader: McapReader) -> int:
    """The flight recorder's wall-clock origin [ns] from an MCAP reader (metadata
    ``hofto_hw.clock``: the wall clock of the loop's t = 0), else 0: times of a log without it
    (older logs, offline logs) are stamped from the start of the data alone."""
    for m in reader.iter_metadata():
        if m.name == CLOCK_METADATA:
            return int(m.metadata.get("origin_ns", "0") or 0)
    return 0


def read_joint_states(path: str | Path, topic: str | None = None) -> JointStates:
    """All ``sensor_msgs/msg/JointState`` messages on ``topic`` (default /joint_states)."""
    path = Path(path)
    topic = topic or JOINT_STATE_TOPIC
    t: list[float] = []
    rows: dict[str, list[list[float]]] = {"position": [], "velocity": [], "effort": []}
    names: list[str] = []
    try:
        with path.open("rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            origin = clock_origin_ns(reader)
            f.seek(0)
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for schema, _channel, _message, msg in reader.iter_decoded_messages(topics=[topic]):
                if schema is None or schema.name != JOINT_STATE_TYPE:
                    got = schema.name if schema else "no schema"
                    raise UserError(f"{path}: topic {topic} carries {got}, not {JOINT_STATE_TYPE}")
                stamp = msg.header.stamp
                t.append((stamp.sec * 1_000_000_000 + stamp.nanosec - origin) * 1e-9)
                k = len(t)
                if not names:
                    names = list(msg.name)
                for field, out in rows.items():
                    values = list(getattr(msg, field))
                    if len(values) != len(names):
                        raise UserError(
                            f"{path}: message {k}: {field} has {len(values)} entries, "
                            f"expected {len(names)} (one per joint)"
                        )
                    out.append(values)
    except FileNotFoundError:
        raise UserError(f"{path}: log not found") from None
    except (McapError, ValueError, EOFError, OSError) as exc:
        raise UserError(f"{path}: not a readable MCAP log: {exc}") from None
    if not t:
        raise UserError(f"{path}: no {JOINT_STATE_TYPE} messages on topic {topic}")
    return JointStates(
        t=np.asarray(t),
        q=np.asarray(rows["position"], dtype=np.float64),
        qd=np.asarray(rows["velocity"], dtype=np.float64),
        tau=np.asarray(rows["effort"], dtype=np.float64),
        names=names,
    )
