"""Planar pieces shared by the machines (numpy only, no rclpy).

* :func:`two_link_ik` / :func:`two_link_fk`: the planar two-link (2R) arm that every machine of
  the package reduces to at some step (SCARA upper arm/forearm about a rail position, the last two
  pump-boom sections, joints 2-3 of the tool changer, the palletizer's lower/upper arm).
* :func:`wrap_angle`, and yaw <-> quaternion for orientations about the z axis of a REP 103 frame
  (x forward, y left, z up; the plane of a planar arm is the x-y plane).

Conventions of the two-link arm: the shoulder is at the origin; theta1 is the first link's angle
from +x, theta2 the second link's angle relative to the first (counter-clockwise positive); the
tip is l1 (cos t1, sin t1) + l2 (cos(t1 + t2), sin(t1 + t2)). Branch 0 has theta2 >= 0, branch 1
theta2 <= 0 (law of cosines: cos t2 = (r^2 - l1^2 - l2^2) / (2 l1 l2)).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike

#: Branch index of :func:`two_link_ik` with theta2 >= 0 (elbow bent counter-clockwise).
ELBOW_POSITIVE = 0
#: Branch index with theta2 <= 0.
ELBOW_NEGATIVE = 1


class Reach(IntEnum):
    """Why a planar two-link target can or cannot be reached."""

    REACHABLE = 0
    TOO_FAR = 1  # r > l1 + l2
    TOO_CLOSE = 2  # r < |l1 - l2|
    INVALID = 3  # non-finite target


@dataclass(frozen=True)
class TwoLinkSolution:
    """Both elbow branches of a planar two-link IK; arrays have the target's leading shape."""

    theta1: np.ndarray  # (..., 2): [branch 0 (theta2 >= 0), branch 1 (theta2 <= 0)], NaN if not reachable
    theta2: np.ndarray  # (..., 2)
    reach: np.ndarray  # (...,) Reach values
    distance: np.ndarray  # (...,) r = |target|
    l1: float
    l2: float

    @property
    def reachable(self) -> np.ndarray:
        return self.reach == Reach.REACHABLE

    def reason(self, index: tuple[int, ...] | int = ()) -> str:
        """Human-readable reachability of one target (``index`` into the batch)."""
        reach, r = Reach(int(self.reach[index])), float(self.distance[index])
        if reach is Reach.TOO_FAR:
            return f"target at r = {r:.6g} m is beyond the reach l1 + l2 = {self.l1 + self.l2:.6g} m"
        if reach is Reach.TOO_CLOSE:
            inner = abs(self.l1 - self.l2)
            return f"target at r = {r:.6g} m is inside the inner radius |l1 - l2| = {inner:.6g} m"
        if reach is Reach.INVALID:
            return "target is not finite"
        return f"reachable (r = {r:.6g} m)"


def wrap_angle(angle: ArrayLike) -> np.ndarray:
    """Angle(s) wrapped to [-pi, pi)."""
    return (np.asarray(angle, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi


def two_link_fk(theta1: ArrayLike, theta2: ArrayLike, l1: float, l2: float) -> np.ndarray:
    """Tip position (..., 2) of the planar two-link arm."""
    theta1 = np.asarray(theta1, dtype=float)
    theta12 = theta1 + np.asarray(theta2, dtype=float)
    x = l1 * np.cos(theta1) + l2 * np.cos(theta12)
    y = l1 * np.sin(theta1) + l2 * np.sin(theta12)
    return np.stack([x, y], axis=-1)


def two_link_ik(x: ArrayLike, y: ArrayLike, l1: float, l2: float, tol: float = 1e-12) -> TwoLinkSolution:
    """Both elbow branches reaching (x, y) from a shoulder at the origin, vectorised.

    ``tol`` (m) lets a target just outside the annulus |l1 - l2| <= r <= l1 + l2 through (by
    round-off) as the stretched or folded arm. A target at the shoulder with l1 == l2 has any
    theta1; it returns theta1 = 0.
    """
    if not (l1 > 0.0 and l2 > 0.0):
        raise ValueError(f"link lengths must be > 0, got l1 = {l1}, l2 = {l2}")
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    r = np.hypot(x, y)
    reach = np.full(r.shape, Reach.REACHABLE, dtype=np.int8)
    reach[r > l1 + l2 + tol] = Reach.TOO_FAR
    reach[r < abs(l1 - l2) - tol] = Reach.TOO_CLOSE
    reach[~np.isfinite(r)] = Reach.INVALID
    ok = reach == Reach.REACHABLE
    cos2 = np.clip((r * r - l1 * l1 - l2 * l2) / (2.0 * l1 * l2), -1.0, 1.0)
    t2 = np.where(ok, np.arccos(cos2), np.nan)
    theta2 = np.stack([t2, -t2], axis=-1)
    theta1 = np.arctan2(y, x)[..., None] - np.arctan2(l2 * np.sin(theta2), l1 + l2 * np.cos(theta2))
    return TwoLinkSolution(theta1=theta1, theta2=theta2, reach=reach, distance=r, l1=float(l1), l2=float(l2))


def yaw_quaternion(yaw: ArrayLike) -> np.ndarray:
    """Quaternion(s) (..., 4) as [x, y, z, w] of a rotation by ``yaw`` about +z."""
    half = 0.5 * np.asarray(yaw, dtype=float)
    zero = np.zeros_like(half)
    return np.stack([zero, zero, np.sin(half), np.cos(half)], axis=-1)


def quaternion_yaw(quaternion: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(yaw, tilt) of quaternion(s) [x, y, z, w] (normalised here; zero norm gives NaN).

    yaw is the heading of the rotated x axis projected on the x-y plane; tilt is the angle
    between the rotated z axis and +z, 0 for a pure rotation about z.
    """
    q = np.asarray(quaternion, dtype=float)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        x, y, z, w = np.moveaxis(q / np.where(norm > 0.0, norm, np.nan), -1, 0)
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    tilt = np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0))
    return yaw, tilt
