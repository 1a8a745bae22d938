"""Avoidance zones in a node: the :class:`~manipulator_kinematics.zone_guard.ZoneGuard` of its zone
file and the clearance topic (docs/zones.md, "Monitor topic").

The topic is a ``diagnostic_msgs/DiagnosticArray``: one DiagnosticStatus per zone, in file order,
``name`` = the zone, ``message`` = the monitored point nearest to it, ``level`` OK (clear), WARN
(this zone slows or stops the command) or ERROR (a point inside: a transgression), and the values
``clearance`` (m, the point's clearance: distance from the zone grown by its margin, < 0 inside),
``point``, ``kind``, ``margin`` and ``scale`` (the command's zone factor, the same in every
status). A site-frame zone while the node has no site pose is STALE, ``message`` "no site pose",
``clearance`` "n/a" (not a transgression: it is not known). Chosen because it carries a name
per number (the zone and its point), every ROS 2 tool reads it (``ros2 topic echo``,
rqt_runtime_monitor, the recorder and ``mk_evaluate``), and the package's status outputs are
already DiagnosticArrays; a Float64MultiArray would need its labels in a layout no tool shows.

The time a command may act (the guard's period) is at least the set one (``zones_period``) and
at least what the loop shows, and the command in force goes on while the new one is on its way
(:class:`~manipulator_kinematics.zone_guard.CommandTimes`): on a loaded machine, whose commands
come late, the approach is slower, not deeper.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from manipulator_kinematics.zone_guard import CommandTimes, Verdict, ZoneGuard
from manipulator_kinematics.zones import Check, Surface


def clearance_message(stamp: Time, hardware_id: str, guard: ZoneGuard, check: Check) -> DiagnosticArray:
    """The clearance topic's message for one check (module docstring)."""
    statuses = []
    for zone in guard.zones:
        clearance, point = check.clearance[zone.name]
        # -inf only for a site-frame zone checked without a site pose (Monitor.check).
        blind = clearance == -math.inf
        level = (
            DiagnosticStatus.STALE
            if blind
            else DiagnosticStatus.ERROR
            if clearance < 0.0
            else DiagnosticStatus.WARN
            if zone.name == check.zone and check.scale < 1.0
            else DiagnosticStatus.OK
        )
        # Never a NaN or an inf as a number: a zone no point is over (a TIN's footprint) is "inf".
        values = {
            "clearance": "n/a" if blind else f"{clearance:.6g}",
            "point": point,
            "kind": zone.kind,
            "margin": f"{zone.margin:.6g}",
            "scale": f"{check.scale:.6g}",
        }
        statuses.append(
            DiagnosticStatus(
                level=level,
                name=zone.name,
                message="no site pose" if blind else point,
                hardware_id=hardware_id,
                values=[KeyValue(key=k, value=v) for k, v in values.items()],
            )
        )
    return DiagnosticArray(header=Header(stamp=stamp), status=statuses)


class ZoneOutput:
    """A node's zones: ``guard`` (the check) and the clearance publisher; call it per command."""

    def __init__(self, node: Node, guard: ZoneGuard, topic: str, qos_depth: int, hardware_id: str) -> None:
        self.node, self.guard, self.hardware_id = node, guard, hardware_id
        self.times = CommandTimes()
        self.publisher = node.create_publisher(
            DiagnosticArray, topic, QoSProfile(depth=qos_depth, reliability=ReliabilityPolicy.RELIABLE)
        )

    @classmethod
    def of(
        cls,
        node: Node,
        file: str,
        points: Sequence[str],
        decelerations: Sequence[float],
        period: float,
        topic: str,
        qos_depth: int,
        hardware_id: str,
        read_surface: Callable[[str, str], Surface] | None = None,
        site_pose: bool = False,
        lag: float = 0.0,
    ) -> ZoneOutput | None:
        """The zones of the node's ``zones_file`` setting (None when it is ""); ConfigError naming
        the setting and the zone file's key when the file is malformed, or has a site-frame zone
        where the node has no site pose (``site_pose`` false)."""
        if not file:
            return None
        guard = ZoneGuard.from_file(
            file, points, decelerations, period, read_surface, site_pose=site_pose, lag=lag
        )
        node.get_logger().info(
            f"{len(guard.zones)} avoidance zones from {file} ({', '.join(z.name for z in guard.zones)}), "
            f"{len(points)} monitored points; clearances on {topic}"
        )
        return cls(node, guard, topic, qos_depth, hardware_id)

    def __call__(
        self,
        stamp: Time,
        positions: np.ndarray,
        velocities: np.ndarray,
        accelerations: np.ndarray | None,
        rates: np.ndarray,
        sampled_ns: int | None = None,
        site: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> Verdict:
        """The verdict on a command (:meth:`ZoneGuard.check`) computed from the state sampled at
        ``sampled_ns`` (its stamp, ns; default ``stamp``'s), for the time it may act (module
        docstring); its clearances published with ``stamp``. ``site``: the site pose (R, t) of
        site-frame zones (p_site = R p + t). ``positions``, ``velocities``, ``accelerations``:
        the monitored points' (:meth:`ZoneGuard.check`; accelerations None: straight paths)."""
        now = self.node.get_clock().now().nanoseconds
        sampled = stamp.sec * 1_000_000_000 + stamp.nanosec if sampled_ns is None else sampled_ns
        period, delay = self.times(now * 1e-9, sampled * 1e-9)
        verdict = self.guard.check(
            positions, velocities, rates, site, period=period, accelerations=accelerations, delay=delay
        )
        self.publisher.publish(clearance_message(stamp, self.hardware_id, self.guard, verdict.check))
        return verdict

    def watch(
        self, stamp: Time, positions: np.ndarray, site: tuple[np.ndarray, np.ndarray] | None = None
    ) -> None:
        """Publish the clearances of the machine standing (no command in force)."""
        self.publisher.publish(
            clearance_message(stamp, self.hardware_id, self.guard, self.guard.watch(positions, site))
        )


__all__ = ["ZoneOutput", "clearance_message"]
