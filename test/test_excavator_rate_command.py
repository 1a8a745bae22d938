"""Numpy cores of the velocity IK node: 6-D twist <-> Q_dot (twist.py) and the safe rate command
(rate_command.py: eq. 9 with damped least squares, stroke ends, speed scaling)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from excavator_kinematics.kinematics import Excavator, bucket_quaternion
from excavator_kinematics.rate_command import clamp_to_stroke, damped_inverse, rate_command, scale_to_speed
from excavator_kinematics.twist import bucket_angles, split_twist, swing_rate, twist_from_q_dot

EXC = Excavator.default()
LIMITS = EXC.limits
RNG = np.random.default_rng(3)


def random_states(n: int) -> np.ndarray:
    u = RNG.uniform(0.05, 0.95, size=(n, 4))
    return LIMITS.d_min + u * (LIMITS.d_max - LIMITS.d_min)


def quaternion_rate_to_omega(q0: np.ndarray, q1: np.ndarray, dt: float) -> np.ndarray:
    """Base-frame angular velocity from two unit quaternions [x, y, z, w] dt apart (omega = 2 q_dot q*)."""
    q_dot = (q1 - q0) / dt
    q = 0.5 * (q0 + q1)
    x, y, z, w = q
    dx, dy, dz, dw = q_dot
    # vector part of q_dot (x) conj(q)
    return 2.0 * np.array(
        [
            -dw * x + dx * w - dy * z + dz * y,
            -dw * y + dy * w - dz * x + dx * z,
            -dw * z + dz * w - dx * y + dy * x,
        ]
    )


@pytest.mark.parametrize("index", range(5))
def test_split_of_a_real_motion_is_its_bucket_rates_with_no_residual(index: int) -> None:
    """The twist of an actual motion (finite differences of pose and quaternion, independent of the
    module's formulas) splits into Q_dot with zero residual."""
    D = random_states(5)[index]
    D_dot = RNG.uniform(-1, 1, 4) * LIMITS.max_rates
    h = 1e-6
    Q0, Q1 = EXC.pose(D - h * D_dot), EXC.pose(D + h * D_dot)
    linear = (Q1[:3] - Q0[:3]) / (2 * h)
    angular = quaternion_rate_to_omega(
        bucket_quaternion(D[0] - h * D_dot[0], Q0[3]), bucket_quaternion(D[0] + h * D_dot[0], Q1[3]), 2 * h
    )
    tip = EXC.pose(D)[:3]
    split = split_twist(D[0], tip, linear, angular)
    np.testing.assert_allclose(split.q_dot[:3], linear, atol=1e-12)
    np.testing.assert_allclose(split.q_dot[3], (Q1[3] - Q0[3]) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(split.residual, 0.0, atol=1e-6)
    np.testing.assert_allclose(swing_rate(D[0], tip, linear), D_dot[0], rtol=1e-6)


def test_unachievable_angular_components_are_the_residual() -> None:
    D = random_states(1)[0]
    tip = EXC.pose(D)[:3]
    q_dot = np.array([0.2, -0.1, 0.05, 0.3])
    linear, angular = twist_from_q_dot(D[0], tip, q_dot)
    radial = np.array([np.cos(D[0]), np.sin(D[0]), 0.0])  # roll axis: the bucket cannot turn about it
    extra = 0.07 * radial + np.array([0.0, 0.0, 0.02])  # plus a yaw rate the tip velocity does not imply
    split = split_twist(D[0], tip, linear, angular + extra)
    np.testing.assert_allclose(split.q_dot, q_dot, atol=1e-12)
    np.testing.assert_allclose(split.residual, extra, atol=1e-12)


def test_no_swing_rate_for_a_tip_on_the_swing_axis() -> None:
    assert swing_rate(0.3, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])) == 0.0


def test_bucket_angles_invert_the_quaternion() -> None:
    theta1 = RNG.uniform(-np.pi, np.pi, 50)
    alpha = RNG.uniform(-5.6, 0.9, 50)  # beyond -pi as a curled bucket gets
    t, a = bucket_angles(bucket_quaternion(theta1, alpha))
    np.testing.assert_allclose(t, theta1, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (a - alpha))), 0.0, atol=1e-12)


