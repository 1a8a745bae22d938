"""Design surfaces for grade control: the cutting edge and the machine's site pose (numpy, no rclpy).

A machine-control display shows the height of the bucket's cutting edge, its middle (the tip Q[:3]
of paper 000's eq. 3) and both corners, above the design surface that civil-design software
exports as a LandXML TIN. Everything here is in the **site frame** (REP 105 style, ENU): x =
easting, y = northing, z = elevation, metres.

* :func:`read_landxml`, :class:`Tin` (the TIN, its point location and heights) and
  :func:`write_landxml` are machine-independent and live in :mod:`manipulator_kinematics.landxml`
  (the hydraulic family's avoidance zones read TINs too); they are imported here, where the
  excavator's code has always found them.
* :func:`cutting_edge` gives the tip and the left and right ends of the cutting edge (bucket width
  w from the machine file): tip +- w/2 along the boom-plane normal (-sin theta1, cos theta1, 0).
* :class:`SitePose` places the machine (base_link) in the site frame: p_site = R p_base + t.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

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
from manipulator_kinematics.model import level_rotation

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


def cutting_edge(tip: ArrayLike, theta1: ArrayLike, width: float) -> np.ndarray:
    """Tip, left and right end of the cutting edge (..., 3, 3) in the base frame.

    ``tip`` (..., 3) is Q[:3] (the middle of the cutting edge, eq. 3), ``theta1`` (...,) the swing;
    the edge lies along the boom-plane normal (-sin theta1, cos theta1, 0) (docs/excavator.md:
    the bucket frame's y axis), left = +y.
    """
    tip = np.asarray(tip, dtype=float)
    theta1 = np.asarray(theta1, dtype=float)
    half = 0.5 * width * np.stack([-np.sin(theta1), np.cos(theta1), np.zeros_like(theta1)], axis=-1)
    return np.stack([tip, tip + half, tip - half], axis=-2)


@dataclass(frozen=True)
class SitePose:
    """The machine's base_link in the site frame: ``rotation`` (3, 3) and ``translation`` (3,)."""

    rotation: np.ndarray
    translation: np.ndarray

    @classmethod
    def from_quaternion(cls, position: ArrayLike, quaternion_xyzw: ArrayLike) -> SitePose:
        """From a geometry_msgs/Pose: position and unit quaternion [x, y, z, w]."""
        return cls(Rotation.from_quat(quaternion_xyzw).as_matrix(), np.asarray(position, dtype=float))

    @classmethod
    def from_rpy(cls, position: ArrayLike, rpy: ArrayLike) -> SitePose:
        """From roll, pitch, yaw (rad) about the fixed x, y, z axes (REP 103)."""
        return cls(Rotation.from_euler("xyz", rpy).as_matrix(), np.asarray(position, dtype=float))

    def apply(self, points: ArrayLike) -> np.ndarray:
        """Points (..., 3) of the base frame in the site frame; with one rotation per state
        (N, 3, 3) (a tilt measured at each), points (N, k, 3)."""
        return np.asarray(points, dtype=float) @ np.swapaxes(self.rotation, -1, -2) + self.translation

    def levelled(self, up: ArrayLike) -> SitePose:
        """This pose with its roll and pitch from a measured tilt: ``up`` (3,) world up in base_link
        (the machine's IMU, :func:`excavator_kinematics.sensing.imu.base_up`). Position and heading
        (of base x projected onto the horizontal) are kept: R = Rz(psi) L(up), L the rotation into
        the level frame (:func:`manipulator_kinematics.model.level_rotation`: base_link's origin
        and heading, z up), which the heading psi turns into the site frame. Equal to this pose
        when ``up`` is its own up, R^T e_z."""
        x = self.rotation[:, 0]
        psi = np.arctan2(x[1], x[0])
        c, s = np.cos(psi), np.sin(psi)
        heading = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return SitePose(heading @ level_rotation(up), self.translation)
