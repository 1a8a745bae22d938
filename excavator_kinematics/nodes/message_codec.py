"""ROS messages <-> numpy for the excavator nodes (parsing with reasons, building outputs)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from excavator_kinematics.core.kinematics import bucket_quaternion
from manipulator_kinematics.joint_state import InputError, joint_values


def stamp_ns(stamp: Time) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def positions_and_rates(msg: JointState, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Both fields of ``names``; InputError when either is empty (a state needs both)."""
    return joint_values(msg, names, require_position=True, require_velocity=True)


def joint_state(
    stamp: Time,
    names: Sequence[str],
    positions: np.ndarray | None = None,
    velocities: np.ndarray | None = None,
) -> JointState:
    msg = JointState(header=Header(stamp=stamp), name=list(names))
    if positions is not None:
        msg.position = [float(v) for v in positions]
    if velocities is not None:
        msg.velocity = [float(v) for v in velocities]
    return msg


def bucket_pose_values(theta1: float, q: Sequence[float]) -> list[float]:
    """Tip position and bucket orientation quaternion (x, y, z, w: yaw theta1, then -alpha about +y;
    REP 103) from Q = [x, y, z, alpha], in the order of geometry_msgs/Pose."""
    return [float(q[0]), float(q[1]), float(q[2]), *bucket_quaternion(theta1, q[3]).tolist()]


def bucket_pose(stamp: Time, frame_id: str, theta1: float, q: np.ndarray) -> PoseStamped:
    msg = PoseStamped(header=Header(stamp=stamp, frame_id=frame_id))
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = bucket_pose_values(theta1, q)
    return msg


def bucket_twist(stamp: Time, frame_id: str, linear: np.ndarray, angular: np.ndarray) -> TwistStamped:
    msg = TwistStamped(header=Header(stamp=stamp, frame_id=frame_id))
    t = msg.twist
    t.linear.x, t.linear.y, t.linear.z = (float(v) for v in linear)
    t.angular.x, t.angular.y, t.angular.z = (float(v) for v in angular)
    return msg


def twist_arrays(msg: TwistStamped) -> tuple[np.ndarray, np.ndarray]:
    """(linear, angular) of a twist; InputError when not finite."""
    t = msg.twist
    linear = np.array([t.linear.x, t.linear.y, t.linear.z])
    angular = np.array([t.angular.x, t.angular.y, t.angular.z])
    if not (np.all(np.isfinite(linear)) and np.all(np.isfinite(angular))):
        raise InputError(f"non-finite twist: linear {linear.tolist()}, angular {angular.tolist()}")
    return linear, angular
