"""Message definitions and topic names of our MCAP logs.

Joint states use ROS 2 ``sensor_msgs/msg/JointState`` encoded as CDR: ``position`` [rad],
``velocity`` [rad/s], ``effort`` [N·m] (joint-side motor torque), one message per tick.
The definition text below is the standard ROS 2 one with its dependencies appended in the
``MSG:`` format rosbag2 writes, so readers need no ROS installation.
"""

from __future__ import annotations

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"

#: topic of the measured joint state
JOINT_STATE_TOPIC = "/joint_states"

_SEPARATOR = "=" * 80

JOINT_STATE_MSGDEF = "\n".join(
    [
        "std_msgs/Header header",
        "string[] name",
        "float64[] position",
        "float64[] velocity",
        "float64[] effort",
        _SEPARATOR,
        "MSG: std_msgs/Header",
        "builtin_interfaces/Time stamp",
        "string frame_id",
        _SEPARATOR,
        "MSG: builtin_interfaces/Time",
        "int32 sec",
        "uint32 nanosec",
    ]
)

#: metadata record naming the joints and where the data came from
METADATA_NAME = "hofto_hw"
