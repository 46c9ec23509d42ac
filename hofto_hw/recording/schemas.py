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


# ----------------------------------------------------------------- flight recorder topics


def _msgdef(*parts: list[str]) -> str:
    """A top-level definition followed by its dependencies, separated as rosbag2 does."""
    out: list[str] = list(parts[0])
    for dep in parts[1:]:
        out += [_SEPARATOR, *dep]
    return "\n".join(out)


_HEADER = ["MSG: std_msgs/Header", "builtin_interfaces/Time stamp", "string frame_id"]
_TIME = ["MSG: builtin_interfaces/Time", "int32 sec", "uint32 nanosec"]

WRENCH_STAMPED_TYPE = "geometry_msgs/msg/WrenchStamped"
WRENCH_STAMPED_MSGDEF = _msgdef(
    ["std_msgs/Header header", "Wrench wrench"],
    _HEADER,
    _TIME,
    ["MSG: geometry_msgs/Wrench", "Vector3  force", "Vector3  torque"],
    ["MSG: geometry_msgs/Vector3", "float64 x", "float64 y", "float64 z"],
)

DIAGNOSTIC_ARRAY_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
DIAGNOSTIC_ARRAY_MSGDEF = _msgdef(
    ["std_msgs/Header header", "DiagnosticStatus[] status"],
    _HEADER,
    _TIME,
    [
        "MSG: diagnostic_msgs/DiagnosticStatus",
        "byte OK=0",
        "byte WARN=1",
        "byte ERROR=2",
        "byte STALE=3",
        "byte level",
        "string name",
        "string message",
        "string hardware_id",
        "KeyValue[] values",
    ],
    ["MSG: diagnostic_msgs/KeyValue", "string key", "string value"],
)

#: Safety events use a small custom message rather than std_msgs/String with JSON: the
#: fields are typed (Foxglove plots them, replay reads the tick as an integer, no parser or
#: schema drift), and the definition travels in the file, so mcap/Foxglove decode it without
#: a ROS installation. (A live ROS 2 subscriber would need the package built; we only log.)
SAFETY_EVENT_TYPE = "hofto_hw_msgs/msg/SafetyEvent"
SAFETY_EVENT_MSGDEF = _msgdef(
    [
        "std_msgs/Header header",
        "uint64 tick",
        "uint16 kind",
        "string kind_name",
        "int16 joint",
        "int8 category",
        "float64 value",
    ],
    _HEADER,
    _TIME,
)

#: Per-tick loop status (controller mode, latched fault bits, bus status, timing): a custom
#: message for the same reasons as the safety event; fixed size, so the writer packs it in
#: batches like the joint states.
TICK_STATUS_TYPE = "hofto_hw_msgs/msg/TickStatus"
TICK_STATUS_MSGDEF = _msgdef(
    [
        "std_msgs/Header header",
        "uint64 tick",
        "uint8 mode",
        "uint32 faults",
        "int32 bus_status",
        "float32 wakeup_us",
        "float32 compute_us",
        "uint8 monitored",
        "float64[] qdd_cmd",
        "float64 sample_dt",
    ],
    _HEADER,
    _TIME,
)

#: flight-recorder topics (JOINT_STATE_TOPIC carries q [rad], qd [rad/s], tau [N·m])
COMMAND_TOPIC = "/joint_commands"  # JointState, position = commanded q [rad]
WRENCH_TOPIC = "/tool/wrench_estimate"  # WrenchStamped [N, N·m]
DIAGNOSTICS_TOPIC = "/diagnostics"  # DiagnosticArray at 10 Hz
SAFETY_TOPIC = "/safety/events"  # SafetyEvent
TICK_STATUS_TOPIC = "/loop/status"  # TickStatus, every tick


def observer_topic(name: str) -> str:
    """JointState topic of observer ``name``'s tau_ext_hat [N·m] (effort field)."""
    return f"/observers/{name}/tau_ext"


#: metadata record name and format tag of flight-recorder files
FLIGHT_METADATA = "hofto_hw.flight"
FLIGHT_FORMAT = "hofto-hw/flight-recorder"

# ------------------------------------------------------------- what draws the arm in 3D

STRING_TYPE = "std_msgs/msg/String"
STRING_MSGDEF = "string data"

TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"
TF_MESSAGE_MSGDEF = _msgdef(
    ["geometry_msgs/TransformStamped[] transforms"],
    [
        "MSG: geometry_msgs/TransformStamped",
        "std_msgs/Header header",
        "string child_frame_id",
        "Transform transform",
    ],
    _HEADER,
    _TIME,
    ["MSG: geometry_msgs/Transform", "Vector3 translation", "Quaternion rotation"],
    ["MSG: geometry_msgs/Vector3", "float64 x", "float64 y", "float64 z"],
    ["MSG: geometry_msgs/Quaternion", "float64 x", "float64 y", "float64 z", "float64 w"],
)

#: the URDF as std_msgs/String, once at the start of each file (latched, as robot_state_publisher)
ROBOT_DESCRIPTION_TOPIC = "/robot_description"
#: each movable joint's transform parent link -> child link (and the tool's aligned frame),
#: from the logged joint positions at LogSpec.tf_rate_hz
TF_TOPIC = "/tf"
#: the fixed joints' transforms, once at the start of each file
TF_STATIC_TOPIC = "/tf_static"

#: metadata record with ``origin_ns``: the wall-clock time [ns since the Unix epoch] of the
#: loop's t = 0. Log times and stamps are origin_ns + round(t·1e9); logs without it have
#: origin 0 (stamps from the loop's t alone).
CLOCK_METADATA = "hofto_hw.clock"

#: The contact and collision thresholds [N·m] per joint the loop's monitor applied to the
#: detector observer's estimate, re-computed by the writer process from the logged records
#: (hofto_hw.replay.levels_track), on the ticks the monitor judged. ``contact`` is empty when
#: the monitor has one level.
COLLISION_THRESHOLDS_TYPE = "hofto_hw_msgs/msg/CollisionThresholds"
COLLISION_THRESHOLDS_MSGDEF = _msgdef(
    ["std_msgs/Header header", "string observer", "float64[] contact", "float64[] collision"],
    _HEADER,
    _TIME,
)
THRESHOLDS_TOPIC = "/safety/thresholds"
