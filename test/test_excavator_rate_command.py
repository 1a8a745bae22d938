"""Numpy cores of the velocity IK node: 6-D twist <-> Q_dot (twist.py) and the safe rate command
(rate_command.py: eq. 9 scaled as a whole by one factor for singularities, stroke ends and speed
limits, so the bucket keeps the commanded direction; the bucket-angle-gives-way secondary task)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import ACTUATORS, Excavator, bucket_quaternion
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.core.rate_command import (
    END_ZONE,
    SINGULAR,
    STROKE,
    damped_inverse,
    describe,
    rate_command,
    scale_to_speed,
    stroke_scale,
    toward_line,
)
from excavator_kinematics.core.twist import bucket_angles, split_twist, swing_rate, twist_from_q_dot

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


def test_stroke_scale() -> None:
    lower, upper = np.array([-1.0, 1.0, 1.0, 1.0]), np.array([1.0, 2.0, 2.0, 2.0])
    d = np.array([0.0, 2.0, 1.0, 1.95])
    rates = np.array([0.5, 0.1, -0.2, 1.0])
    scale, clamped = stroke_scale(d, rates, lower, upper, horizon=0.1)
    assert scale == 0.0  # two actuators at their ends want to go further: the whole command stops
    assert clamped.tolist() == [False, True, True, True]  # the third has 0.05 m for 0.1 m in 0.1 s
    scale, clamped = stroke_scale(d, rates * [1, 0, 0, 1], lower, upper, horizon=0.1)
    assert scale == pytest.approx(0.5) and clamped.tolist() == [False, False, False, True]
    scale, clamped = stroke_scale(d, -rates, lower, upper, horizon=0.1)
    assert scale == 1.0 and not clamped.any()  # away from the ends (0.95 m for 0.1 m): untouched
    outside = np.array([0.0, 2.1, 0.9, 1.5])
    beyond, _ = stroke_scale(outside, np.array([0.0, 0.3, -0.3, 0.0]), lower, upper, 0.1)
    assert beyond == 0.0  # already beyond an end: never further out
    back, _ = stroke_scale(outside, np.array([0.0, -0.3, 0.3, 0.0]), lower, upper, 0.1)
    assert back == 1.0  # but back inside
    near, _ = stroke_scale(
        np.array([0.0, 2.0 - 0.9 * END_ZONE, 1.5, 1.5]), np.array([0.0, 1e-6, 0.0, 0.0]), lower, upper, 0.1
    )
    assert near == 0.0  # within END_ZONE of the end counts as at it: the approach ends
    free, clamped = stroke_scale(d, rates, np.full(4, -np.inf), np.full(4, np.inf), 0.1)
    assert free == 1.0 and not clamped.any()


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


def test_stroke_end_stops_the_whole_command_in_its_direction() -> None:
    """Issue #18 item 4: stopping only the cylinder at its end (the old clamp) turned the bucket
    onto another direction; now the whole command slows, and stops at the end."""
    D = LIMITS.reference.copy()
    D[1] = LIMITS.stroke_max[0]  # boom cylinder fully extended
    J = EXC.jc0(D)
    wanted = np.array([0.0, 0.05, -0.02, 0.03])  # boom cylinder wants to extend further
    cmd = rate_command(J, D, J @ wanted, LIMITS, 50.0, 0.1)
    assert np.all(cmd.d_dot == 0.0) and cmd.scale == 0.0
    assert cmd.clamped.tolist() == [False, True, False, False] and cmd.speed_scale == 1.0
    assert (cmd.limit, cmd.actuator) == (STROKE, 1)
    assert describe(cmd, ACTUATORS) == (
        "stopped",
        "stopped: boom_cylinder at its stroke end, the target direction cannot be continued",
    )
    D[1] = LIMITS.stroke_max[0] - 0.002  # 2 mm before the end: 0.05 m/s would take 0.04 s < 0.1 s
    cmd = rate_command(EXC.jc0(D), D, EXC.jc0(D) @ wanted, LIMITS, 50.0, 0.1)
    assert cmd.scale == pytest.approx(0.002 / (0.05 * 0.1), rel=1e-9)
    np.testing.assert_allclose(cmd.d_dot, cmd.scale * wanted, rtol=1e-12, atol=1e-15)
    assert describe(cmd, ACTUATORS)[1] == "slowed: stroke end of boom_cylinder ahead"
    D[1] = LIMITS.stroke_max[0]
    back = rate_command(J, D, -(J @ wanted), LIMITS, 50.0, 0.1)  # away from the end: as commanded
    np.testing.assert_allclose(back.d_dot, -wanted, rtol=1e-12)
    assert back.scale == 1.0 and describe(back, ACTUATORS) == ("tracking", "tracking")


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


@pytest.mark.slow
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


def along(jc0: np.ndarray, d_dot: np.ndarray, q_dot: np.ndarray, rows: slice = slice(None)) -> float:
    """The factor s of the achieved bucket rate JC0 D_dot as s x q_dot (least squares; checked by
    the caller to be a multiple)."""
    q = q_dot[rows]
    return float((jc0 @ d_dot)[rows] @ q / (q @ q))


def test_every_command_is_the_target_direction_within_every_limit() -> None:
    """5,000 random states (a third of them on a stroke end or the swing limit, a third within 5 mm
    of one) and targets from 0.01x to 100x the speeds: the achieved Q_dot = JC0 D_dot is s x Q_dot
    with 0 <= s <= 1 (to 1e-10 of |Q_dot|), no rate is above its limit by even an ulp, no actuator
    at an end moves further out and none can reach its end within the stroke horizon."""
    rng = np.random.default_rng(18)
    n = 5_000
    states = random_states(n)
    ends = np.where(rng.random((n, 4)) < 0.5, LIMITS.d_min, LIMITS.d_max)
    pick = rng.integers(0, 3, size=(n, 1))
    states = np.where(pick == 0, np.where(rng.random((n, 4)) < 0.3, ends, states), states)
    near = ends + np.sign(LIMITS.reference - ends) * rng.uniform(0.0, 0.005, (n, 4))
    states = np.where((pick == 1) & (rng.random((n, 4)) < 0.3), near, states)
    targets = rng.normal(size=(n, 4)) * 10.0 ** rng.uniform(-2, 2, (n, 1))
    scales, horizon = [], 0.1
    for D, q_dot in zip(states, targets, strict=True):
        J = EXC.jc0(D)
        cmd = rate_command(J, D, q_dot, LIMITS, 50.0, horizon)
        s = along(J, cmd.d_dot, q_dot)
        assert np.linalg.norm(J @ cmd.d_dot - s * q_dot) <= 1e-10 * np.linalg.norm(q_dot)
        assert -1e-12 <= s <= 1.0 + 1e-12 and s == pytest.approx(cmd.scale, rel=1e-9, abs=1e-12)
        assert np.all(np.abs(cmd.d_dot) <= LIMITS.max_rates)
        outward = np.where(cmd.d_dot > 0, LIMITS.d_max - D, np.where(cmd.d_dot < 0, D - LIMITS.d_min, np.inf))
        assert np.all(np.abs(cmd.d_dot) * horizon <= np.maximum(outward, 0.0) * (1 + 1e-12))
        scales.append(cmd.scale)
    scales = np.array(scales)
    # Every kind was met: as commanded, slowed, stopped.
    assert (scales == 1.0).sum() > 250 and ((scales > 0) & (scales < 1)).sum() > 250
    assert (scales == 0.0).sum() > 250


def test_damping_slows_but_does_not_bend() -> None:
    """Above the threshold damped least squares alone bends the direction (JC0 D_dot is not a
    multiple of Q_dot); the command is the exact solution brought down to its size instead."""
    D = LIMITS.reference
    J = EXC.jc0(D)
    q_dot = np.array([0.05, 0.0, 0.05, 0.05])
    threshold = np.linalg.cond(J) / 2.0
    sigma = np.linalg.svd(J, compute_uv=False)
    lam = sigma[0] / threshold * (1.0 - threshold / (sigma[0] / sigma[-1]))
    dls = J.T @ np.linalg.solve(J @ J.T + lam**2 * np.eye(4), q_dot)  # normal-equations form
    bent = J @ dls
    assert np.linalg.norm(bent - along(J, dls, q_dot) * q_dot) > 1e-3 * np.linalg.norm(q_dot)
    cmd = rate_command(J, D, q_dot, LIMITS, threshold, 0.1)
    exact = np.linalg.solve(J, q_dot)
    np.testing.assert_allclose(cmd.d_dot, exact * np.linalg.norm(dls) / np.linalg.norm(exact), rtol=1e-9)
    assert cmd.limit == SINGULAR and 0.0 < cmd.scale < 1.0 and cmd.damping == pytest.approx(lam)
    assert describe(cmd, ACTUATORS) == ("slowed", "slowed: JC0 near singular")


def test_a_direction_a_singular_jacobian_cannot_give_stops() -> None:
    J = np.diag([2.0, 1.0, 1.0, 0.0])  # no rate moves the fourth component
    D = LIMITS.reference
    stopped = rate_command(J, D, np.array([0.1, 0.0, 0.0, 0.1]), LIMITS, 50.0, 0.1)
    assert np.all(stopped.d_dot == 0.0) and stopped.scale == 0.0 and stopped.limit == SINGULAR
    assert describe(stopped, ACTUATORS)[0] == "stopped"
    possible = rate_command(J, D, np.array([0.1, 0.0, 0.0, 0.0]), LIMITS, 50.0, 0.1)
    np.testing.assert_allclose(J @ possible.d_dot, possible.scale * np.array([0.1, 0.0, 0.0, 0.0]))
    assert possible.scale > 0.0


# The table (constant linear target twist from the reference state), plus a slow oblique one
# that stays inside the stroke box for a while and a fast sideways one (swing at its speed limit).
LINES = [
    (2.0, 0.0, 0.0),
    (0.0, 0.0, -1.0),
    (0.0, 0.0, 1.0),
    (-1.0, 0.0, 0.0),
    (0.3, 0.3, -0.3),
    (0.0, 3.0, 0.0),
]


def drive(linear: tuple[float, ...], gives_way: bool, seconds: float = 12.0, dt: float = 0.01):
    """The plant under rate_command at 100 Hz for a constant linear target: (tips, alphas,
    commands, the factor s of each achieved step JC0 D_dot = s Q_dot on the rows the task keeps)."""
    plant = Plant(LIMITS, LIMITS.reference)
    q_dot = np.r_[linear, 0.0]
    rows = slice(0, 3) if gives_way else slice(None)
    poses, commands, factors = [EXC.pose(plant.d)], [], []
    for _ in range(round(seconds / dt)):
        J = EXC.jc0(plant.d)
        cmd = rate_command(J, plant.d, q_dot, LIMITS, 50.0, 0.1, gives_way)
        s = along(J, cmd.d_dot, q_dot, rows)
        assert np.linalg.norm((J @ cmd.d_dot)[rows] - s * q_dot[rows]) <= 1e-12 * np.linalg.norm(q_dot)
        assert np.all(np.abs(cmd.d_dot) <= LIMITS.max_rates)
        commands.append(cmd)
        factors.append(s)
        plant.step(cmd.d_dot, dt)
        poses.append(EXC.pose(plant.d))
    poses = np.array(poses)
    return poses[:, :3], poses[:, 3], commands, np.array(factors)


def off_line(tips: np.ndarray, linear: tuple[float, ...]) -> tuple[float, float]:
    """(travel along the commanded line, largest distance from it); the line starts at tips[0]."""
    u = np.array(linear) / np.linalg.norm(linear)
    offsets = tips - tips[0]
    t = offsets @ u
    return float(t.max()), float(np.linalg.norm(offsets - t[:, None] * u, axis=1).max())


@pytest.mark.parametrize("linear", LINES)
def test_the_tip_keeps_the_commanded_line_past_the_stroke_ends(linear: tuple[float, ...]) -> None:
    """Before the fix (per-actuator clamp) the tip left these lines by 4.25, 1.12, 1.93 and 2.08 m;
    now by at most 1.5 cm (the issue's four: 6 mm; the rest is the 10 ms steps: each re-solve is
    tangent to the line, the step between follows JC0's curvature, 12 mm for the sideways 3 m/s with
    the swing at its speed limit), the bucket angle stays (0.1 deg), and the bucket stops for good
    where the line cannot be continued."""
    tips, alphas, commands, factors = drive(linear, gives_way=False)
    travel, off = off_line(tips, linear)
    assert off <= 0.015, off
    assert travel > 1.0 and np.all((factors >= -1e-12) & (factors <= 1.0 + 1e-12))
    assert np.abs(alphas - alphas[0]).max() <= np.radians(0.1)
    states = [describe(c, ACTUATORS)[0] for c in commands]
    assert "stopped" in states
    first = states.index("stopped")
    assert set(states[first:]) == {"stopped"}  # stopped for good: no creeping on in another direction
    assert np.all(tips[first + 1 :] == tips[first + 1]) and np.all(commands[-1].d_dot == 0.0)


# One line in the fast tier (about 2 s each on an idle machine), the other three slow.
@pytest.mark.parametrize(
    "linear", [LINES[1], *(pytest.param(line, marks=pytest.mark.slow) for line in (LINES[0], *LINES[2:4]))]
)
def test_bucket_angle_gives_way_keeps_the_tip_line_further(linear: tuple[float, ...]) -> None:
    """The secondary task: the tip's linear velocity stays a non-negative multiple of the target at
    every step (to 1e-12, checked in drive), the tip gets at least as far along the line, and the
    bucket turns (it held its angle without the setting)."""
    tips, alphas, commands, factors = drive(linear, gives_way=True)
    plain = drive(linear, gives_way=False)[0]
    travel, off = off_line(tips, linear)
    assert off <= 0.03, off
    assert travel >= off_line(plain, linear)[0] - 1e-6
    assert np.all((factors >= -1e-12) & (factors <= 1.0 + 1e-12))
    assert any(c.gives_way for c in commands) and np.abs(alphas - alphas[0]).max() > np.radians(5)


def test_the_way_back_to_the_line() -> None:
    """toward_line: gain x the across-line offset of the tip and the bucket angle's offset from the
    angle the target gives at the tip's progress; None beyond LINE_RESTART; no line without a
    linear velocity."""
    start, q_dot = np.array([1.0, 0.0, 1.0, -2.0]), np.array([2.0, 0.0, 0.0, 1.0])
    Q = np.array([1.5, 0.01, 0.98, -2.0 + 0.25 + 0.02])  # 0.5 m along: the angle should be -1.75
    np.testing.assert_allclose(toward_line(start, q_dot, Q, 2.0), [0.0, -0.02, 0.04, -0.04], atol=1e-15)
    np.testing.assert_allclose(
        toward_line(start, q_dot, Q, 2.0, hold_angle=False), [0.0, -0.02, 0.04, 0.0], atol=1e-15
    )
    assert toward_line(start, q_dot, Q + [0.0, 0.06, 0.0, 0.0], 2.0) is None  # moved, not drifted
    np.testing.assert_allclose(toward_line(start, q_dot, start + q_dot * 0.3, 2.0), 0.0, atol=1e-15)
    np.testing.assert_array_equal(toward_line(start, np.array([0.0, 0.0, 0.0, 1.0]), Q, 2.0), 0.0)
