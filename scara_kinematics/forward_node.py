"""Forward kinematics node of the SCARA arm: joint_states -> tool_pose, tool_twist.

Subscribes sensor_msgs/JointState (joints matched by name, others ignored) and publishes the
tool point's geometry_msgs/PoseStamped and, when the message carries velocities, its
TwistStamped (linear velocity of the tool point and angular velocity, in ``base_frame``), both
stamped with the input's stamp. A message that lacks a joint, mismatches its arrays or holds a
non-finite value is dropped and logged (throttled); nothing non-finite is published. A state
outside the joint limits is still published (it is a measurement; the pose is where the arm is)
with a throttled warning.

Parameters (defaults in config/scara.yaml, section ``scara_forward``): ``base_frame``,
``joint_states_topic``, ``pose_topic``, ``twist_topic``, and the ``scara.*`` machine.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from manipulator_kinematics.joint_state import joint_values
from manipulator_kinematics.node_util import (
    ThrottledLog,
    machine_parameters,
    make_node,
    node_parameters,
    run,
)
from scara_kinematics.kinematics import CONFIG_FILE, IKStatus, Scara
from scara_kinematics.messages import tool_pose, tool_twist

#: Seconds between two log lines of one kind about dropped or out-of-limit inputs.
LOG_PERIOD = 2.0


class ScaraForward:
    """Computes and publishes the tool pose and twist for each joint state."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.scara = Scara.from_parameters(machine_parameters(node, "scara", CONFIG_FILE))
        settings = node_parameters(node, CONFIG_FILE, "scara_forward")
        self.base_frame = str(settings["base_frame"])
        self.pose_pub = node.create_publisher(PoseStamped, str(settings["pose_topic"]), 10)
        self.twist_pub = node.create_publisher(TwistStamped, str(settings["twist_topic"]), 10)
        node.create_subscription(JointState, str(settings["joint_states_topic"]), self.on_joint_state, 10)
        self.log = ThrottledLog(node, LOG_PERIOD)

    def on_joint_state(self, msg: JointState) -> None:
        try:
            q, qd = joint_values(msg, self.scara.joint_names, require_position=True)
        except ValueError as error:
            self.log("warning", f"dropped joint_states: {error}")
            return
        x = self.scara.fk(q)
        xd = None if qd is None else self.scara.velocity_fk(q, qd)
        if not np.all(np.isfinite(x)) or (xd is not None and not np.all(np.isfinite(xd))):
            self.log("warning", f"dropped joint_states: non-finite pose or twist from {q.tolist()}")
            return
        if not self.scara.within_limits(q):
            violation = self.scara.describe(q, IKStatus.JOINT_LIMITS, 0.0)
            self.log("warning", f"joint_states outside the limits (published all the same): {violation}")
        stamp = msg.header.stamp
        self.pose_pub.publish(tool_pose(stamp, self.base_frame, x))
        if xd is not None:
            self.twist_pub.publish(tool_twist(stamp, self.base_frame, xd))


def _create() -> Node:
    node = make_node("scara_forward")
    ScaraForward(node)  # the subscription holds its bound method, so it lives as long as the node
    return node


def main(args: Sequence[str] | None = None) -> int:
    return run(_create, args)


if __name__ == "__main__":
    raise SystemExit(main())
