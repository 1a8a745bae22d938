"""Where the machine stands in the site frame, for a node (ROS side of
:class:`~manipulator_kinematics.site.SitePose`): the forward nodes' grade outputs
(:mod:`.surface_grade`: the excavator's and the hydraulic family's) and the excavator's velocity
IK's and IK server's site-frame avoidance zones (docs/zones.md) read it with the same settings
(:data:`SITE_POSE`):

* ``site_pose_source: fixed``: ``site_position`` (m) and ``site_rpy`` (rad, fixed axes) of
  base_link in the site frame ``site_frame`` (x easting, y northing, z up), e.g. a surveyed stand;
* ``site_pose_source: topic``: the latest geometry_msgs/PoseStamped on the node's ``site_pose``
  topic (GNSS localisation; frame_id must be ``site_frame``, a unit quaternion, finite values),
  used for a state at most ``site_pose_max_age`` s from its stamp.

A message that breaks the rules is refused with a throttled reason; the pose before it stays.
"""

from __future__ import annotations

import math
from typing import Any

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile

from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.schema import Number, Numbers, Schema, Text
from manipulator_kinematics.site import SitePose

#: The settings of a site pose, same names and meanings in every node that reads one.
SITE_POSE: Schema = {
    "site_frame": Text(empty=False, doc="frame_id of the site (x easting, y northing, z up)"),
    "site_pose_source": Text(
        choices=("fixed", "topic"),
        doc="base_link in the site frame: fixed (site_position, site_rpy) or from topics.site_pose",
    ),
    "site_position": Numbers(
        3, Number(min=-1e8, max=1e8, unit="m"), doc="fixed position of base_link in the site frame (m)"
    ),
    "site_rpy": Numbers(
        3,
        Number(min=-7.0, max=7.0, unit="rad"),
        doc="fixed roll, pitch, yaw of base_link in the site frame (rad, fixed axes)",
    ),
    "site_pose_max_age": Number(
        unit="s", min=0.0, max=3600.0, doc="max |stamp(machine state) - stamp(site pose)|"
    ),
}


class SitePoseInput:
    """The site pose of one node: fixed, or the subscription to its topic (module docstring)."""

    def __init__(
        self, node: Node, settings: dict[str, Any], topic: str, qos: QoSProfile, log: ThrottledLog
    ) -> None:
        self.frame = settings["site_frame"]
        self.topic = topic
        self.log = log
        self.max_age_ns = int(settings["site_pose_max_age"] * 1e9)
        self.from_topic = settings["site_pose_source"] == "topic"
        self.pose: SitePose | None = (
            None if self.from_topic else SitePose.from_rpy(settings["site_position"], settings["site_rpy"])
        )
        self.stamp_ns = 0
        if self.from_topic:
            node.create_subscription(PoseStamped, topic, self.on_pose, qos)

    def describe(self) -> str:
        """Where the pose comes from, for a node's start-up line."""
        return f"from {self.topic}" if self.from_topic else "fixed"

    def on_pose(self, msg: PoseStamped) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        values = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
        if msg.header.frame_id != self.frame or not all(map(math.isfinite, values)) or abs(norm - 1.0) > 1e-3:
            self.log(
                "error",
                f"rejected site pose: needs frame_id {self.frame!r} (got "
                f"{msg.header.frame_id!r}), finite values and a unit quaternion (|q| = {norm:.6g})",
            )
            return
        self.pose = SitePose.from_quaternion(values[:3], values[3:])
        self.stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec

    def at(self, stamp_ns: int) -> tuple[SitePose | None, str]:
        """The site pose for a state stamped ``stamp_ns`` and "", or None and why there is none
        (none received yet, or one farther than ``site_pose_max_age`` from that stamp)."""
        if self.pose is None:
            return None, f"no site pose received on {self.topic} yet"
        if self.from_topic and abs(stamp_ns - self.stamp_ns) > self.max_age_ns:
            return None, (
                f"the site pose is {(stamp_ns - self.stamp_ns) * 1e-9:+.3f} s from the cylinder stamp "
                f"(site_pose_max_age {self.max_age_ns * 1e-9:g} s)"
            )
        return self.pose, ""


__all__ = ["SITE_POSE", "SitePoseInput"]
