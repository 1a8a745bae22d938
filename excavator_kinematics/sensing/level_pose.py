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
from collections import deque
from typing import Any

from geometry_msgs.msg import PoseStamped, Vector3Stamped
from rclpy.node import Node
from rclpy.qos import QoSProfile
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header

from excavator_kinematics.sensing.imu import base_up, level_rotation
from manipulator_kinematics.codec.packed import PackedMessage
from manipulator_kinematics.node_util import ThrottledLog

#: Tilts kept for pairing: a few sets of any rate (a pose waits for one tilt at most).
KEPT_TILTS = 8


class LevelPose:
    """Subscription to the machine's tilt and the level-frame bucket pose publisher of one node."""

    def __init__(
        self, node: Node, settings: dict[str, Any], topics: dict[str, str], qos: QoSProfile, log: ThrottledLog
    ) -> None:
        self.log = log
        self.max_age_ns = int(settings["tilt_max_age"] * 1e9)
        #: (stamp ns, up) of the latest tilts, oldest first.
        self.tilts: deque[tuple[int, list[float]]] = deque(maxlen=KEPT_TILTS)
        #: A bucket pose waiting for the tilt of its stamp: (stamp ns, (sec, nanosec), theta1, pose).
        self.waiting: tuple[int, tuple[int, int], float, list[float]] | None = None
        self.message = PackedMessage(
            PoseStamped(header=Header(frame_id=settings["frame"])), ("header.stamp", "pose")
        )
        self.publisher = node.create_publisher(PoseStamped, topics["bucket_pose_level"], qos)
        node.create_subscription(Vector3Stamped, topics["machine_tilt"], self.on_tilt, qos)

    def on_tilt(self, msg: Vector3Stamped) -> None:
        v = msg.vector
        up = [v.x, v.y, v.z]
        norm = math.sqrt(sum(c * c for c in up))
        if not all(map(math.isfinite, up)) or abs(norm - 1.0) > 1e-3 or v.z <= 0.0:
            self.log("error", f"rejected machine_tilt {up}: needs a finite unit vector pointing up")
            return
        stamp = msg.header.stamp
        if stamp.sec < 0:
            self.log("error", f"rejected machine_tilt: negative stamp (sec {stamp.sec})")
            return
        self.tilts.append((stamp.sec * 1_000_000_000 + stamp.nanosec, up))
        if self.waiting is not None:
            self.publish_waiting()

    def pose(self, stamp_ns: int, sec_nanosec: tuple[int, int], theta1: float, pose: list[float]) -> None:
        """Publish the level pose of the bucket pose ``pose`` (base_link) now if the tilt of its
        stamp (or a later one) has come, else when the next tilt comes (a pose still waiting is then
        paired with what there is)."""
        if self.waiting is not None:
            self.publish_waiting()
        self.waiting = (stamp_ns, sec_nanosec, theta1, pose)
        if any(stamp >= stamp_ns for stamp, _ in self.tilts):
            self.publish_waiting()

    def publish_waiting(self) -> None:
        stamp_ns, sec_nanosec, theta1, pose = self.waiting
        self.waiting = None
        nearest = min(self.tilts, key=lambda tilt: abs(tilt[0] - stamp_ns), default=None)
        if nearest is None or abs(stamp_ns - nearest[0]) > self.max_age_ns:
            age = "none received" if nearest is None else f"{(stamp_ns - nearest[0]) * 1e-9:+.3f} s away"
            self.log(
                "warning", f"no bucket_pose_level: machine tilt {age} (max age {self.max_age_ns * 1e-9:g} s)"
            )
            return
        rotation = level_rotation(base_up(nearest[1], theta1))
        position = rotation @ pose[:3]
        orientation = (Rotation.from_matrix(rotation) * Rotation.from_quat(pose[3:])).as_quat()
        values = [*position.tolist(), *orientation.tolist()]
        if not all(map(math.isfinite, values)):
            self.log("error", f"no bucket_pose_level: not finite for tilt {nearest[1]}")
            return
        self.publisher.publish(self.message.pack((*sec_nanosec, *values)))
