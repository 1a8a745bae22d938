"""The forward node's bucket pose in the gravity-aligned level frame (ROS side of
:func:`excavator_kinematics.sensing.imu.level_rotation`).

Settings ``level.*`` of excavator_forward: with ``enabled``, the node reads ``topics.machine_tilt``
(geometry_msgs/Vector3Stamped: world up in the upper structure's frame, as excavator_imu_state
publishes it from the cab IMU) and publishes, with each bucket pose, ``topics.bucket_pose_level``
(geometry_msgs/PoseStamped in ``level.frame``): the same pose in the frame with base_link's origin
and heading whose z is gravity's up (the swing turns the cab's tilt into base_link's: u_base =
Rz(theta1) u_upper). A tilt older than ``level.tilt_max_age`` s (from the cylinder stamp), not
finite or not of unit length (1e-3), gives no level pose and a throttled reason.

Pairing by stamp: excavator_imu_state stamps a set's tilt and lengths alike, but the two topics
arrive in either order. A bucket pose takes the tilt of its own stamp when it has come; while no
tilt of that stamp or later has come, the pose waits (one at most) for the next tilt, and is then
paired with the nearest tilt by stamp (within ``tilt_max_age``). So every set gets its own tilt at
any sensor rate, and a tilt source with other stamps still gets the nearest one.
"""

from __future__ import annotations

import math
from typing import Any

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header

from excavator_kinematics.sensing.imu import base_up, level_rotation
from excavator_kinematics.sensing.machine_tilt import TiltInput
from manipulator_kinematics.codec.packed import PackedMessage
from manipulator_kinematics.node_util import ThrottledLog


class LevelPose:
    """Subscription to the machine's tilt and the level-frame bucket pose publisher of one node."""

    def __init__(
        self, node: Node, settings: dict[str, Any], topics: dict[str, str], qos: QoSProfile, log: ThrottledLog
    ) -> None:
        self.log = log
        self.tilt = TiltInput(node, topics["machine_tilt"], settings["tilt_max_age"], qos, log, self.on_tilt)
        #: A bucket pose waiting for the tilt of its stamp: (stamp ns, (sec, nanosec), theta1, pose).
        self.waiting: tuple[int, tuple[int, int], float, list[float]] | None = None
        self.message = PackedMessage(
            PoseStamped(header=Header(frame_id=settings["frame"])), ("header.stamp", "pose")
        )
        self.publisher = node.create_publisher(PoseStamped, topics["bucket_pose_level"], qos)

    def on_tilt(self) -> None:
        if self.waiting is not None:
            self.publish_waiting()

    def pose(self, stamp_ns: int, sec_nanosec: tuple[int, int], theta1: float, pose: list[float]) -> None:
        """Publish the level pose of the bucket pose ``pose`` (base_link) now if the tilt of its
        stamp (or a later one) has come, else when the next tilt comes (a pose still waiting is then
        paired with what there is)."""
        if self.waiting is not None:
            self.publish_waiting()
        self.waiting = (stamp_ns, sec_nanosec, theta1, pose)
        if self.tilt.came_since(stamp_ns):
            self.publish_waiting()

    def publish_waiting(self) -> None:
        stamp_ns, sec_nanosec, theta1, pose = self.waiting
        self.waiting = None
        up, why = self.tilt.at(stamp_ns)
        if up is None:
            self.log("warning", f"no bucket_pose_level: {why}")
            return
        rotation = level_rotation(base_up(up, theta1))
        position = rotation @ pose[:3]
        orientation = (Rotation.from_matrix(rotation) * Rotation.from_quat(pose[3:])).as_quat()
        values = [*position.tolist(), *orientation.tolist()]
        if not all(map(math.isfinite, values)):
            self.log("error", f"no bucket_pose_level: not finite for tilt {up}")
            return
        self.publisher.publish(self.message.pack((*sec_nanosec, *values)))
