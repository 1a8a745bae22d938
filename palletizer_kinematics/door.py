"""The paper's door-shaped TCP trajectory P0 -> P1 -> P2 -> P3 -> P4 (section 3.1). numpy only.

Each leg is a straight Cartesian segment sampled at a spacing of at most ``step`` (the shared
:func:`~manipulator_kinematics.trajectory.straight_line`), timed by a rest-to-rest quintic time
law s(t) (the shared :func:`~manipulator_kinematics.trajectory.quintic`, jtraj's polynomial) of
duration T = 15/8 L / v_max, so the TCP speed peaks at ``speed`` in the middle of every leg and
the robot stops at each corner. The time of a sample is s^-1 of its arc length (bisection: s is
monotonic). The flange keeps one orientation (the home yaw by default) and every sample is solved
by the closed-form IK; joint rates come from the Jacobian: [v; 0] = J_(x,y,z,yaw) qdot.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.trajectory import quintic, straight_line
from palletizer_kinematics.kinematics import VARIANTS, Palletizer, axis_from_dh

#: The paper's control points P0..P4 of the TCP, mm converted to m.
DOOR_POINTS = np.array(
    [
        [1.505, 0.0, 1.436],
        [1.150, -0.776, 0.270],
        [1.150, -0.776, 0.793],
        [1.722, 0.590, 0.793],
        [1.722, 0.590, 0.270],
    ]
)
#: Rows of the geometric Jacobian that the robot controls: vx, vy, vz, wz.
_TASK_ROWS = [0, 1, 2, 5]


@dataclass(frozen=True)
class DoorTrajectory:
    """Samples (M of them) of the door trajectory.

    ``t`` (M,) s; ``segment`` (M,) leg index (0 = P0 -> P1); ``position`` (M, 3) TCP, m;
    ``velocity`` (M, 3) TCP, m/s; ``dh`` (M, 4) [theta1, theta2, theta3, theta5]; ``axis`` the
    axis angles (M, 4) of each variant; ``axis_rates`` (M, 4) of the model's variant, rad/s.
    """

    t: np.ndarray
    segment: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    dh: np.ndarray
    axis: dict[str, np.ndarray]
    axis_rates: np.ndarray
    variant: str


def leg_times(length: float, speed: float, arc: np.ndarray) -> tuple[np.ndarray, float]:
    """Times (M,) at which a leg's quintic time law reaches ``arc`` (M,), and the leg's duration."""
    duration = 15.0 / 8.0 * length / speed
    low, high = np.zeros_like(arc), np.full_like(arc, duration)
    for _ in range(64):  # s is monotonic: bisection halves the bracket to below 1e-18 * duration
        middle = 0.5 * (low + high)
        below = quintic([0.0], [length], middle, duration=duration).q[:, 0] < arc
        low, high = np.where(below, middle, low), np.where(below, high, middle)
    # The ends exactly: the leg starts at rest at t = 0 and ends at rest at t = T.
    return np.where(arc <= 0.0, 0.0, np.where(arc >= length, duration, 0.5 * (low + high))), duration


def door_trajectory(
    model: Palletizer,
    points: ArrayLike = DOOR_POINTS,
    *,
    step: float = 0.01,
    speed: float = 1.0,
    yaw: float = 0.0,
) -> DoorTrajectory:
    """Sample, time and solve the polyline through ``points`` (K, 3) (module docstring).

    Raises ValueError naming the first sample without a valid IK solution.
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
        raise ValueError(f"need at least two points of shape (K, 3), got {points.shape}")
    if not speed > 0.0:
        raise ValueError(f"speed must be > 0, got {speed}")
    times, positions, velocities, segments, start = [], [], [], [], 0.0
    for k, (p0, p1) in enumerate(itertools.pairwise(points)):
        samples = straight_line(p0, p1, step)
        length = float(np.linalg.norm(p1 - p0))
        if k > 0:
            samples = samples[1:]  # the corner is the previous leg's last sample
        if length == 0.0:
            continue
        arc = np.linalg.norm(samples - p0, axis=-1)
        t, duration = leg_times(length, speed, arc)
        rate = quintic([0.0], [length], t, duration=duration).qd[:, 0]
        times.append(start + t)
        positions.append(samples)
        velocities.append(rate[:, None] * (p1 - p0) / length)
        segments.append(np.full(len(t), k))
        start += duration
    position = np.concatenate(positions)
    targets = np.tile(np.diag([1.0, -1.0, -1.0, 1.0]), (len(position), 1, 1))
    targets[:, :2, :2] = [[np.cos(yaw), np.sin(yaw)], [np.sin(yaw), -np.cos(yaw)]]
    targets[:, :3, 3] = position
    solutions = model.solve_ik(targets)
    failed = np.flatnonzero(~solutions.ok)
    if failed.size:
        i = int(failed[0])
        raise ValueError(
            f"sample {i} at {position[i].tolist()} m has no valid IK solution: {solutions.note(i)}"
        )
    q = solutions.solution
    dh = model.dh_angles(q)
    velocity = np.concatenate(velocities)
    task = np.concatenate([velocity, np.zeros((len(velocity), 1))], axis=-1)
    rates = np.linalg.solve(model.jacob0(q)[:, _TASK_ROWS, :], task[..., None])[..., 0]
    axis = {v: axis_from_dh(dh, v) for v in VARIANTS}
    return DoorTrajectory(
        t=np.concatenate(times),
        segment=np.concatenate(segments),
        position=position,
        velocity=velocity,
        dh=dh,
        axis=axis,
        axis_rates=rates,
        variant=model.variant,
    )
