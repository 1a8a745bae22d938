"""The excavator as a registered machine (entry point ``excavator`` of
``manipulator_kinematics.machines``, see :mod:`manipulator_kinematics.registry`).

Its joints are the actuators, in the order of D = [theta1, d2, d3, d4]: the swing drive and the
boom, arm and bucket cylinders; its limits are the swing range and the strokes. Its machine file
has two sections: the linkage in the family's ``hydraulic_machine`` section (read onto the
excavator's topology) and the ``excavator`` section (:mod:`excavator_kinematics.core.machine_file`).
"""

from __future__ import annotations

from typing import Any

from excavator_kinematics.core.kinematics import ACTUATORS, Excavator
from excavator_kinematics.core.machine_file import FAMILY, GEOMETRY, SCHEMA, SECTION, describe, read
from manipulator_kinematics.registry import Hook, Machine
from manipulator_kinematics.serial_chain import JointLimits

_JOINT_STATE = "sensor_msgs/msg/JointState"
_TWIST = "geometry_msgs/msg/TwistStamped"


def _model(params: dict[str, Any]) -> Excavator:
    return Excavator(describe(params))


def _limits(model: Excavator) -> JointLimits:
    return model.joint_limits


MACHINE = Machine(
    name="excavator",
    summary="hydraulic excavator (paper 000): swing + boom/arm/bucket cylinders -> bucket tip, "
    "velocity and acceleration, and the cylinder rates for a bucket velocity",
    section=SECTION,
    config_file="excavator_cet200.yaml",
    schema=SCHEMA,
    factory=_model,
    also={FAMILY: GEOMETRY},
    read=read,
    # Every topic of the excavator nodes (config/excavator_nodes.yaml, default names).
    topics={
        "cylinder_lengths": _JOINT_STATE,
        "joint_states": _JOINT_STATE,
        "open_chain_joint_states": _JOINT_STATE,
        "urdf_joint_states": _JOINT_STATE,
        "grade_height": "geometry_msgs/msg/PointStamped",
        "site_pose": "geometry_msgs/msg/PoseStamped",
        "machine_tilt": "geometry_msgs/msg/Vector3Stamped",
        "bucket_pose_level": "geometry_msgs/msg/PoseStamped",
        "imu/cab": "sensor_msgs/msg/Imu",
        "imu/boom": "sensor_msgs/msg/Imu",
        "imu/arm": "sensor_msgs/msg/Imu",
        "imu/bucket_linkage": "sensor_msgs/msg/Imu",
        "grade/tip": "geometry_msgs/msg/PointStamped",
        "grade/left": "geometry_msgs/msg/PointStamped",
        "grade/right": "geometry_msgs/msg/PointStamped",
        "grade/status": "diagnostic_msgs/msg/DiagnosticArray",
        "cylinder_rate_commands": _JOINT_STATE,
        "velocity_controller/commands": "std_msgs/msg/Float64MultiArray",
        "velocity_ik_status": "diagnostic_msgs/msg/DiagnosticArray",
        "zone_clearance": "diagnostic_msgs/msg/DiagnosticArray",
        "bucket_pose": "geometry_msgs/msg/PoseStamped",
        "bucket_twist": _TWIST,
        "bucket_accel": "geometry_msgs/msg/AccelStamped",
        "target_bucket_twist": _TWIST,
    },
    joint_names=lambda model: ACTUATORS,
    limits=_limits,
    analyse=Hook("excavator_kinematics.tools.evaluation:analyse"),
    synthesize=Hook("excavator_kinematics.tools.synthetic:excavator_bag"),
    samples=Hook("excavator_kinematics.tools.evaluation:samples"),
    forward_node="excavator_forward",
    urdf=Hook("excavator_kinematics.core.urdf_joints:excavator_urdf"),
    scene=Hook("excavator_kinematics.tools.scene:excavator_scene"),
    monitored=Hook("excavator_kinematics.core.monitored:ReadingPoints"),
    read_surface=Hook("excavator_kinematics.grade.design_surface:read_landxml"),
)
