"""Joint-state logs in MCAP (ROS 2 message encodings, so Foxglove and ros2 bag open them).

:mod:`schemas` holds the message definitions and topic names, :mod:`writer` writes logs and
:mod:`reader` reads them back into arrays. The real-time logger builds on these.
"""

from hofto_hw.logging.reader import JointStates, read_joint_states
from hofto_hw.logging.schemas import JOINT_STATE_TOPIC
from hofto_hw.logging.writer import JointStateWriter, write_joint_states

__all__ = [
    "JOINT_STATE_TOPIC",
    "JointStateWriter",
    "JointStates",
    "read_joint_states",
    "write_joint_states",
]
