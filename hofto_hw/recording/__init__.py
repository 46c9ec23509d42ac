"""Recording: MCAP logs in ROS 2 message encodings (Foxglove and ros2 bag open them).

:mod:`schemas` holds the message definitions and topic names, :mod:`writer` writes offline
joint-state logs and :mod:`reader` reads them back into arrays.

The flight recorder of the real-time loop: :mod:`record` (record layouts, RecordSink),
:mod:`ring` (lock-free shared-memory ring), :mod:`shared` (the segment: control block and
rings), :mod:`recorder` (FlightRecorder, the sink that owns the writer process),
:mod:`writer_process` (drains the rings), :mod:`flight_file` (one MCAP file: topics,
attachments, rotation unit), :mod:`cdr` (fixed-layout CDR batches), :mod:`attachments`
(config/URDF/parameters/thresholds of a run), :mod:`recover` and :mod:`info` (`hofto-hw log`).
"""

from hofto_hw.recording.reader import JointStates, read_joint_states
from hofto_hw.recording.schemas import JOINT_STATE_TOPIC
from hofto_hw.recording.writer import JointStateWriter, write_joint_states

__all__ = [
    "JOINT_STATE_TOPIC",
    "JointStateWriter",
    "JointStates",
    "read_joint_states",
    "write_joint_states",
]
