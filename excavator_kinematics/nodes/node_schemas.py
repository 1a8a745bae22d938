"""Settings schemas of the excavator nodes (manipulator_kinematics.schema); their defaults live in
``config/excavator_nodes.yaml`` (sections ``/**/<node>``), the one place a user reads them."""

from __future__ import annotations

from manipulator_kinematics.nodes.base import FRAME_PREFIX, input_reliability
from manipulator_kinematics.nodes.site_pose import SITE_POSE
from manipulator_kinematics.nodes.surface_grade import DESIGN_SURFACE, GRADE_TOPICS
from manipulator_kinematics.schema import Flag, Number, Numbers, Schema, Text

NODES_CONFIG = "excavator_nodes.yaml"


def _topic(what: str) -> Text:
    return Text(empty=False, doc=what)


def _seconds(doc: str, exclusive_min: bool = False) -> Number:
    """A duration setting: 0 s (or just above, with ``exclusive_min``) to an hour."""
    return Number(unit="s", min=0.0, max=3600.0, exclusive_min=exclusive_min, doc=doc)


_WARNING_PERIOD = _seconds("the same kind of rejection is logged at most this often")
_QOS_DEPTH = Number(min=1, max=100_000, integer=True, doc="reliable keep-last depth of the publishers")
_INPUT_DEPTH = Number(
    min=1,
    max=100_000,
    integer=True,
    doc="depth of the input subscriptions: act on the latest input, drop a backlog",
)
_SWING_MAX_AGE = _seconds("max |stamp(cylinder_lengths) - stamp(joint_states)|")

#: The machine's tilt from topics.machine_tilt (excavator_kinematics.sensing.machine_tilt).
_TILT_MAX_AGE = _seconds("max |stamp(cylinder_lengths) - stamp(machine_tilt)|")
_SITE_POSE_TOPIC = _topic("input: geometry_msgs/PoseStamped, base_link in the site frame (GNSS)")
_MACHINE_TILT_TOPIC = _topic("input: geometry_msgs/Vector3Stamped, up in the upper structure's frame")

FORWARD: Schema = {
    "base_frame": Text(empty=False, doc="frame_id of bucket_pose, bucket_twist and bucket_accel"),
    "frame_prefix": FRAME_PREFIX,
    "swing_max_age": _SWING_MAX_AGE,
    "acceleration_time_constant": _seconds("low-pass on the accelerations; 0 = raw"),
    "acceleration_max_gap": _seconds("a longer gap between messages restarts the differencing"),
    "warning_period": _WARNING_PERIOD,
    "qos_depth": Number(
        min=1,
        max=100_000,
        integer=True,
        doc="reliable keep-last depth of every topic (400: 0.4 s of 1 kHz input; "
        "Fast DDS caps a keep-last depth at 400 unless a profile raises "
        "max_samples_per_instance)",
    ),
    "input_reliability": input_reliability("cylinder_lengths and joint_states"),
    "urdf_joint_states_rate": Number(
        min=0.0,
        max=10_000.0,
        unit="Hz",
        doc="most urdf_joint_states per second of input stamps; 0 = every input",
    ),
    "grade": {
        "enabled": Flag(doc="publish grade_height: the bucket tip above the design plane"),
        "point": Numbers(
            3, Number(min=-1e4, max=1e4, unit="m"), doc="a point [x, y, z] of the plane (m, base frame)"
        ),
        "normal": Numbers(
            3,
            Number(min=-1e6, max=1e6),
            default=None,
            doc="the plane's upward normal [x, y, z] (any length); or give slope/cross_slope",
        ),
        "slope": Number(
            min=-1e4,
            max=1e4,
            unit="%",
            default=None,
            doc="rise of the plane per run along base x, percent (default 0)",
        ),
        "cross_slope": Number(
            min=-1e4,
            max=1e4,
            unit="%",
            default=None,
            doc="rise of the plane per run along base y, percent (default 0)",
        ),
        "frame": Text(empty=False, doc="frame_id of grade_height: the design surface's frame"),
    },
    "level": {
        "enabled": Flag(doc="publish bucket_pose_level from the machine tilt (topics.machine_tilt)"),
        "frame": Text(empty=False, doc="frame_id of bucket_pose_level: base_link levelled by gravity"),
        "tilt_max_age": _TILT_MAX_AGE,
    },
    "design_surface": DESIGN_SURFACE,
    "topics": {
        "cylinder_lengths": _topic("input: sensor_msgs/JointState, boom/arm/bucket cylinder length and rate"),
        "joint_states": _topic("input: sensor_msgs/JointState, swing_joint angle and rate"),
        "bucket_pose": _topic("output: geometry_msgs/PoseStamped"),
        "bucket_twist": _topic("output: geometry_msgs/TwistStamped"),
        "bucket_accel": _topic("output: geometry_msgs/AccelStamped"),
        "open_chain_joint_states": _topic("output: sensor_msgs/JointState of the open chain"),
        "urdf_joint_states": _topic("output: sensor_msgs/JointState of every joint of urdf/excavator.urdf"),
        "grade_height": _topic("output: geometry_msgs/PointStamped, the tip in the design surface's frame"),
        "machine_tilt": _MACHINE_TILT_TOPIC,
        "bucket_pose_level": _topic("output: geometry_msgs/PoseStamped in the level frame"),
        **GRADE_TOPICS,
    },
}

