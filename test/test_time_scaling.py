"""Time scaling of a sampled path (manipulator_kinematics.time_scaling) against closed forms, a
brute-force lower envelope, the FK of a planar 2R arm and finite differences of q(t).

Tolerances: joint speeds <= limit x (1 + 1e-12) and tip speed <= the asked one exactly (speeds are
clipped to the caps); |sdd| <= a x (1 + 1e-9) (the rounding of the accumulated sums, ~N eps).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from manipulator_kinematics.planar import two_link_fk, two_link_ik
from manipulator_kinematics.time_scaling import ACCELERATION, TIP_SPEED, time_scale

SPEED_RTOL = 1e-12
ACCELERATION_RTOL = 1e-9
L1 = L2 = 1.0
TIP, ACC = 0.5, 1.0  # m/s, m/s^2 on the 2R arm's line


def line_2r(count: int, start=(1.6, -0.6), end=(0.3, 1.1)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A planar 2R arm's joints (count, 2) along a straight tip line, the arc lengths, the tangent."""
    start, end = np.asarray(start), np.asarray(end)
    s = np.linspace(0.0, float(np.linalg.norm(end - start)), count)
    tangent = (end - start) / s[-1]
    points = start + s[:, None] * tangent
    solution = two_link_ik(points[:, 0], points[:, 1], L1, L2)
    q = np.stack([solution.theta1[:, 0], solution.theta2[:, 0]], axis=1)
    return q, s, tangent


def jacobian_2r(q: np.ndarray) -> np.ndarray:
    t1, t12 = q[:, 0], q[:, 0] + q[:, 1]
    return np.stack(
        [
            np.stack([-L1 * np.sin(t1) - L2 * np.sin(t12), -L2 * np.sin(t12)], -1),
            np.stack([L1 * np.cos(t1) + L2 * np.cos(t12), L2 * np.cos(t12)], -1),
        ],
        -2,
    )


