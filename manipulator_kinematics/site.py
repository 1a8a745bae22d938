"""The machine in the site frame, for grade against a design surface (numpy, no rclpy): any
machine's tool point and the ends of its cutting edge, and the machine's base frame placed in the
site frame (REP 105 style, ENU: x easting, y northing, z elevation, metres). The excavator's
grade (:mod:`excavator_kinematics.grade.design_surface`) and the hydraulic family's forward node
(:mod:`manipulator_kinematics.nodes.surface_grade`) use them.

* :func:`cutting_edge` gives the tip and the left and right ends of the cutting edge (tool width
  w from the machine file): tip +- w/2 along the boom-plane normal (-sin theta1, cos theta1, 0).
* :class:`SitePose` places the machine (base_link) in the site frame: p_site = R p_base + t.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from manipulator_kinematics.model import level_rotation

__all__ = ["SitePose", "cutting_edge"]


def cutting_edge(tip: ArrayLike, theta1: ArrayLike, width: float) -> np.ndarray:
    """Tip, left and right end of the cutting edge (..., 3, 3) in the base frame.

    ``tip`` (..., 3) is Q[:3] (the middle of the cutting edge, eq. 3), ``theta1`` (...,) the swing;
    the edge lies along the boom-plane normal (-sin theta1, cos theta1, 0) (the tool
    frame's y axis: docs/excavator.md, docs/hydraulic_family.md), left = +y.
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
        (a machine's IMU: the excavator's ``excavator_kinematics.sensing.imu.base_up``). Position and heading
        (of base x projected onto the horizontal) are kept: R = Rz(psi) L(up), L the rotation into
        the level frame (:func:`manipulator_kinematics.model.level_rotation`: base_link's origin
        and heading, z up), which the heading psi turns into the site frame. Equal to this pose
        when ``up`` is its own up, R^T e_z."""
        x = self.rotation[:, 0]
        psi = np.arctan2(x[1], x[0])
        c, s = np.cos(psi), np.sin(psi)
        heading = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return SitePose(heading @ level_rotation(up), self.translation)
