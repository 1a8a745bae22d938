"""Excavator plan_path (excavator_kinematics.core.path): straight tip lines at a constant bucket angle,
timed within every actuator's max speed, the tip speed and the acceleration bound; a path that
leaves the workspace ends at the farthest reachable point."""

from __future__ import annotations

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.path import END_TOLERANCE, plan_path
from manipulator_kinematics.plan_bounds import MAX_POINTS, MAX_WAYPOINTS
from manipulator_kinematics.time_scaling import ACCELERATION, TIP_SPEED

EXC = Excavator.default()
REFERENCE = EXC.limits.reference
START = EXC.pose(REFERENCE)[:3]
WAYPOINTS = np.array([START, START + [1.5, 0.0, 0.0], START + [1.5, 0.0, -1.0], START + [1.5, 2.0, -1.0]])
MAX_RATES = EXC.limits.max_rates


def on_polyline(points: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    """Distance (m) of each point to the nearest segment of the polyline."""
    a, b = waypoints[:-1], waypoints[1:]
    d = b - a
    u = np.clip(np.einsum("nkj,kj->nk", points[:, None] - a, d) / np.einsum("kj,kj->k", d, d), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + u[..., None] * d), axis=-1).min(axis=1)


@pytest.mark.parametrize(("tip_speed", "acceleration"), [(0.3, 0.5), (2.0, 5.0)])
def test_straight_lines_at_the_seed_angle_within_every_limit(tip_speed: float, acceleration: float) -> None:
    plan = plan_path(EXC, WAYPOINTS, 0.02, tip_speed, acceleration, seed=REFERENCE)
    assert plan.ok and not plan.truncated and plan.last_waypoint == 3, plan.message
    timing = plan.timing
    Q = EXC.pose(timing.q)
    assert on_polyline(Q[:, :3], WAYPOINTS).max() < 1e-9
    np.testing.assert_allclose(Q[:, 3], EXC.pose(REFERENCE)[3], atol=1e-9)
    np.testing.assert_allclose(Q[[0, -1], :3], WAYPOINTS[[0, -1]], atol=1e-9)
    # Limits: every actuator, the tip, the acceleration; at rest at both ends.
    usage = np.abs(timing.qd) / MAX_RATES
    assert usage.max() <= 1.0 + 1e-12 and timing.speed.max() <= tip_speed * (1.0 + 1e-12)
    assert np.abs(timing.sdd).max() <= acceleration * (1.0 + 1e-9)
    assert np.all(timing.qd[[0, -1]] == 0.0) and timing.speed[0] == timing.speed[-1] == 0.0
    # Slowed only where needed: below the tip speed, off the acceleration curves, an actuator binds.
    # A joint at its limit "at the sample or on a chord next to it" (time_scaling's definition):
    # its usage is the largest of the sample's rate and the rates along the adjacent chords.
    chord = np.abs(np.diff(timing.q, axis=0)) / np.diff(timing.s)[:, None]
    along = np.maximum(np.vstack([chord[:1], chord]), np.vstack([chord, chord[-1:]])) * timing.speed[:, None]
    limit_usage = np.maximum(usage, along / MAX_RATES)
    joint = timing.active >= 0
    np.testing.assert_allclose(limit_usage[joint, timing.active[joint]], 1.0, rtol=1e-9)
    np.testing.assert_allclose(timing.speed[timing.active == TIP_SPEED], tip_speed, rtol=1e-12)
    assert set(np.unique(timing.active)) <= {TIP_SPEED, ACCELERATION, 0, 1, 2, 3}
    if tip_speed == 2.0:
        assert joint.sum() > 50  # boom and arm cylinders at their max speed on the lines in x and z
    else:
        assert (timing.active == TIP_SPEED).sum() > 100
    # Velocities and accelerations are the time derivatives of the positions (finite differences).
    dt = np.diff(timing.t)
    np.testing.assert_allclose(
        np.diff(timing.q, axis=0) / dt[:, None], 0.5 * (timing.qd[1:] + timing.qd[:-1]), atol=2e-3
    )
    # At a corner the path is at rest and the acceleration jumps (braking -> starting): the
    # intervals next to it are left out of the acceleration check.
    corner = np.flatnonzero(timing.speed[1:-1] == 0.0) + 1
    assert len(corner) == 2  # the two corners of the three lines
    smooth = ~np.isin(np.arange(len(dt)), np.concatenate((corner - 1, corner)))
    np.testing.assert_allclose(
        (np.diff(timing.qd, axis=0) / dt[:, None])[smooth],
        (0.5 * (timing.qdd[1:] + timing.qdd[:-1]))[smooth],
        atol=0.05 * acceleration,
    )
    # Tip velocity along the line = the timed speed (JC0 Ddot, eq. 8), to the O(step^2) of the
    # sampled path derivative (2e-6 m/s measured at 0.02 m).
    tip = EXC.state(timing.q, timing.qd).Q_dot[:, :3]
    np.testing.assert_allclose(np.linalg.norm(tip, axis=1), timing.speed, atol=1e-5)


