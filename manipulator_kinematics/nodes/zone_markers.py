"""Avoidance zones and monitored points as visualization_msgs markers (``machine_markers`` with
``zones_file``; docs/zones.md).

Zones in the base frame, each in namespace ``zone`` (its boundary, red, translucent) and
``zone_margin`` (the boundary grown by the margin, orange, fainter): ceilings and floors as thin
squares ``EXTENT`` m wide about the machine, walls as thin vertical rectangles through their point
across their normal, boxes as boxes, swing sectors as a fan on the ground plane z = 0 out to
``EXTENT`` / 2, TINs as their triangles (margin: the same triangles shifted up or down). A zone
in the site frame is not drawn (the markers have no site pose): the node says so once at start.
The monitored points are one SPHERE_LIST (namespace ``monitored_point``), each coloured by its
smallest clearance: green beyond ``NEAR`` m, orange within it, red inside a zone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from manipulator_kinematics.zones import Zone

#: Width of a drawn ceiling, floor or wall (m): the planes themselves have no end.
EXTENT = 30.0
#: Thickness of a drawn plane (m).
THIN = 0.02
#: A point this close to a zone (m, clearance) is drawn orange.
NEAR = 0.5
#: Drawn triangles of a TIN at the most (a display needs no more).
MAX_TRIANGLES = 20_000
BOUNDARY, MARGIN = ColorRGBA(r=0.9, g=0.1, b=0.1, a=0.35), ColorRGBA(r=1.0, g=0.55, b=0.0, a=0.15)
CLEAR, CLOSE, INSIDE = (
    ColorRGBA(r=0.1, g=0.8, b=0.2, a=1.0),
    ColorRGBA(r=1.0, g=0.55, b=0.0, a=1.0),
    ColorRGBA(r=0.9, g=0.1, b=0.1, a=1.0),
)


def _marker(kind: int, ns: str, index: int, color: ColorRGBA) -> Marker:
    m = Marker(ns=ns, id=index, type=kind, action=Marker.ADD, color=color)
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 1.0
    return m


def _box(m: Marker, centre: Sequence[float], size: Sequence[float], yaw: float = 0.0) -> Marker:
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in centre)
    m.pose.orientation.z, m.pose.orientation.w = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in size)
    return m


def _triangles(m: Marker, corners: np.ndarray) -> Marker:
    """``corners`` (T, 3, 3) as a TRIANGLE_LIST."""
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in corners.reshape(-1, 3)]
    return m


def _shape(zone: Zone, grow: float, m: Marker) -> Marker:
    """``zone`` grown by ``grow`` (0: its boundary; its margin: the margin's) into ``m``."""
    v = zone.values
    if zone.kind in ("ceiling", "floor"):
        height = v["height"] + (-grow if zone.kind == "ceiling" else grow)
        return _box(m, (0.0, 0.0, height), (EXTENT, EXTENT, THIN))
    if zone.kind == "wall":
        normal = np.asarray(v["normal"], float) / math.hypot(*v["normal"])
        point = np.asarray(v["point"], float) - grow * normal
        return _box(m, (*point, 0.0), (THIN, EXTENT, EXTENT), math.atan2(normal[1], normal[0]))
    if zone.kind == "box":
        lo, hi = np.asarray(v["min"], float) - grow, np.asarray(v["max"], float) + grow
        return _box(m, 0.5 * (lo + hi), hi - lo)
    m.type = Marker.TRIANGLE_LIST
    if zone.kind == "sector":
        width = np.mod(v["to"] - v["from"], 2 * np.pi)
        steps = max(2, int(width / 0.05))
        a = v["from"] + np.linspace(0.0, width, steps + 1)
        rim = np.stack((np.cos(a), np.sin(a), np.zeros_like(a)), axis=-1) * 0.5 * EXTENT
        return _triangles(m, np.stack((np.zeros_like(rim[1:]), rim[:-1], rim[1:]), axis=1))
    tin = zone.surface
    corners = np.asarray(tin.vertices, float)[np.asarray(tin.faces)[:MAX_TRIANGLES]]  # type: ignore[union-attr]
    return _triangles(m, corners + [0.0, 0.0, grow if v["side"] == "below" else -grow])


def zone_markers(zones: Sequence[Zone]) -> list[Marker]:
    """The base-frame zones' markers (module docstring); headers are the caller's to set."""
    out = []
    for i, zone in enumerate(z for z in zones if z.frame == "base"):
        out.append(_shape(zone, 0.0, _marker(Marker.CUBE, "zone", i, BOUNDARY)))
        if zone.margin > 0.0:
            out.append(_shape(zone, zone.margin, _marker(Marker.CUBE, "zone_margin", i, MARGIN)))
    return out


def point_marker(positions: np.ndarray, clearance: np.ndarray, diameter: float) -> Marker:
    """The monitored points (P, 3) as one SPHERE_LIST, coloured by their clearances (P,)."""
    m = _marker(Marker.SPHERE_LIST, "monitored_point", 0, CLEAR)
    m.scale.x = m.scale.y = m.scale.z = diameter
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in positions]
    m.colors = [INSIDE if c < 0.0 else CLOSE if c < NEAR else CLEAR for c in clearance.tolist()]
    return m


def stamped(markers: list[Marker], stamp: Time, frame_id: str) -> list[Marker]:
    """``markers`` with one header."""
    header = Header(stamp=stamp, frame_id=frame_id)
    for m in markers:
        m.header = header
    return markers


__all__ = ["point_marker", "stamped", "zone_markers"]