def joint_rate(q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """|dq/ds| per sample: the central difference or a chord next to it, whichever is steeper."""
    chord = np.abs(np.diff(q, axis=0) / np.diff(s)[:, None])
    central = np.abs(np.gradient(q, s, axis=0, edge_order=2))
    return np.maximum.reduce([central, np.vstack([chord[:1], chord]), np.vstack([chord, chord[-1:]])])


def assert_within_limits(timed, vmax, tip_speed, acceleration) -> None:
    assert np.all(np.abs(timed.qd) <= np.asarray(vmax) * (1.0 + SPEED_RTOL))
    # Along each chord too (what a controller interpolating the positions follows).
    chord = np.abs(np.diff(timed.q, axis=0) / np.diff(timed.s)[:, None])
    fastest = np.maximum(timed.speed[1:], timed.speed[:-1])[:, None]
    assert np.all(chord * fastest <= np.asarray(vmax) * (1.0 + SPEED_RTOL))
    assert np.all(timed.speed <= tip_speed)
    assert np.all(np.abs(timed.sdd) <= acceleration * (1.0 + ACCELERATION_RTOL))
    assert timed.speed[0] == timed.speed[-1] == 0.0 and timed.t[0] == 0.0
    np.testing.assert_array_equal(timed.qd[[0, -1]], 0.0)
    assert np.all(np.diff(timed.t) > 0.0)


def test_trapezoid_and_triangle_durations_are_the_closed_form() -> None:
    # q = s (one joint, the tip itself), ramps of v^2 / (2 a) = 0.2 m land on samples.
    s = np.linspace(0.0, 1.0, 21)
    timed = time_scale(s[:, None], s, [np.inf], 0.2, 0.1)
    assert timed.duration == pytest.approx(1.0 / 0.2 + 0.2 / 0.1, rel=1e-12)
    np.testing.assert_array_equal(timed.active[4:17], TIP_SPEED)
    np.testing.assert_array_equal(timed.speed[4:17], 0.2)
    np.testing.assert_array_equal(timed.active[[0, 1, 2, 3, 17, 18, 19, 20]], ACCELERATION)
    np.testing.assert_allclose(timed.sdd[1:4], 0.1, rtol=1e-12)
    np.testing.assert_allclose(timed.sdd[5:16], 0.0, atol=1e-12)
    # Too short to reach the speed: accelerate to the middle, brake: T = 2 sqrt(L / a).
    short = time_scale(s[:5, None], s[:5], [np.inf], 0.2, 0.1)
    assert short.duration == pytest.approx(2.0 * math.sqrt(0.2 / 0.1), rel=1e-12)
    assert np.all(short.active == ACCELERATION) and short.speed.max() == pytest.approx(math.sqrt(0.1 * 0.2))


def test_two_samples_rest_to_rest_and_one_sample() -> None:
    q = np.array([[0.0, 1.0], [0.5, 0.0]])
    s = np.array([0.0, 1.0])
    triangle = time_scale(q, s, [np.inf, np.inf], 10.0, 0.25)
    assert triangle.duration == pytest.approx(2.0 * math.sqrt(1.0 / 0.25), rel=1e-14)
    # Joint 0 moves 0.5 rad per metre: at 0.1 rad/s the tip cruises at 0.2 m/s.
    trapezoid = time_scale(q, s, [0.1, np.inf], 10.0, 0.25)
    assert trapezoid.duration == pytest.approx(1.0 / 0.2 + 0.2 / 0.25, rel=1e-14)
    np.testing.assert_array_equal(trapezoid.qd, 0.0)
    np.testing.assert_allclose(trapezoid.qdd, [[0.125, -0.25], [-0.125, 0.25]], rtol=1e-14)
    single = time_scale(q[:1], s[:1], [1.0, 1.0], 1.0, 1.0)
    assert single.duration == 0.0 and single.q.shape == (1, 2) and np.all(single.qd == 0.0)


def test_speed_is_the_lower_envelope_of_the_caps() -> None:
    # The fastest profile is x_i = min_k (c_k + 2 a |s_i - s_k|): checked by brute force (O(N^2)).
    q, s, _ = line_2r(400)
    vmax = np.array([0.45, 0.55])
    timed = time_scale(q, s, vmax, TIP, ACC)
    with np.errstate(divide="ignore"):
        cap = np.minimum(TIP, np.min(vmax / joint_rate(q, s), axis=1)) ** 2
    cap[[0, -1]] = 0.0
    envelope = np.min(cap[None, :] + 2.0 * ACC * np.abs(s[:, None] - s[None, :]), axis=1)
    np.testing.assert_allclose(timed.speed**2, envelope, rtol=1e-12, atol=1e-15)
    assert_within_limits(timed, vmax, TIP, ACC)
    assert {int(a) for a in np.unique(timed.active)} == {ACCELERATION, TIP_SPEED, 0, 1}


def test_slows_only_where_a_constraint_is_active() -> None:
    q, s, _ = line_2r(2000)
    vmax = np.array([0.45, 0.55])
    timed = time_scale(q, s, vmax, TIP, ACC)
    tip = timed.active == TIP_SPEED
    np.testing.assert_array_equal(timed.speed[tip], TIP)  # the asked speed wherever nothing else binds
    for joint in (0, 1):
        at_limit = timed.active == joint
        assert np.any(at_limit)
        np.testing.assert_allclose(
            timed.speed[at_limit] * joint_rate(q, s)[at_limit, joint], vmax[joint], rtol=SPEED_RTOL
        )
    # On acceleration curves the tip is slower than every cap and accelerates or brakes at a
    # on a segment next to it.
    on_curve = np.flatnonzero(timed.active[1:-1] == ACCELERATION) + 1
    assert np.all(timed.speed[on_curve] < TIP)
    segment = np.abs(np.diff(timed.speed**2)) / (2.0 * np.diff(s))
    np.testing.assert_allclose(np.maximum(segment[on_curve - 1], segment[on_curve]), ACC, rtol=1e-9)
    assert timed.limited_by(("j1", "j2")).keys() == {"tip speed", "acceleration", "j1", "j2"}
    # Without joint limits the joints never set the speed.
    free = time_scale(q, s, [np.inf, np.inf], TIP, ACC)
    assert set(np.unique(free.active).tolist()) == {ACCELERATION, TIP_SPEED}
    assert free.duration < timed.duration


def test_a_corner_keeps_the_chords_within_the_limits() -> None:
    # Two lines meeting at a corner: q(s) has a kink, where the central difference understates
    # the chords on either side; the chords set the cap there.
    first, _, _ = line_2r(201, (1.6, -0.6), (1.0, 0.4))
    second, _, _ = line_2r(201, (1.0, 0.4), (0.2, 0.2))
    q = np.vstack([first, second[1:]])
    s = np.concatenate(
        [
            np.linspace(0.0, math.hypot(0.6, 1.0), 201),
            math.hypot(0.6, 1.0) + np.linspace(0.0, math.hypot(0.8, 0.2), 201)[1:],
        ]
    )
    vmax = np.array([0.45, 0.55])
    timed = time_scale(q, s, vmax, TIP, ACC)
    assert_within_limits(timed, vmax, TIP, ACC)
    central = np.abs(np.gradient(q, s, axis=0, edge_order=2))
    assert np.any(joint_rate(q, s)[200] > 1.2 * central[200])  # the kink: chords steeper than the mean


def test_limits_hold_on_a_long_path() -> None:
    q, s, _ = line_2r(100_000)
    vmax = np.array([0.45, 0.55])
    timed = time_scale(q, s, vmax, TIP, ACC)
    assert_within_limits(timed, vmax, TIP, ACC)
    # Each segment is at constant sdd: its length is the mean speed times its time (to the
    # rounding of differences of s ~ 2 m at 2e-5 m apart).
    np.testing.assert_allclose(
        np.diff(s), 0.5 * (timed.speed[1:] + timed.speed[:-1]) * np.diff(timed.t), rtol=1e-9
    )


def test_fk_and_finite_differences_agree_with_qd_and_qdd() -> None:
    # The tip velocity J(q) qd is the speed along the tangent, and qd, qdd are the derivatives of
    # q(t): both converge with the sampling (second order for qd, at least first for qdd).
    errors = []
    for count in (500, 1000, 2000):
        q, s, tangent = line_2r(count)
        timed = time_scale(q, s, [0.45, 0.55], TIP, ACC)
        np.testing.assert_allclose(two_link_fk(q[:, 0], q[:, 1], L1, L2)[0], (1.6, -0.6), atol=1e-12)
        tip = np.einsum("nij,nj->ni", jacobian_2r(q), timed.qd)
        fk = np.max(np.abs(tip - timed.speed[:, None] * tangent))
        qd = np.max(np.abs(np.gradient(q, timed.t, axis=0)[1:-1] - timed.qd[1:-1]))
        qdd = np.sqrt(np.mean((np.gradient(timed.qd, timed.t, axis=0) - timed.qdd) ** 2))
        errors.append((fk, qd, qdd))
    errors = np.array(errors)
    assert np.all(errors[-1] < [1e-6, 1e-3, 2e-4]), errors
    assert np.all(errors[1:, 0] < errors[:-1, 0] / 3.0), errors  # second order
    assert np.all(errors[1:, 1:] < errors[:-1, 1:] / 1.5), errors


@pytest.mark.parametrize(
    ("q", "s", "vmax", "tip", "acc", "match"),
    [
        ([[0.0], [np.nan]], [0.0, 1.0], [1.0], 1.0, 1.0, "finite"),
        ([[0.0], [1.0]], [0.5, 1.0], [1.0], 1.0, 1.0, "start at 0"),
        ([[0.0], [1.0], [2.0]], [0.0, 1.0, 1.0], [1.0], 1.0, 1.0, "strictly"),
        ([[0.0], [1.0]], [0.0, 1.0], [0.0], 1.0, 1.0, "joint speed"),
        ([[0.0], [1.0]], [0.0, 1.0], [np.nan], 1.0, 1.0, "joint speed"),
        ([[0.0], [1.0]], [0.0, 1.0], [1.0], 0.0, 1.0, "tip_speed"),
        ([[0.0], [1.0]], [0.0, 1.0], [1.0], np.inf, 1.0, "tip_speed"),
        ([[0.0], [1.0]], [0.0, 1.0], [1.0], 1.0, np.nan, "acceleration"),
        ([[0.0], [1.0]], [0.0, 1.0], [1.0], 1.0, -1.0, "acceleration"),
        ([[0.0], [1.0]], [0.0, 1.0], [1.0, 1.0], 1.0, 1.0, "need q"),
        ([[0.0], [1e300], [0.0]], [0.0, 1e-300, 2e-300], [1.0], 1.0, 1.0, "overflows"),
    ],
)
def test_bad_input_is_refused(q, s, vmax, tip, acc, match) -> None:
    with pytest.raises(ValueError, match=match):
        time_scale(q, s, vmax, tip, acc)