def test_without_a_seed_the_angle_of_the_first_waypoints_solution() -> None:
    plan = plan_path(EXC, WAYPOINTS[:2], 0.05, 0.5, 0.5)
    free = EXC.position_ik(WAYPOINTS[0])
    assert plan.ok and plan.alpha == pytest.approx(EXC.pose(free.solution)[3], abs=1e-12)
    np.testing.assert_allclose(plan.timing.q[0], free.solution, atol=1e-9)


def test_a_path_leaving_the_workspace_ends_at_the_farthest_reachable_point() -> None:
    waypoints = [START, START + [0.5, 0.0, 0.0], START + [8.5, 0.0, 0.0], START + [8.5, 0.0, -2.0]]
    plan = plan_path(EXC, waypoints, 0.05, 0.5, 0.5, seed=REFERENCE)
    assert plan.ok and plan.truncated and plan.last_waypoint == 1
    assert "waypoint 2" in plan.message and "arm_cylinder" in plan.message and "farthest" in plan.message
    end = plan.points[-1]
    direction = np.array([1.0, 0.0, 0.0])
    alpha = plan.alpha
    inside = EXC.ik(np.append(end, alpha))
    beyond = EXC.ik(np.append(end + 2 * END_TOLERANCE * direction, alpha))
    assert inside.ok and not beyond.ok
    np.testing.assert_allclose(EXC.pose(plan.timing.q[-1])[:3], end, atol=1e-9)
    assert plan.timing.speed[-1] == 0.0


def test_requests_it_cannot_take() -> None:
    unreachable = plan_path(EXC, [[20.0, 0.0, 0.0], START], 0.05, 0.5, 0.5)
    assert not unreachable.ok and unreachable.last_waypoint == -1 and "first waypoint" in unreachable.message
    with pytest.raises(ValueError, match=f"at most {MAX_POINTS}"):
        plan_path(EXC, [START, START + [1000.0, 0.0, 0.0]], 0.01, 0.5, 0.5)
    with pytest.raises(ValueError, match="acceleration"):
        plan_path(EXC, [START], 0.05, 0.5, 0.0)
    # The bounds of every machine's plan (manipulator_kinematics.plan_bounds), before any work.
    with pytest.raises(ValueError, match=r"tip_speed 1e-300 m/s is outside \[0\.001, 10\]"):
        plan_path(EXC, [START], 0.05, 1e-300, 0.5)
    for step, speed, what in ((1e300, 0.5, "step 1e\\+300 m"), (0.05, 1e300, "tip_speed 1e\\+300 m/s")):
        with pytest.raises(ValueError, match=what):
            plan_path(EXC, [START], step, speed, 0.5)
    with pytest.raises(ValueError, match=f"1 <= K <= {MAX_WAYPOINTS}"):
        plan_path(EXC, [START] * (MAX_WAYPOINTS + 1), 0.05, 0.5, 0.5)
    with pytest.raises(ValueError, match=r"at least 7\.99e\+05 s at 0\.001 m/s; at most 86400 s"):
        plan_path(EXC, [START, START + [1.0, 0.0, 0.0]] * 400, 0.5, 1e-3, 0.5, seed=REFERENCE)
    one = plan_path(EXC, [START], 0.05, 0.5, 0.5, seed=REFERENCE)
    assert one.ok and len(one.timing.t) == 1 and one.timing.duration == 0.0
