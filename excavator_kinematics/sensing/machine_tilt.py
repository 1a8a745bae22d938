"""The machine's tilt for a node (ROS side of :func:`excavator_kinematics.sensing.imu.base_up`):
geometry_msgs/Vector3Stamped on ``topics.machine_tilt``, world up in the upper structure's frame
as excavator_imu_state publishes it from the cab IMU. The forward node's level pose
(:mod:`.level_pose`) and the velocity IK's site-frame avoidance zones (docs/zones.md) read it.

A tilt not finite, not of unit length (1e-3), not pointing up or with a negative stamp is refused
with a throttled reason. The latest :data:`KEPT_TILTS` are kept for pairing with a state by stamp.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.qos import QoSProfile

from manipulator_kinematics.node_util import ThrottledLog

#: Tilts kept for pairing: a few sets of any rate (a pose waits for one tilt at most).
KEPT_TILTS = 8


class TiltInput:
    """The subscription to the machine's tilt and its latest accepted values; ``on_new`` is called
    after each."""

    def __init__(
        self,
        node: Node,
        topic: str,
        max_age: float,
        qos: QoSProfile,
        log: ThrottledLog,
        on_new: Callable[[], None] | None = None,
    ) -> None:
        self.topic, self.log, self.on_new = topic, log, on_new
        self.max_age_ns = int(max_age * 1e9)
        #: (stamp ns, up) of the latest tilts, oldest first.
        self.tilts: deque[tuple[int, list[float]]] = deque(maxlen=KEPT_TILTS)
        node.create_subscription(Vector3Stamped, topic, self.on_tilt, qos)

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
        if self.on_new is not None:
            self.on_new()

    def came_since(self, stamp_ns: int) -> bool:
        """Whether a tilt of this stamp or a later one has come."""
        return any(stamp >= stamp_ns for stamp, _ in self.tilts)

    def at(self, stamp_ns: int) -> tuple[list[float] | None, str]:
        """The tilt nearest to ``stamp_ns`` (up in the upper structure's frame) and "", or None and
        why (none received, or the nearest farther than the max age)."""
        nearest = min(self.tilts, key=lambda tilt: abs(tilt[0] - stamp_ns), default=None)
        if nearest is None or abs(stamp_ns - nearest[0]) > self.max_age_ns:
            age = "none received" if nearest is None else f"{(stamp_ns - nearest[0]) * 1e-9:+.3f} s away"
            return None, f"machine tilt {age} (max age {self.max_age_ns * 1e-9:g} s)"
        return nearest[1], ""


__all__ = ["KEPT_TILTS", "TiltInput"]