def test_exact_inverse_below_the_threshold() -> None:
    for D in random_states(20):
        q_dot = RNG.normal(size=4) * 0.1
        J = EXC.jc0(D)
        d_dot, condition, damping = damped_inverse(J, q_dot, condition_threshold=50.0)
        assert damping == 0.0
        np.testing.assert_allclose(condition, np.linalg.cond(J), rtol=1e-12)
        np.testing.assert_allclose(d_dot, np.linalg.solve(J, q_dot), rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(J @ d_dot, q_dot, atol=1e-12)


def test_damped_least_squares_above_the_threshold() -> None:
    D = LIMITS.reference
    J = EXC.jc0(D)
    q_dot = np.array([0.3, 0.1, -0.2, 0.1])
    condition = np.linalg.cond(J)
    threshold = condition / 2.0
    d_dot, _, damping = damped_inverse(J, q_dot, threshold)
    sigma = np.linalg.svd(J, compute_uv=False)
    expected_lambda = sigma[0] / threshold * (1.0 - threshold / condition)
    assert damping == pytest.approx(expected_lambda, rel=1e-12)
    # Normal-equations form of DLS, independent of the SVD used by the module.
    expected = J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(4), q_dot)
    np.testing.assert_allclose(d_dot, expected, rtol=1e-9)
    # Continuous at the threshold: just above it the command is the exact inverse's.
    near, _, _ = damped_inverse(J, q_dot, condition * (1 - 1e-9))
    np.testing.assert_allclose(near, np.linalg.solve(J, q_dot), rtol=1e-6)


def test_damping_bounds_the_rates_of_a_singular_jacobian() -> None:
    J = np.diag([2.0, 1.0, 1.0, 1e-9])
    q_dot = np.array([0.0, 0.0, 0.0, 1.0])
    d_dot, condition, damping = damped_inverse(J, q_dot, condition_threshold=50.0)
    assert condition > 1e9 and damping > 0.0
    # Gain sigma / (sigma^2 + lambda^2) <= 1 / (2 lambda) with lambda -> sigma_max / threshold.
    assert np.linalg.norm(d_dot) <= 50.0 / (2.0 * 2.0) * 1.0001
    assert np.all(np.isfinite(d_dot))


def test_stroke_end_clamp() -> None:
    lower, upper = np.array([-1.0, 1.0, 1.0, 1.0]), np.array([1.0, 2.0, 2.0, 2.0])
    d = np.array([0.0, 2.0, 1.0, 1.95])
    rates = np.array([0.5, 0.1, -0.2, 1.0])
    out, clamped = clamp_to_stroke(d, rates, lower, upper, horizon=0.1)
    np.testing.assert_allclose(out, [0.5, 0.0, 0.0, 0.5])  # at the end, at the end, approach 0.05 m / 0.1 s
    assert clamped.tolist() == [False, True, True, True]
    back, clamped = clamp_to_stroke(d, -rates, lower, upper, horizon=0.1)
    np.testing.assert_allclose(back, [-0.5, -0.1, 0.2, -1.0])  # away from the ends: untouched
    assert not clamped.any()
    beyond, _ = clamp_to_stroke(
        np.array([0.0, 2.1, 0.9, 1.5]), np.array([0.0, 0.3, -0.3, 0.0]), lower, upper, 0.1
    )
    np.testing.assert_allclose(beyond, 0.0)  # already beyond an end: never further out
    free, clamped = clamp_to_stroke(d, rates, np.full(4, -np.inf), np.full(4, np.inf), 0.1)
    np.testing.assert_allclose(free, rates)
    assert not clamped.any()


