"""numpy <-> ROS messages for the SCARA nodes (REP 103: the arm's plane is the base x-y plane)."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from manipulator_kinematics.planar import yaw_quaternion


def tool_pose(stamp: Time, frame_id: str, x: np.ndarray) -> PoseStamped:
    """Tool point (px, py, 0) with heading phi about +z, from x = [px, py, phi]."""
    msg = PoseStamped(header=Header(stamp=stamp, frame_id=frame_id))
    msg.pose.position.x, msg.pose.position.y = float(x[0]), float(x[1])
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in yaw_quaternion(x[2]))
    return msg


def tool_twist(stamp: Time, frame_id: str, xd: np.ndarray) -> TwistStamped:
    """Tool point velocity (px', py', 0) and angular velocity (0, 0, phi'), from xd = [px', py', phi']."""
    msg = TwistStamped(header=Header(stamp=stamp, frame_id=frame_id))
    msg.twist.linear.x, msg.twist.linear.y = float(xd[0]), float(xd[1])
    msg.twist.angular.z = float(xd[2])
    return msg


def joint_state(stamp: Time, names: Sequence[str], positions: np.ndarray) -> JointState:
    return JointState(header=Header(stamp=stamp), name=list(names), position=[float(v) for v in positions])
