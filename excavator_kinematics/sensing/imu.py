"""Joint angles and cylinder lengths from inclination sensors (IMUs) (numpy, no rclpy).

A retrofit machine carries an IMU on the upper structure (cab), the boom, the arm and the bucket
linkage (the H-link, "dogbone", or the bucket itself). Each one tells which way is up in its own
frame; the mounting rotations of the machine file (``excavator.imu``) turn that into the frame of
its body. Every body of the arm turns about one axis, the boom-plane normal y (docs/excavator.md:
counter-clockwise in the side view = about -y), so for a body's up vector u = (ux, uy, uz) the
*side angle* ``a = atan2(ux, uz)`` grows by exactly the body's turn about -y, whatever the
machine's roll and pitch (uy, the sideways tilt, never enters). Relative angles are differences
of side angles, in which the tilt of the cab cancels exactly (the paper's theta are relative to
the upper structure, eq. 3):

    theta2 = a_boom - a_cab,   theta3 = a_arm - a_boom,   theta4 = a_bucket - a_arm

and with the sensor on the H-link, theta4 follows from the H-link's angle psi = a_h - a_arm in the
arm frame through the bucket four-bar (arm, side link, H-link, bucket; eq. 2 inverted in closed
form, :meth:`ImuArm.theta4_from_h_link`). Lengths then come from
:meth:`~excavator_kinematics.core.kinematics.Excavator.cylinder_lengths` (inverse of eqs. 1-2).

Rates from the gyros: with omega the body's angular velocity in its frame, a world-fixed u obeys
du/dt = u x omega, so

    a_dot = -omega_y + uy (ux omega_x + uz omega_z) / (ux^2 + uz^2)

(just -omega_y on a level machine; the second term removes the swing's share on a tilted one),
theta_dot are the same differences of a_dot, and the cylinder rates are theta_dot / k (eq. 7,
:meth:`~excavator_kinematics.core.kinematics.Excavator.k_entries`).

Up in a sensor's frame: from the sensor's orientation when its driver provides one
(sensor_msgs/Imu, orientation_covariance[0] != -1; up = the third row of R(q), the yaw does not
matter), else from gravity: at rest the accelerometer reads f = +g up, so up = f / |f|. Moving
bodies add their own acceleration to f, so :class:`TiltFilter` is a complementary filter: the
gyro carries u between samples (du/dt = u x omega), and u is pulled toward f / |f| with time
constant tau: weight 1 - exp(-dt / tau) per sample (tau = 0: f / |f| as it is, for sensors at
rest or already filtered).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from excavator_kinematics.core.kinematics import Excavator, StrokeError
from manipulator_kinematics.model import level_rotation  # noqa: F401 - re-exported (the level frame; shared with bag visuals)

#: The four sensors, in the order of every (..., 4, 3) array here.
SENSORS = ("cab", "boom", "arm", "bucket_linkage")
GRAVITY = 9.80665

#: Largest angle (rad) between a sensor's boom-plane normal (body y) and the horizontal. The side
#: angle atan2(ux, uz) is undefined when y points up (ux = uz = 0), and the gyro's share in
#: :func:`side_rate` grows as |uy| / (ux^2 + uz^2): at 60 deg a noise of 0.01 rad/s becomes at most
#: 0.035 rad/s, near 90 deg it became cylinder rates of 1.6e7 m/s (issue 29). No excavator works
#: rolled that far (they tip over near 30 deg), so such a set is refused, not bounded.
MAX_SIDEWAYS_TILT = math.radians(60.0)


class ImuJoints(NamedTuple):
    """theta2..theta4 and their rates (..., 3); cylinder lengths and rates (..., 3); world up in
    the upper structure's frame (..., 3), the machine's tilt (:func:`level_rotation`)."""

    theta: np.ndarray
    theta_dot: np.ndarray
    lengths: np.ndarray
    rates: np.ndarray
    up_cab: np.ndarray


def base_up(up_cab: ArrayLike, theta1: ArrayLike) -> np.ndarray:
    """World up in base_link (..., 3) from up in the upper structure's frame and the swing: the
    upper structure is base_link turned by theta1 about z, so u_base = Rz(theta1) u_upper."""
    u = np.asarray(up_cab, dtype=float)
    c, s = np.cos(theta1), np.sin(theta1)
    x, y = c * u[..., 0] - s * u[..., 1], s * u[..., 0] + c * u[..., 1]
    return np.stack([x, y, np.broadcast_to(u[..., 2], x.shape)], axis=-1)


def up_from_orientation(quaternion_xyzw: ArrayLike) -> np.ndarray:
    """World up (..., 3) in the frame of a sensor whose orientation is q (..., 4) [x, y, z, w]:
    the third row of R(q) = R^T e_z."""
    q = np.asarray(quaternion_xyzw, dtype=float)
    x, y, z, w = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack([2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)], axis=-1)


def up_from_acceleration(specific_force: ArrayLike) -> np.ndarray:
    """World up (..., 3) from an accelerometer at rest: f / |f| (f = +g up)."""
    f = np.asarray(specific_force, dtype=float)
    return f / np.linalg.norm(f, axis=-1, keepdims=True)


def side_angle(up: np.ndarray) -> np.ndarray:
    """a = atan2(ux, uz) (...,) of up vectors in body frames: the body's turn about -y."""
    return np.arctan2(up[..., 0], up[..., 2])


