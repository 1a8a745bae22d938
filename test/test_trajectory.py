"""Quintic joint trajectory (jtraj's polynomial) and straight-line Cartesian interpolation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manipulator_kinematics.trajectory import quintic, straight_line

PI = math.pi
# Tool changer paper's case (tool_changer.md): tf = 30 s.
Q0 = np.array([PI / 4, PI / 3, -PI / 4, PI / 3, 5 * PI / 4, 0.0])
QF = np.array([PI / 2, PI / 6, -PI / 3, PI / 4, PI / 2, PI / 4])


def test_boundary_values() -> None:
    trajectory = quintic(Q0, QF, np.linspace(0.0, 30.0, 301))
    np.testing.assert_allclose(trajectory.q[0], Q0, atol=1e-15)
    np.testing.assert_allclose(trajectory.q[-1], QF, atol=1e-14)
    for rates in (trajectory.qd, trajectory.qdd):
        np.testing.assert_allclose(rates[[0, -1]], 0.0, atol=1e-15)


def test_peak_velocity_and_acceleration() -> None:
    T = 30.0
    delta = QF - Q0
    middle = quintic(Q0, QF, [0.0, T / 2, T])
    np.testing.assert_allclose(middle.qd[1], 15.0 / 8.0 * delta / T, rtol=1e-12)
    np.testing.assert_allclose(middle.qdd[1], 0.0, atol=1e-15)
    t_peak = (0.5 - math.sqrt(3) / 6) * T
    peak = quintic(Q0, QF, [t_peak], duration=T)
    np.testing.assert_allclose(peak.qdd[0], 10 * math.sqrt(3) / 3 * delta / T**2, rtol=1e-12)
    # Dense samples: the speed of every joint peaks at 15 s (the paper's observation).
    dense = quintic(Q0, QF, np.linspace(0.0, T, 3001))
    assert np.all(dense.t[np.argmax(np.abs(dense.qd), axis=0)] == pytest.approx(15.0))
    assert np.argmax(np.max(np.abs(dense.qdd), axis=0)) == 4  # J5 has the largest delta
    np.testing.assert_allclose(dense.q[:, 0] - Q0[0], dense.q[:, 5] - Q0[5], atol=1e-15)  # J1 / J6 coincide


def test_rates_are_derivatives_of_positions() -> None:
    t = np.linspace(0.0, 4.0, 4001)
    trajectory = quintic(Q0, QF, t, qd0=[0.3, 0, -0.2, 0, 0, 0.1], qdf=[0, 0.5, 0, 0, -0.4, 0])
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(trajectory.q, dt, axis=0)[1:-1], trajectory.qd[1:-1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(trajectory.qd, dt, axis=0)[1:-1], trajectory.qdd[1:-1], atol=1e-5)
    np.testing.assert_allclose(trajectory.qd[0], [0.3, 0, -0.2, 0, 0, 0.1], atol=1e-14)
    np.testing.assert_allclose(trajectory.qd[-1], [0, 0.5, 0, 0, -0.4, 0], atol=1e-14)
    np.testing.assert_allclose(trajectory.qdd[[0, -1]], 0.0, atol=1e-13)


def test_times_outside_the_duration_are_refused() -> None:
    with pytest.raises(ValueError, match="times must lie"):
        quintic(Q0, QF, [0.0, 31.0], duration=30.0)
    with pytest.raises(ValueError):
        quintic(Q0, QF[:3], [0.0, 1.0])


def test_straight_line_steps_like_the_pump_boom_paper() -> None:
    p0, p1 = np.array([10.0, 0.0, 5.0]), np.array([13.0, 4.0, 5.0])  # L = 5 m
    points = straight_line(p0, p1, 0.1)
    assert len(points) == 51
    np.testing.assert_allclose(points[[0, -1]], [p0, p1], atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(np.diff(points, axis=0), axis=1), 0.1, atol=1e-14)
    np.testing.assert_allclose(points[7], p0 + 7 * (p1 - p0) / 50)
    # N = ceil(L / step): a remainder adds a step, spacing shrinks to L / N.
    uneven = straight_line([0.0, 0.0], [0.25, 0.0], 0.1)
    np.testing.assert_allclose(uneven[:, 0], [0.0, 0.25 / 3, 0.5 / 3, 0.25])
    assert len(straight_line([0.0], [1.1], 0.1)) == 12  # 11 steps despite 1.1 / 0.1 > 11 in floating point
    assert len(straight_line([1.0, 2.0], [1.0, 2.0], 0.1)) == 1
    with pytest.raises(ValueError):
        straight_line([0.0], [1.0], 0.0)
