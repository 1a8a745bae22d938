"""Planar two-link IK (both branches, reachability reasons), angle wrapping, yaw quaternions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manipulator_kinematics.planar import (
    ELBOW_NEGATIVE,
    ELBOW_POSITIVE,
    Reach,
    quaternion_yaw,
    two_link_fk,
    two_link_ik,
    wrap_angle,
    yaw_quaternion,
)


def test_hand_case_both_elbows() -> None:
    solution = two_link_ik(1.0, 1.0, 1.0, 1.0)
    np.testing.assert_allclose(solution.theta1, [0.0, math.pi / 2], atol=1e-15)
    np.testing.assert_allclose(solution.theta2, [math.pi / 2, -math.pi / 2], atol=1e-15)
    assert solution.reachable


def test_round_trip_over_random_reachable_targets() -> None:
    rng = np.random.default_rng(1)
    l1, l2 = 0.7, 0.4
    q = rng.uniform(-math.pi, math.pi, (10_000, 2))
    target = two_link_fk(q[:, 0], q[:, 1], l1, l2)
    solution = two_link_ik(target[:, 0], target[:, 1], l1, l2)
    assert solution.reachable.all()
    for branch in (ELBOW_POSITIVE, ELBOW_NEGATIVE):
        tip = two_link_fk(solution.theta1[:, branch], solution.theta2[:, branch], l1, l2)
        np.testing.assert_allclose(tip, target, atol=1e-12)
    assert np.all(solution.theta2[:, ELBOW_POSITIVE] >= 0) and np.all(solution.theta2[:, ELBOW_NEGATIVE] <= 0)
    # The sampled configuration is one of the two branches.
    matches = np.abs(wrap_angle(solution.theta1 - q[:, :1])) < 1e-9
    assert np.all(matches.any(axis=1))


def test_reachability_reasons() -> None:
    solution = two_link_ik([2.0, 0.1, np.nan, 1.1], [0.0, 0.0, 0.0, 0.0], 0.7, 0.4)
    assert solution.reach.tolist() == [Reach.TOO_FAR, Reach.TOO_CLOSE, Reach.INVALID, Reach.REACHABLE]
    assert np.isnan(solution.theta1[:3]).all() and np.isfinite(solution.theta1[3]).all()
    assert "r = 2 m is beyond the reach l1 + l2 = 1.1 m" in solution.reason(0)
    assert "inside the inner radius |l1 - l2| = 0.3 m" in solution.reason(1)
    assert solution.reason(2) == "target is not finite"
    # Stretched arm exactly at the boundary: both branches coincide.
    np.testing.assert_allclose(solution.theta2[3], [0.0, 0.0], atol=1e-7)


def test_wrap_angle_range() -> None:
    angles = np.array([-3 * math.pi, -math.pi, 0.5, math.pi, 7.0])
    wrapped = wrap_angle(angles)
    assert np.all(wrapped >= -math.pi) and np.all(wrapped < math.pi)
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angles), atol=1e-12)
    np.testing.assert_allclose(wrapped[[2, 4]], [0.5, 7.0 - 2 * math.pi])


def test_yaw_quaternion_round_trip_and_tilt() -> None:
    yaw = np.linspace(-3.1, 3.1, 50)
    quaternion = yaw_quaternion(yaw)
    np.testing.assert_allclose(np.linalg.norm(quaternion, axis=-1), 1.0)
    back, tilt = quaternion_yaw(quaternion * 3.0)  # not normalised on purpose
    np.testing.assert_allclose(back, yaw, atol=1e-12)
    np.testing.assert_allclose(tilt, 0.0, atol=1e-7)
    # 0.3 rad about x, then nothing about z: tilt 0.3, yaw 0.
    roll = [math.sin(0.15), 0.0, 0.0, math.cos(0.15)]
    yaw_roll, tilt_roll = quaternion_yaw(roll)
    assert yaw_roll == pytest.approx(0.0, abs=1e-12) and tilt_roll == pytest.approx(0.3, abs=1e-12)
    assert np.isnan(quaternion_yaw([0.0, 0.0, 0.0, 0.0])[0])
