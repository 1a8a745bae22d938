"""Generic forward node of a serial machine: ``joint_states`` -> ``tool_pose`` + ``tool_twist``.

Subscribes sensor_msgs/JointState (the machine's joints matched by name, others ignored) and
publishes the tool's geometry_msgs/PoseStamped (``model.fkine``) and, when the message carries
velocities, its TwistStamped (``model.jacob0`` times the joint rates: linear velocity of the tool
point and angular velocity, in ``base_frame``), both stamped with the input's stamp.

A message that lacks a joint, mismatches its arrays, holds a non-finite value or a position
further outside the limits than 1000 x the joint's range (implausible:
:func:`manipulator_kinematics.joint_state.check_plausible_positions`), or gives a non-finite pose
or twist is dropped with a throttled log line; nothing non-finite is published. A state outside
the joint limits otherwise is still published (it is a measurement) with a warning.

Built for 1 kHz input like excavator_forward (docs/excavator_nodes.md): the subscription is raw and
:func:`manipulator_kinematics.joint_state.decode_joint_state` reads the JointState from its bytes,
and both outputs are :class:`manipulator_kinematics.codec.packed.PackedMessage` objects (only their
numbers rewritten per message): rclpy's message conversion would cost more than the kinematics.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from manipulator_kinematics.codec.packed import PackedMessage
from manipulator_kinematics.joint_state import (
    InputError,
    check_plausible_positions,
    decode_joint_state,
    joint_values,
)
from manipulator_kinematics.model import describe_limits, matrix_quaternion
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes.base import FRAME_PREFIX, MachineNode, input_qos, input_reliability
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.schema import Number, Text

SETTINGS = {
    "base_frame": Text(empty=False, doc="frame_id of tool_pose and tool_twist (the machine's base)"),
    "frame_prefix": FRAME_PREFIX,
    "qos_depth": Number(min=1, max=100_000, integer=True, doc="keep-last depth of every topic"),
    "input_reliability": input_reliability("joint_states"),
    "warning_period": Number(
        min=0.0, max=3600.0, unit="s", doc="the same kind of rejection is logged at most this often"
    ),
    "topics": {
        "joint_states": Text(empty=False, doc="input: sensor_msgs/JointState"),
        "tool_pose": Text(empty=False, doc="output: geometry_msgs/PoseStamped"),
        "tool_twist": Text(empty=False, doc="output: geometry_msgs/TwistStamped"),
    },
}
# What changes in an output from one input to the next: everything but frame_id.
STAMPED = ("header.stamp", "pose", "twist")


class ForwardNode(MachineNode):
    """FK of every joint state of a registered serial machine (module docstring)."""

    SETTINGS = SETTINGS

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        s = self.settings
        self.frame = s["frame_prefix"] + s["base_frame"]
        self.joint_names = machine.joint_names(self.model)
        self.limits = machine.limits(self.model)
        self.log = ThrottledLog(self, s["warning_period"])
        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        topics = s["topics"]
        header = Header(frame_id=self.frame)
        self.pose = PackedMessage(PoseStamped(header=header), STAMPED)
        self.twist = PackedMessage(TwistStamped(header=header), STAMPED)
        self.pose_pub = self.create_publisher(PoseStamped, topics["tool_pose"], qos)
        self.twist_pub = self.create_publisher(TwistStamped, topics["tool_twist"], qos)
        self.create_subscription(
            JointState,
            topics["joint_states"],
            self.on_joint_state,
            input_qos(s["qos_depth"], s["input_reliability"]),
            raw=True,
        )
        self.get_logger().info(
            f"{machine.name}: {topics['joint_states']} {list(self.joint_names)} -> {topics['tool_pose']}, "
            f"{topics['tool_twist']} in frame {self.frame!r}"
        )

    def on_joint_state(self, raw: bytes) -> None:
        try:
            msg = decode_joint_state(raw)
            q, qd = joint_values(msg, self.joint_names, require_position=True)
            check_plausible_positions(q, self.joint_names, self.limits.lower, self.limits.upper)
        except InputError as error:
            self.log("warning", f"dropped joint_states: {error}")
            return
        with np.errstate(all="ignore"):  # overflow shows as a non-finite result, checked below
            transform = self.model.fkine(q)
            # Python floats: struct packs them, and math checks them, faster than numpy scalars.
            pose = [*transform[:3, 3].tolist(), *matrix_quaternion(transform[:3, :3]).tolist()]
            twist = [] if qd is None else (self.model.jacob0(q) @ qd).tolist()
        if not all(map(math.isfinite, (*pose, *twist))):  # what goes out, checked itself
            self.log("warning", f"dropped joint_states: non-finite pose or twist from {q.tolist()}")
            return
        if not self.limits.within(q):
            self.log(
                "warning",
                "joint_states outside the limits (published all the same): "
                + describe_limits(q, self.limits),
            )
        stamp = (msg.sec, msg.nanosec)
        self.pose_pub.publish(self.pose.pack((*stamp, *pose)))
        if twist:
            self.twist_pub.publish(self.twist.pack((*stamp, *twist)))
