"""Design surfaces for grade control: the cutting edge and the machine's site pose (numpy, no rclpy).

A machine-control display shows the height of the bucket's cutting edge, its middle (the tip Q[:3]
of paper 000's eq. 3) and both corners, above the design surface that civil-design software
exports as a LandXML TIN. Everything here is in the **site frame** (REP 105 style, ENU): x =
easting, y = northing, z = elevation, metres.

* :func:`read_landxml`, :class:`Tin` (the TIN, its point location and heights) and
  :func:`write_landxml` (:mod:`manipulator_kinematics.landxml`), :func:`cutting_edge` (the tip
  and the left and right ends of the cutting edge: tip +- w/2 along the boom-plane normal) and
  :class:`SitePose` (base_link in the site frame: p_site = R p_base + t)
  (:mod:`manipulator_kinematics.site`) are machine-independent (the hydraulic family's grade and
  avoidance zones use them too); they are imported here, where the excavator's code has always
  found them.
"""

from __future__ import annotations

from manipulator_kinematics.landxml import (
    MAX_ELEMENTS,
    MAX_FACES,
    MAX_FILE_BYTES,
    MAX_POINTS,
    SurfaceHeights,
    Tin,
    read_landxml,
    write_landxml,
)
from manipulator_kinematics.site import SitePose, cutting_edge

__all__ = [
    "MAX_ELEMENTS",
    "MAX_FACES",
    "MAX_FILE_BYTES",
    "MAX_POINTS",
    "SitePose",
    "SurfaceHeights",
    "Tin",
    "cutting_edge",
    "read_landxml",
    "write_landxml",
]
