"""The paper's joint-space quintic (section 4, Figs. 7-9) on the shared trajectory module.

tf = 30 s from theta(0) = [pi/4, pi/3, -pi/4, pi/3, 5pi/4, 0] to theta(30) = [pi/2, pi/6, -pi/3,
pi/4, pi/2, pi/4] with zero boundary velocity and acceleration. The polynomial makes every joint
speed peak at tf/2 and end at 0; joints with equal deltas (J1/J6: +45 deg, J3/J4: -15 deg) have
identical velocity and acceleration curves; J5 (-135 deg) has the largest acceleration.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from manipulator_kinematics.trajectory import JointTrajectory, quintic

PI = math.pi
PAPER_START = np.array([PI / 4, PI / 3, -PI / 4, PI / 3, 5 * PI / 4, 0.0])
PAPER_END = np.array([PI / 2, PI / 6, -PI / 3, PI / 4, PI / 2, PI / 4])
PAPER_DURATION = 30.0


def paper_trajectory(samples: int = 301) -> JointTrajectory:
    """The paper's case sampled at ``samples`` equally spaced times in [0, 30] s."""
    return quintic(PAPER_START, PAPER_END, np.linspace(0.0, PAPER_DURATION, samples))


def joint_trajectory_message(trajectory: JointTrajectory, joint_names: Sequence[str], frame_id: str = ""):
    """The samples as a ``trajectory_msgs/JointTrajectory`` (positions, velocities, accelerations).

    Imports the ROS message package here, so the rest of this module stays numpy only.
    """
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory as Message
    from trajectory_msgs.msg import JointTrajectoryPoint

    message = Message(joint_names=list(joint_names))
    message.header.frame_id = frame_id
    for t, q, qd, qdd in zip(trajectory.t, trajectory.q, trajectory.qd, trajectory.qdd, strict=True):
        seconds, nanoseconds = divmod(round(float(t) * 1e9), 1_000_000_000)
        stamp = Duration(sec=int(seconds), nanosec=int(nanoseconds))
        message.points.append(
            JointTrajectoryPoint(
                positions=q.tolist(),
                velocities=qd.tolist(),
                accelerations=qdd.tolist(),
                time_from_start=stamp,
            )
        )
    return message