VELOCITY_IK: Schema = {
    "base_frame": Text(empty=False, doc="the frame_id of target_bucket_twist (empty frame_id: this one)"),
    "frame_prefix": FRAME_PREFIX,
    "command_timeout": _seconds("no accepted target for this long: zero rates once, then hold"),
    "state_timeout": _seconds("a cylinder/swing state older than this is refused"),
    "swing_max_age": _SWING_MAX_AGE,
    "condition_threshold": Number(min=1.0, max=1e12, doc="cond(JC0) above which damped least squares starts"),
    "stroke_horizon": _seconds(
        exclusive_min=True, doc="the whole command slows: no actuator reaches its end sooner than this"
    ),
    "bucket_angle_gives_way": Flag(
        doc="at a stroke end keep the tip's linear direction and let the bucket "
        "angle rate give way; false: the whole twist's direction is kept"
    ),
    "line_gain": Number(
        min=0.0,
        max=100.0,
        unit="1/s",
        doc="a constant target's drift from its line is corrected at this rate; 0 = off",
    ),
    "status_period": _seconds("an unchanged status is published again after this long"),
    "twist_residual_tolerance": Number(
        min=0.0, max=1e3, unit="rad/s", doc="unachievable angular velocity before a (throttled) warning"
    ),
    "warning_period": _WARNING_PERIOD,
    "publish_array": Flag(doc="also publish Float64MultiArray for a ros2_control forward command controller"),
    "qos_depth": _QOS_DEPTH,
    "input_queue_depth": _INPUT_DEPTH,
    "input_reliability": input_reliability("target_bucket_twist, cylinder_lengths and joint_states"),
    "zones_file": Text(doc="avoidance zone file (YAML, docs/zones.md) read at start; empty: no zones"),
    "zones_period": _seconds(
        exclusive_min=True,
        doc="longest a command acts before the next one can slow it (state period plus latency)",
    ),
    "zones_stop_time": _seconds(
        exclusive_min=True,
        doc="the actuators stop from full speed within this (deceleration limits: max speed / this)",
    ),
    "zones_lag": _seconds(doc="the actuators' first-order time constant (0: they follow at once)"),
    "site": {
        **SITE_POSE,
        "tilt": Flag(
            doc="roll and pitch of the site pose from topics.machine_tilt (heading and position "
            "from the site pose); used by site-frame zones only"
        ),
        "tilt_max_age": _TILT_MAX_AGE,
    },
    "topics": {
        "target_bucket_twist": _topic("input: geometry_msgs/TwistStamped in base_frame"),
        "cylinder_lengths": _topic("input: sensor_msgs/JointState, cylinder lengths"),
        "joint_states": _topic("input: sensor_msgs/JointState, swing_joint"),
        "rate_commands": _topic("output: sensor_msgs/JointState velocities of swing_joint and the cylinders"),
        "rate_command_array": _topic("output: std_msgs/Float64MultiArray in that order (publish_array)"),
        "status": _topic("output: diagnostic_msgs/DiagnosticArray: tracking / slowed (by what) / stopped"),
        "zone_clearance": _topic("output: diagnostic_msgs/DiagnosticArray, per zone its smallest clearance"),
        "site_pose": _SITE_POSE_TOPIC,
        "machine_tilt": _MACHINE_TILT_TOPIC,
    },
}

