"""Recording: MCAP logs in ROS 2 message encodings (Foxglove and ros2 bag open them).

:mod:`schemas` holds the message definitions and topic names, :mod:`writer` writes logs and
:mod:`reader` reads them back into arrays. The real-time logger builds on these.
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
