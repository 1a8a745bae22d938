"""numpy <-> ROS messages for the generic nodes: poses, twists and joint states of any machine."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseStamped, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from manipulator_kinematics.model import matrix_quaternion


def pose_stamped(stamp: Time, frame_id: str, transform: np.ndarray) -> PoseStamped:
    """A 4x4 homogeneous transform as PoseStamped (quaternion with w >= 0)."""
    msg = PoseStamped(header=Header(stamp=stamp, frame_id=frame_id))
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = (float(v) for v in transform[:3, 3])
    o.x, o.y, o.z, o.w = (float(v) for v in matrix_quaternion(transform[:3, :3]))
    return msg


def twist_stamped(stamp: Time, frame_id: str, twist: np.ndarray) -> TwistStamped:
    """A 6-vector [vx, vy, vz, wx, wy, wz] (a Jacobian times joint rates) as TwistStamped."""
    msg = TwistStamped(header=Header(stamp=stamp, frame_id=frame_id))
    linear, angular = msg.twist.linear, msg.twist.angular
    linear.x, linear.y, linear.z, angular.x, angular.y, angular.z = (float(v) for v in twist)
    return msg


def joint_state(stamp: Time, names: Sequence[str], positions: np.ndarray) -> JointState:
    return JointState(header=Header(stamp=stamp), name=list(names), position=[float(v) for v in positions])


def pose_array(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) and quaternion (4,) (x, y, z, w) of a Pose, unchecked."""
    p, o = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z]), np.array([o.x, o.y, o.z, o.w])

