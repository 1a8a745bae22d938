"""numpy -> trajectory_msgs/JointTrajectory (imports the ROS message types; not part of the numpy core)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Duration
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


def joint_trajectory(
    names: Sequence[str], t: np.ndarray, q: np.ndarray, qd: np.ndarray | None = None, frame_id: str = ""
) -> JointTrajectory:
    """A JointTrajectory of samples ``t`` (M,) s from the start, positions ``q`` (M, n), rates ``qd`` (M, n).

    The header stamp stays zero: "start when received", as trajectory_msgs documents it.
    """
    t, q = np.asarray(t, dtype=float), np.asarray(q, dtype=float)
    if q.shape != (len(t), len(names)) or (qd is not None and np.shape(qd) != q.shape):
        raise ValueError(f"need q (and qd) of shape ({len(t)}, {len(names)}), got {q.shape}")
    if not (np.all(np.isfinite(q)) and np.all(np.diff(t) > 0.0) and t[0] >= 0.0):
        raise ValueError("positions must be finite and times increasing from >= 0")
    points = []
    for i, time in enumerate(t):
        sec, nanosec = divmod(round(float(time) * 1e9), 1_000_000_000)
        point = JointTrajectoryPoint(
            positions=[float(v) for v in q[i]], time_from_start=Duration(sec=sec, nanosec=nanosec)
        )
        if qd is not None:
            point.velocities = [float(v) for v in qd[i]]
        points.append(point)
    return JointTrajectory(header=Header(frame_id=frame_id), joint_names=list(names), points=points)


def trajectory_dict(msg: JointTrajectory) -> dict[str, Any]:
    """The message as plain data (the YAML ``ros2 topic pub`` takes)."""
    return {
        "header": {
            "stamp": {"sec": msg.header.stamp.sec, "nanosec": msg.header.stamp.nanosec},
            "frame_id": msg.header.frame_id,
        },
        "joint_names": list(msg.joint_names),
        "points": [
            {
                "positions": list(p.positions),
                "velocities": list(p.velocities),
                "accelerations": list(p.accelerations),
                "effort": list(p.effort),
                "time_from_start": {"sec": p.time_from_start.sec, "nanosec": p.time_from_start.nanosec},
            }
            for p in msg.points
        ],
    }
