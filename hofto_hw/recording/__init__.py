"""Recording: MCAP logs in ROS 2 message encodings (Foxglove and ros2 bag open them).

:mod:`schemas` holds the message definitions and topic names, :mod:`writer` writes offline
joint-state logs and :mod:`reader` reads them back into arrays.

The flight recorder of the real-time loop: :mod:`record` (record layouts, RecordSink),
:mod:`ring` (lock-free shared-memory ring), :mod:`shared` (the segment: control block and
rings), :mod:`recorder` (FlightRecorder, the sink that owns the writer process),
:mod:`writer_process` (drains the rings), :mod:`flight_file` (one MCAP file: topics,
attachments, rotation unit), :mod:`cdr` (fixed-layout CDR batches), :mod:`attachments`
(config/URDF/parameters/thresholds of a run), :mod:`recover` and :mod:`info` (`hofto-hw log`).

The names below are imported on first use: the loop's process imports the flight recorder's
modules (record, ring, shared) and never the MCAP reader or writer, which only the writer
process and the offline commands need.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

#: name -> module holding it
_LAZY = {
    "JointStates": "reader",
    "read_joint_states": "reader",
    "JOINT_STATE_TOPIC": "schemas",
    "JointStateWriter": "writer",
    "write_joint_states": "writer",
}

__all__ = [
    "JOINT_STATE_TOPIC",
    "JointStateWriter",
    "JointStates",
    "read_joint_states",
    "write_joint_states",
]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(f"hofto_hw.recording.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'hofto_hw.recording' has no attribute {name!r}")
