"""A forward node's grade outputs against a design TIN (ROS side of
:mod:`manipulator_kinematics.landxml` and :mod:`manipulator_kinematics.site`): the excavator's
(``excavator_forward``, its bucket's cutting edge) and every hydraulic family machine's
(``hydraulic_forward``, its tool point and the tool's width), same settings, topics and messages.

Settings ``design_surface.*`` (:data:`DESIGN_SURFACE`; docs/excavator_nodes.md, docs/nodes.md):

* ``file``: a LandXML 1.2 file (``surface``: the Surface's name, empty = the only one), read at
  start-up into a :class:`~manipulator_kinematics.landxml.Tin` in the site frame
  ``site_frame`` (x easting, y northing, z up);
* where the machine is: ``site_pose_source: fixed`` (``site_position`` m, ``site_rpy`` rad of
  base_link in the site frame) or ``topic``: geometry_msgs/PoseStamped on ``topics.site_pose``
  (GNSS localisation; frame_id must be ``site_frame``), at most ``site_pose_max_age`` s from the
  state's stamp (:class:`~manipulator_kinematics.nodes.site_pose.SitePoseInput`, which the
  excavator's site-frame zones read too).

On each forward result it publishes, with the state message's stamp, three
geometry_msgs/PointStamped in ``site_frame``: ``topics.grade_tip``, ``grade_left``,
``grade_right`` for the middle and the two ends of the cutting edge, ``point.x``/``point.y`` =
the point's easting and northing, ``point.z`` = its height above the surface vertically below it
(m, + above = cut, - below = fill). A point outside the surface gets no message; the status,
``topics.grade_status`` (diagnostic_msgs/DiagnosticArray, transient local: a late subscriber gets
the latest), says per point OK (on the surface), WARN (outside the surface) or ERROR (no site
pose), and is published whenever it changes.
"""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from manipulator_kinematics.codec.packed import PackedMessage
from manipulator_kinematics.landxml import Tin, read_landxml
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes.site_pose import SITE_POSE, SitePoseInput
from manipulator_kinematics.schema import Schema, Text
from manipulator_kinematics.site import cutting_edge

#: The ``design_surface`` settings of a forward node.
DESIGN_SURFACE: Schema = {
    "file": Text(doc="LandXML 1.2 file of the design TIN (read at start-up); empty: none"),
    "surface": Text(doc="name of the Surface in the file; empty: the file's only surface"),
    **SITE_POSE,
}
#: Its topics (the forward node's ``topics``).
GRADE_TOPICS: Schema = {
    "site_pose": Text(
        empty=False, doc="input: geometry_msgs/PoseStamped, base_link in the site frame (GNSS)"
    ),
    "grade_tip": Text(
        empty=False, doc="output: geometry_msgs/PointStamped, tip x, y and height above the TIN"
    ),
    "grade_left": Text(empty=False, doc="output: geometry_msgs/PointStamped, left end of the cutting edge"),
    "grade_right": Text(empty=False, doc="output: geometry_msgs/PointStamped, right end of the cutting edge"),
    "grade_status": Text(empty=False, doc="output: diagnostic_msgs/DiagnosticArray, inside/outside the TIN"),
}

POINTS = ("tip", "left", "right")
_FIELDS = ("header.stamp", "point")
_OK, _OUTSIDE, _NO_POSE = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
_TEXT = {_OK: "on the design surface", _OUTSIDE: "outside the design surface", _NO_POSE: "no site pose"}


class SurfaceGrade:
    """Publishers, site pose and TIN of the surface grade outputs of one node."""

    def __init__(
        self,
        node: Node,
        settings: dict[str, Any],
        topics: dict[str, str],
        width: float,
        qos: QoSProfile,
        log: ThrottledLog,
    ) -> None:
        self.surface: Tin = read_landxml(settings["file"], settings["surface"])
        self.frame = settings["site_frame"]
        self.width = width
        self.log = log
        self.site = SitePoseInput(node, settings, topics["site_pose"], qos, log)
        header = Header(frame_id=self.frame)
        self.messages = [PackedMessage(PointStamped(header=header), _FIELDS) for _ in POINTS]
        self.publishers = [node.create_publisher(PointStamped, topics[f"grade_{p}"], qos) for p in POINTS]
        latched = QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        self.status_pub = node.create_publisher(DiagnosticArray, topics["grade_status"], latched)
        self.status: tuple[int, ...] | None = None
        self.clock = node.get_clock()
        node.get_logger().info(
            f"design surface {self.surface.name!r}: {len(self.surface.faces)} triangles from "
            f"{settings['file']} in frame {self.frame!r}; site pose {self.site.describe()}"
        )

    def values(self, stamp_ns: int, theta1: float, tip: list[float]) -> list[list[float] | None]:
        """[x, y, height] (site frame) of tip, left and right end of the cutting edge, None where
        outside the surface or without a site pose (the status says which)."""
        pose, why = self.site.at(stamp_ns)
        if pose is None:
            if self.site.pose is not None:  # stale (none yet: the status says so, once)
                self.log("warning", f"no grade: {why}")
            self.report((_NO_POSE,) * 3)
            return [None] * 3
        points = pose.apply(cutting_edge(tip, theta1, self.width))
        heights = self.surface.heights(points)
        self.report(tuple(_OK if inside else _OUTSIDE for inside in heights.inside.tolist()))
        return [
            [x, y, h] if inside else None
            for (x, y, _), h, inside in zip(
                points.tolist(), heights.height.tolist(), heights.inside.tolist(), strict=True
            )
        ]

    def publish(self, sec_nanosec: tuple[int, int], values: list[list[float] | None]) -> None:
        for message, publisher, value in zip(self.messages, self.publishers, values, strict=True):
            if value is not None:
                publisher.publish(message.pack((*sec_nanosec, *value)))

    def report(self, status: tuple[int, ...]) -> None:
        if status == self.status:
            return
        self.status = status
        outside = [p for p, s in zip(POINTS, status, strict=True) if s != _OK]
        if outside:
            self.log("warning", f"no grade for {', '.join(outside)}: {_TEXT[max(status)]}")
        self.status_pub.publish(
            DiagnosticArray(
                header=Header(stamp=self.clock.now().to_msg(), frame_id=self.frame),
                status=[
                    DiagnosticStatus(
                        level=s, name=f"grade {p}", message=_TEXT[s], hardware_id=self.surface.name
                    )
                    for p, s in zip(POINTS, status, strict=True)
                ],
            )
        )