IMU_STATE: Schema = {
    "max_skew": _seconds("largest spread of the four sensors' latest stamps in one set"),
    "max_age": _seconds(
        exclusive_min=True,
        doc="a sensor whose newest message arrived longer ago (node clock) is stale: no "
        "output, a reason; also the grace after start-up; checked every max_age / 4",
    ),
    "gravity_time_constant": _seconds(
        "complementary filter of the gravity direction "
        "(sensors without orientation); 0 = the accelerometer as it is"
    ),
    "max_angular_rate": Number(
        min=0.0, max=1e3, unit="rad/s", exclusive_min=True, doc="a gyro reading beyond this is implausible"
    ),
    "max_dynamic_acceleration": Number(
        min=0.0,
        max=1e3,
        unit="m/s^2",
        exclusive_min=True,
        doc="| |linear_acceleration| - g | beyond this: no gravity direction",
    ),
    "upper_structure_frame": Text(empty=False, doc="frame_id of machine_tilt"),
    "frame_prefix": FRAME_PREFIX,
    "warning_period": _WARNING_PERIOD,
    "qos_depth": _QOS_DEPTH,
    "input_reliability": input_reliability("the four Imu topics"),
    "topics": {
        "imu_cab": _topic("input: sensor_msgs/Imu on the upper structure"),
        "imu_boom": _topic("input: sensor_msgs/Imu on the boom"),
        "imu_arm": _topic("input: sensor_msgs/Imu on the arm"),
        "imu_bucket_linkage": _topic("input: sensor_msgs/Imu on the H-link or the bucket (machine file)"),
        "cylinder_lengths": _topic("output: sensor_msgs/JointState, cylinder lengths and rates"),
        "machine_tilt": _topic("output: geometry_msgs/Vector3Stamped, up in the upper structure's frame"),
    },
}

SIM: Schema = {
    "rate": Number(
        min=0.0, max=10_000.0, unit="Hz", exclusive_min=True, doc="rate of cylinder_lengths and joint_states"
    ),
    "time_constant": _seconds("first-order lag of the actuators; 0 = ideal"),
    "command_timeout": _seconds("no rate command for this long: the actuators stop"),
    "warning_period": _WARNING_PERIOD,
    "initial_swing_angle": Number(
        min=-7.0, max=7.0, unit="rad", doc="true swing angle at start (rad; the reading is it - zero_offset)"
    ),
    "initial_cylinder_lengths": Numbers(
        3,
        Number(min=0.0, max=20.0, unit="m"),
        default=None,
        doc="true boom, arm, bucket cylinder lengths at start (m; readings are them - zero_offset); "
        "default: the machine's reference lengths",
    ),
    "qos_depth": _QOS_DEPTH,
    "input_queue_depth": _INPUT_DEPTH,
    "input_reliability": input_reliability("rate_commands"),
    "topics": {
        "rate_commands": _topic("input: sensor_msgs/JointState velocities (rate commands)"),
        "cylinder_lengths": _topic("output: sensor_msgs/JointState, cylinder lengths and rates"),
        "joint_states": _topic("output: sensor_msgs/JointState, swing_joint"),
    },
}
