"""The forward node's bucket pose in the gravity-aligned level frame (ROS side of
:func:`excavator_kinematics.imu.level_rotation`).

Settings ``level.*`` of excavator_forward: with ``enabled``, the node reads ``topics.machine_tilt``
(geometry_msgs/Vector3Stamped: world up in the upper structure's frame, as excavator_imu_state
publishes it from the cab IMU) and publishes, with each bucket pose, ``topics.bucket_pose_level``
(geometry_msgs/PoseStamped in ``level.frame``): the same pose in the frame with base_link's origin
and heading whose z is gravity's up (the swing turns the cab's tilt into base_link's: u_base =
Rz(theta1) u_upper). A tilt older than ``level.tilt_max_age`` s (from the cylinder stamp), not
finite or not of unit length (1e-3), gives no level pose and a throttled reason.
"""

from __future__ import annotations

import math
from typing import Any

from geometry_msgs.msg import PoseStamped, Vector3Stamped
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.time import Time
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header

from excavator_kinematics.imu import base_up, level_rotation
from manipulator_kinematics.codec.packed import PackedMessage
from manipulator_kinematics.node_util import ThrottledLog


class LevelPose:
    """Subscription to the machine's tilt and the level-frame bucket pose publisher of one node."""

    def __init__(self, node: Node, settings: dict[str, Any], topics: dict[str, str], qos: QoSProfile,
                 log: ThrottledLog) -> None:
        self.log = log
        self.max_age_ns = int(settings["tilt_max_age"] * 1e9)
        self.up: list[float] | None = None
        self.stamp_ns = 0
        self.message = PackedMessage(PoseStamped(header=Header(frame_id=settings["frame"])),
                                     ("header.stamp", "pose"))
        self.publisher = node.create_publisher(PoseStamped, topics["bucket_pose_level"], qos)
        node.create_subscription(Vector3Stamped, topics["machine_tilt"], self.on_tilt, qos)

    def on_tilt(self, msg: Vector3Stamped) -> None:
        v = msg.vector
        up = [v.x, v.y, v.z]
        norm = math.sqrt(sum(c * c for c in up))
        if not all(map(math.isfinite, up)) or abs(norm - 1.0) > 1e-3 or v.z <= 0.0:
            self.log("error", f"rejected machine_tilt {up}: needs a finite unit vector pointing up")
            return
        self.up, self.stamp_ns = up, Time.from_msg(msg.header.stamp).nanoseconds

    def values(self, stamp_ns: int, theta1: float, pose: list[float]) -> list[float]:
        """Position and quaternion [x, y, z, w] of the bucket pose ``pose`` (base_link) in the
        level frame, or [] without a fresh tilt."""
        if self.up is None or abs(stamp_ns - self.stamp_ns) > self.max_age_ns:
            age = "none received" if self.up is None else f"{(stamp_ns - self.stamp_ns) * 1e-9:+.3f} s away"
            self.log("warning", f"no bucket_pose_level: machine tilt {age} "
                     f"(max age {self.max_age_ns * 1e-9:g} s)")
            return []
        rotation = level_rotation(base_up(self.up, theta1))
        position = rotation @ pose[:3]
        orientation = (Rotation.from_matrix(rotation) * Rotation.from_quat(pose[3:])).as_quat()
        return [*position.tolist(), *orientation.tolist()]

    def publish(self, sec_nanosec: tuple[int, int], values: list[float]) -> None:
        self.publisher.publish(self.message.pack((*sec_nanosec, *values)))