def test_speed_scaling_keeps_the_direction() -> None:
    max_speed = np.array([1.0, 0.15, 0.18, 0.2])
    rates = np.array([0.5, 0.3, -0.09, 0.1])
    out, scale = scale_to_speed(rates, max_speed)
    assert scale == pytest.approx(0.5)
    np.testing.assert_allclose(out, rates * 0.5)
    assert np.max(np.abs(out) / max_speed) == pytest.approx(1.0)
    same, scale = scale_to_speed(rates * 0.1, max_speed)
    assert scale == 1.0
    np.testing.assert_allclose(same, rates * 0.1)


def test_fast_target_is_scaled_so_the_bucket_keeps_its_direction() -> None:
    D = LIMITS.reference
    q_dot = np.array([2.0, 0.5, -1.0, 0.4])  # far beyond the cylinder speeds
    cmd = rate_command(EXC.jc0(D), D, q_dot, LIMITS, 50.0, 0.1)
    assert 0.0 < cmd.speed_scale < 1.0 and not cmd.clamped.any()
    assert np.max(np.abs(cmd.d_dot) / LIMITS.max_rates) == pytest.approx(1.0)
    np.testing.assert_allclose(EXC.jc0(D) @ cmd.d_dot, cmd.speed_scale * q_dot, atol=1e-12)


def test_stroke_end_stops_only_that_cylinder_before_scaling() -> None:
    D = LIMITS.reference.copy()
    D[1] = LIMITS.stroke_max[0]  # boom cylinder fully extended
    J = EXC.jc0(D)
    wanted = np.array([0.0, 0.05, -0.02, 0.03])  # boom cylinder wants to extend further
    q_dot = J @ wanted
    cmd = rate_command(J, D, q_dot, LIMITS, 50.0, 0.1)
    np.testing.assert_allclose(cmd.d_dot, [0.0, 0.0, -0.02, 0.03], atol=1e-12)
    assert cmd.clamped.tolist() == [False, True, False, False] and cmd.speed_scale == 1.0


def test_swing_limit_applies_like_a_stroke_end() -> None:
    limits = dataclasses.replace(LIMITS, swing_min=-0.5, swing_max=0.5)
    D = LIMITS.reference.copy()
    D[0] = 0.5
    J = EXC.jc0(D)
    cmd = rate_command(J, D, J @ np.array([0.2, 0.0, 0.0, 0.0]), limits, 50.0, 0.1)
    np.testing.assert_allclose(cmd.d_dot, 0.0, atol=1e-12)


def test_a_target_that_overflows_is_refused() -> None:
    D = LIMITS.reference
    with pytest.raises(ValueError, match="overflow"):
        rate_command(EXC.jc0(D), D, np.full(4, 1.7e308), LIMITS, 50.0, 0.1)


def test_speed_limits_hold_exactly_not_to_an_ulp() -> None:
    """20,000 random states and targets (most far beyond the speeds): no command exceeds a limit,
    not even by an ulp (before the fix 1 in 25 did, ratio 1.0000000000000002), and the direction
    is kept to round-off."""
    rng = np.random.default_rng(11)
    states = random_states(20_000)
    over, scaled = 0, 0
    for D, q_dot in zip(states, rng.normal(scale=2.0, size=(20_000, 4)), strict=True):
        cmd = rate_command(EXC.jc0(D), D, q_dot, LIMITS, 50.0, 0.1)
        over += int(np.any(np.abs(cmd.d_dot) > LIMITS.max_rates))
        if cmd.speed_scale < 1.0 and not cmd.clamped.any():
            scaled += 1
            unscaled = rate_command(EXC.jc0(D), D, q_dot * cmd.speed_scale, LIMITS, 50.0, 0.1).d_dot
            np.testing.assert_allclose(cmd.d_dot, unscaled, rtol=1e-13, atol=1e-16)
    assert over == 0 and scaled > 10_000
    # The rounding case itself: 1 / ratio times the fastest rate is an ulp above the limit.
    d_dot = np.array([0.0, 0.15 * 3.0000000000000004, 0.0, 0.0])
    out, _ = scale_to_speed(d_dot, np.array([1.0, 0.15, 1.0, 1.0]))
    assert out[1] <= 0.15