def side_rate(up: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """da/dt (...,) for a world-fixed up vector and the body's angular velocity, both in its frame."""
    ux, uy, uz = np.moveaxis(up, -1, 0)
    wx, wy, wz = np.moveaxis(omega, -1, 0)
    return -wy + uy * (ux * wx + uz * wz) / (ux * ux + uz * uz)


class TiltFilter:
    """Complementary filter of the up vectors of several sensors (n, 3) from gyro and accelerometer.

    Each :meth:`update` turns the estimate by the gyro over dt (first order: u + (u x omega) dt),
    then moves it toward f / |f| by 1 - exp(-dt / tau), then normalises. The first sample (or a
    restart) takes f / |f| as it is.
    """

    def __init__(self, time_constant: float) -> None:
        self.time_constant = float(time_constant)
        self.up: np.ndarray | None = None

    def update(self, dt: float, omega: ArrayLike, specific_force: ArrayLike) -> np.ndarray:
        measured = up_from_acceleration(specific_force)
        if self.up is None or self.time_constant == 0.0 or not dt > 0.0:
            self.up = measured
            return measured
        predicted = self.up + np.cross(self.up, np.asarray(omega, dtype=float)) * dt
        weight = 1.0 - math.exp(-dt / self.time_constant)
        up = predicted + weight * (measured - predicted)
        self.up = up / np.linalg.norm(up, axis=-1, keepdims=True)
        return self.up


class ImuArm:
    """The arm's joints from the four sensors' up vectors and angular velocities (sensor frames)."""

    def __init__(self, exc: Excavator, imu: Mapping[str, Any] | None = None) -> None:
        """``imu``: the machine file's ``excavator.imu`` section (default: the machine's own)."""
        imu = exc.description.imu if imu is None else imu
        self.exc = exc
        self.on_h_link = imu["bucket_linkage"]["body"] == "h_link"
        #: (4, 3, 3): each sensor's frame in its body's frame, R_body_sensor.
        self.mounting = np.stack(
            [Rotation.from_euler("xyz", imu[s]["rotation_rpy"]).as_matrix() for s in SENSORS]
        )
        g = exc.description
        self._pivot = np.array(g.side_link_pivot)  # arm frame
        self._bucket_pin = np.array([g.arm_length, 0.0])
        self._side, self._h_link = g.side_link_length, g.h_link_length
        h_pin = np.array(g.h_link_pin)  # bucket frame
        self._h_radius, self._h_phase = float(np.hypot(*h_pin)), math.atan2(h_pin[1], h_pin[0])
        self._h_orientation = g.orientations[3]
        # The joints at the reference state: the branch every reading is brought to (joints()).
        self._reference = exc.joint_angles(exc.limits.reference[1:])

    def joints(self, up: ArrayLike, omega: ArrayLike) -> ImuJoints:
        """theta2..4, rates, cylinder lengths and rates from up vectors and angular velocities
        (..., 4, 3) in the sensors' frames (order :data:`SENSORS`). StrokeError when the angles
        are out of the machine's reach."""
        up_body = np.einsum("sij,...sj->...si", self.mounting, np.asarray(up, dtype=float))
        omega_body = np.einsum("sij,...sj->...si", self.mounting, np.asarray(omega, dtype=float))
        sideways = np.arcsin(np.clip(np.abs(up_body[..., 1]), 0.0, 1.0))
        if not np.all(sideways <= MAX_SIDEWAYS_TILT):
            worst = np.unravel_index(
                np.argmax(np.where(np.isnan(sideways), np.inf, sideways)), sideways.shape
            )
            raise StrokeError(
                f"imu {SENSORS[worst[-1]]}: its boom plane is tilted {math.degrees(sideways[worst]):.1f} deg "
                f"sideways (more than {math.degrees(MAX_SIDEWAYS_TILT):g}): the side angle and its rate are "
                "ill-conditioned there (gyro noise amplified as |uy| / (ux^2 + uz^2))"
            )
        a, a_dot = side_angle(up_body), side_rate(up_body, omega_body)
        relative = np.diff(a, axis=-1)  # boom - cab, arm - boom, linkage - arm
        relative_dot = np.diff(a_dot, axis=-1)
        theta2, theta3 = relative[..., 0], relative[..., 1]
        if self.on_h_link:
            theta4, theta4_dot = self.theta4_from_h_link(relative[..., 2], relative_dot[..., 2])
        else:
            theta4, theta4_dot = relative[..., 2], relative_dot[..., 2]
        # Side angles are in (-pi, pi]: bring the joints to the branch the model uses (eqs. 1-2).
        theta = np.stack([theta2, theta3, theta4], axis=-1)
        theta = self._reference + (theta - self._reference + np.pi) % (2.0 * np.pi) - np.pi
        theta_dot = np.stack([relative_dot[..., 0], relative_dot[..., 1], theta4_dot], axis=-1)
        lengths = self.exc.cylinder_lengths(theta.reshape(-1, 3)).reshape(theta.shape)
        k, _ = self.exc.k_entries(lengths.reshape(-1, 3))
        return ImuJoints(theta, theta_dot, lengths, theta_dot / k.reshape(theta.shape), up_body[..., 0, :])

    def theta4_from_h_link(self, psi: np.ndarray, psi_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """theta4 and its rate from the H-link's angle psi in the arm frame (R -> H) and its rate.

        H = R + h u (u = (cos psi, sin psi)) with R on the side link's circle about the pivot P
        and H on the bucket's circle about the bucket pin B: R is where the circle |R - P| = s
        meets |R - (B - h u)| = b, on the branch of the forward model (the sign of
        cross(R - B, H - B) is the H-link's orientation). The rate from the four-bar's velocity
        loop omega_b perp(H - B) - omega_s perp(R - P) = psi_dot perp(H - R) (Cramer's rule).
        """
        u = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
        centre = self._bucket_pin - self._h_link * u  # R's second circle, radius b
        s, b = self._side, self._h_radius
        between = centre - self._pivot
        d = np.linalg.norm(between, axis=-1)
        along = (d * d + s * s - b * b) / (2.0 * d)
        across_sq = s * s - along * along
        if np.any(across_sq < 0.0) or not np.all(np.isfinite(across_sq)):
            raise StrokeError("bucket_linkage IMU: H-link angle the bucket linkage cannot take")
        e = between / d[..., None]
        normal = np.stack([-e[..., 1], e[..., 0]], axis=-1)
        foot = self._pivot + along[..., None] * e
        candidates = [foot + sign * np.sqrt(across_sq)[..., None] * normal for sign in (1.0, -1.0)]
        H = [R + self._h_link * u for R in candidates]
        branch = [
            np.sign(_cross(R - self._bucket_pin, h - self._bucket_pin)) == self._h_orientation
            for R, h in zip(candidates, H, strict=True)
        ]
        R = np.where(branch[0][..., None], candidates[0], candidates[1])
        H = np.where(branch[0][..., None], H[0], H[1])
        to_h, to_r, coupler = H - self._bucket_pin, R - self._pivot, H - R
        theta4 = np.arctan2(to_h[..., 1], to_h[..., 0]) - self._h_phase
        # [perp(H - B), -perp(R - P)] [omega_b, omega_s]^T = psi_dot perp(H - R); perp(x, y) = (-y, x).
        det = _cross(to_r, to_h)  # det of the 2 x 2 matrix
        omega_b = psi_dot * _cross(to_r, coupler) / det
        return theta4, omega_b


def _cross(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]


def simulated_readings(
    arm: ImuArm,
    D: ArrayLike,
    D_dot: ArrayLike,
    tilt_rpy: ArrayLike,
    rng: np.random.Generator | None = None,
    orientation_noise: float = 0.0,
    gyro_noise: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the four IMUs of ``arm`` read at states D (N, 4) moving at D_dot (N, 4), the machine
    standing still at roll, pitch, yaw ``tilt_rpy``: orientations [x, y, z, w] (N, 4, 4), angular
    velocities (N, 4, 3) and specific forces (N, 4, 3, gravity only) in each sensor's frame.

    Body frames as in the module docstring: the upper structure is the tilt times the swing, each
    body turns from it by its side angle about -y (theta2, theta2 + theta3, and theta2..4 for the
    bucket or the H-link's angle for the H-link). Noise, when asked for: a random rotation of
    ``orientation_noise`` rad (normal, per axis) on each orientation and normal gyro noise (rad/s).
    """
    exc = arm.exc
    D, D_dot = np.asarray(D, dtype=float), np.asarray(D_dot, dtype=float)
    n = len(D)
    s = exc.state(D, D_dot)
    theta, theta_dot = s.theta, s.theta_dot
    side = np.zeros((n, 4))
    side_dot = np.zeros((n, 4))
    side[:, 1:] = np.cumsum(theta[:, 1:], axis=1)
    side_dot[:, 1:] = np.cumsum(theta_dot[:, 1:], axis=1)
    if arm.on_h_link:
        pins = exc.pins(D)
        c, si = np.cos(D[:, 0]), np.sin(D[:, 0])
        h = pins["h_link_pin"] - pins["bucket_cylinder_rod"]
        h_angle = np.arctan2(h[:, 2], h[:, 0] * c + h[:, 1] * si)
        psi = h_angle - side[:, 2]
        _, ratio = arm.theta4_from_h_link(psi, np.ones(n))  # d theta4 / d psi
        side[:, 3], side_dot[:, 3] = h_angle, side_dot[:, 2] + theta_dot[:, 3] / ratio
    world_base = Rotation.from_euler("xyz", tilt_rpy)
    upper = world_base * Rotation.from_euler("z", D[:, :1])
    omega_upper = world_base.apply(np.column_stack([np.zeros((n, 2)), D_dot[:, 0]]))
    quaternions, omegas, forces = [], [], []
    for i in range(4):
        body = upper * Rotation.from_euler("y", -side[:, i, None])
        sensor = body * Rotation.from_matrix(arm.mounting[i])
        omega_world = omega_upper + upper.apply(np.column_stack([np.zeros(n), -side_dot[:, i], np.zeros(n)]))
        orientation = sensor
        if orientation_noise > 0.0 and rng is not None:
            orientation = sensor * Rotation.from_rotvec(rng.normal(0.0, orientation_noise, (n, 3)))
        omega = sensor.inv().apply(omega_world)
        if gyro_noise > 0.0 and rng is not None:
            omega = omega + rng.normal(0.0, gyro_noise, (n, 3))
        quaternions.append(orientation.as_quat())
        omegas.append(omega)
        forces.append(sensor.inv().apply(np.tile([0.0, 0.0, GRAVITY], (n, 1))))
    return np.stack(quaternions, axis=1), np.stack(omegas, axis=1), np.stack(forces, axis=1)
