"""numpy <-> ROS messages for the generic nodes: poses, twists and joint states of any machine."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Pose, PoseStamped, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from manipulator_kinematics.model import matrix_quaternion
from manipulator_kinematics.trajectory import JointTrajectory as Samples

#: Latest time_from_start a Duration holds (its ``sec`` is an int32).
MAX_TIME_FROM_START = 2.0**31 - 1.0


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


def joint_trajectory(frame_id: str, names: Sequence[str], samples: Samples) -> JointTrajectory:
    """Timed joint samples (t, q, qd, qdd) as a JointTrajectory with positions, velocities and
    accelerations. ValueError when a value is not finite or a time is outside what a Duration holds."""
    t = np.asarray(samples.t, dtype=float)
    values = (samples.q, samples.qd, samples.qdd)
    if not (np.all(np.isfinite(t)) and np.all(t >= 0.0) and np.all(t <= MAX_TIME_FROM_START)):
        raise ValueError(f"times must lie in [0, {MAX_TIME_FROM_START:.0f}] s")
    if not all(np.all(np.isfinite(v)) for v in values):
        raise ValueError("positions, velocities and accelerations must be finite")
    nanoseconds = np.rint(t * 1e9).astype(np.int64).tolist()
    q, qd, qdd = (np.asarray(v, dtype=float).tolist() for v in values)
    points = [
        JointTrajectoryPoint(
            positions=p,
            velocities=v,
            accelerations=a,
            time_from_start=Duration(sec=ns // 10**9, nanosec=ns % 10**9),
        )
        for p, v, a, ns in zip(q, qd, qdd, nanoseconds, strict=True)
    ]
    return JointTrajectory(header=Header(frame_id=frame_id), joint_names=list(names), points=points)
