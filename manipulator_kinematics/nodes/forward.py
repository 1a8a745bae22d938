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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from manipulator_kinematics.config import Number, Text
from manipulator_kinematics.joint_state import InputError, check_plausible_positions, joint_values
from manipulator_kinematics.model import describe_limits
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes.base import FRAME_PREFIX, MachineNode, input_qos, input_reliability
from manipulator_kinematics.nodes.messages import pose_stamped, twist_stamped
from manipulator_kinematics.registry import Machine

SETTINGS = {
    "base_frame": Text(empty=False, doc="frame_id of tool_pose and tool_twist (the machine's base)"),
    "frame_prefix": FRAME_PREFIX,
    "qos_depth": Number(min=1, max=100_000, integer=True, doc="keep-last depth of every topic"),
    "input_reliability": input_reliability("joint_states"),
    "warning_period": Number(min=0.0, max=3600.0, unit="s",
                             doc="the same kind of rejection is logged at most this often"),
    "topics": {
        "joint_states": Text(empty=False, doc="input: sensor_msgs/JointState"),
        "tool_pose": Text(empty=False, doc="output: geometry_msgs/PoseStamped"),
        "tool_twist": Text(empty=False, doc="output: geometry_msgs/TwistStamped"),
    },
}


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
        self.pose_pub = self.create_publisher(PoseStamped, topics["tool_pose"], qos)
        self.twist_pub = self.create_publisher(TwistStamped, topics["tool_twist"], qos)
        self.create_subscription(JointState, topics["joint_states"], self.on_joint_state,
                                 input_qos(s["qos_depth"], s["input_reliability"]))
        self.get_logger().info(
            f"{machine.name}: {topics['joint_states']} {list(self.joint_names)} -> {topics['tool_pose']}, "
            f"{topics['tool_twist']} in frame {self.frame!r}")

    def on_joint_state(self, msg: JointState) -> None:
        try:
            q, qd = joint_values(msg, self.joint_names, require_position=True)
            check_plausible_positions(q, self.joint_names, self.limits.lower, self.limits.upper)
        except InputError as error:
            self.log("warning", f"dropped joint_states: {error}")
            return
        with np.errstate(all="ignore"):  # overflow shows as a non-finite result, checked below
            pose = self.model.fkine(q)
            twist = None if qd is None else self.model.jacob0(q) @ qd
        if not np.all(np.isfinite(pose)) or (twist is not None and not np.all(np.isfinite(twist))):
            self.log("warning", f"dropped joint_states: non-finite pose or twist from {q.tolist()}")
            return
        if not self.limits.within(q):
            self.log("warning", "joint_states outside the limits (published all the same): "
                     + describe_limits(q, self.limits))
        stamp = msg.header.stamp
        self.pose_pub.publish(pose_stamped(stamp, self.frame, pose))
        if twist is not None:
            self.twist_pub.publish(twist_stamped(stamp, self.frame, twist))
