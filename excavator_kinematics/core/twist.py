"""6-D bucket twists (ROS) <-> the four achievable bucket rates Q_dot = [x_dot, y_dot, z_dot, alpha_dot].

The excavator's task coordinates are Q = [x, y, z, alpha] (paper eq. 3): the tip position in the
base frame and the bucket line angle alpha. Its bucket can only turn about two axes: the swing axis
(+z, rate theta1_dot) and the boom-plane normal n (rate alpha_dot). In REP 103 terms the bucket
orientation is a yaw theta1 followed by a rotation of -alpha about +y, so

    omega = theta1_dot * e_z + alpha_dot * n,     n = (sin theta1, -cos theta1, 0).

theta1_dot is not free either: it is the swing rate that moves the tip sideways,
theta1_dot = v_tangential / rho with rho = x cos theta1 + y sin theta1 the signed distance of the
tip from the swing axis (first two rows of eq. 5). A commanded 6-D twist therefore has four
achievable components (the linear velocity and the omega component along n); whatever remains of
omega is the consistency residual. Numpy only, no ROS.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from excavator_kinematics.core.kinematics import bucket_angular_velocity

# Below this distance of the tip from the swing axis (m) the swing rate a sideways tip velocity
# needs is unbounded; the residual then takes theta1_dot = 0 (JC0 is singular there anyway).
MIN_SWING_RADIUS = 1e-6


class TwistSplit(NamedTuple):
    """A 6-D twist split into the achievable rates and what cannot be achieved."""

    q_dot: np.ndarray  # (..., 4) [x_dot, y_dot, z_dot, alpha_dot]
    residual: np.ndarray  # (..., 3) commanded omega minus the omega the achievable part gives (rad/s)


def boom_plane_normal(theta1: np.ndarray | float) -> np.ndarray:
    """Unit axis about which alpha is positive: -(R_z(theta1) e_y) = (sin theta1, -cos theta1, 0)."""
    theta1 = np.asarray(theta1, dtype=float)
    return np.stack((np.sin(theta1), -np.cos(theta1), np.zeros_like(theta1)), axis=-1)


def swing_rate(theta1: np.ndarray | float, tip: np.ndarray, linear: np.ndarray) -> np.ndarray:
    """Swing rate theta1_dot that produces the tip's sideways velocity (rows 1-2 of eq. 5).

    Zero where the tip is within MIN_SWING_RADIUS of the swing axis (no finite rate exists).
    """
    theta1 = np.asarray(theta1, dtype=float)
    tip, linear = np.asarray(tip, dtype=float), np.asarray(linear, dtype=float)
    c, s = np.cos(theta1), np.sin(theta1)
    rho = tip[..., 0] * c + tip[..., 1] * s
    tangential = -linear[..., 0] * s + linear[..., 1] * c
    safe = np.abs(rho) >= MIN_SWING_RADIUS
    return np.where(safe, tangential / np.where(safe, rho, 1.0), 0.0)


def split_twist(
    theta1: np.ndarray | float, tip: np.ndarray, linear: np.ndarray, angular: np.ndarray
) -> TwistSplit:
    """Achievable part Q_dot of a base-frame twist (linear, angular) at the bucket tip, and the
    angular-velocity residual that the excavator cannot produce (inverse of the module's map)."""
    linear, angular = np.asarray(linear, dtype=float), np.asarray(angular, dtype=float)
    alpha_dot = np.sum(angular * boom_plane_normal(theta1), axis=-1)
    achievable = bucket_angular_velocity(theta1, swing_rate(theta1, tip, linear), alpha_dot)
    q_dot = np.concatenate((linear, alpha_dot[..., None]), axis=-1)
    return TwistSplit(q_dot, angular - achievable)


def twist_from_q_dot(
    theta1: np.ndarray | float, tip: np.ndarray, q_dot: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The consistent 6-D twist (linear, angular) of bucket rates Q_dot: zero residual by construction."""
    q_dot = np.asarray(q_dot, dtype=float)
    linear = q_dot[..., :3]
    return linear, bucket_angular_velocity(theta1, swing_rate(theta1, tip, linear), q_dot[..., 3])


def bucket_angles(quaternion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta1, alpha) of a bucket orientation quaternion [x, y, z, w] (inverse of bucket_quaternion).

    alpha is returned in (-pi, pi]; the bucket line angle of a real machine can lie outside that
    range (a curled bucket reaches about -320 deg on the CET200), so compare alphas modulo 2 pi.
    Requires a quaternion of the form yaw-then-pitch, as the forward node publishes.
    """
    x, y, z, w = np.moveaxis(np.asarray(quaternion, dtype=float), -1, 0)
    # R = R_z(theta1) R_y(-alpha): first column (cos t1 cos a, sin t1 cos a, sin a),
    # second column (-sin t1, cos t1, 0).
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r10 = 2.0 * (x * y + z * w)
    r20 = 2.0 * (x * z - y * w)
    r01 = 2.0 * (x * y - z * w)
    r11 = 1.0 - 2.0 * (x * x + z * z)
    theta1 = np.arctan2(-r01, r11)
    alpha = np.arctan2(r20, r00 * np.cos(theta1) + r10 * np.sin(theta1))
    return theta1, alpha
