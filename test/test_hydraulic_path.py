"""The hydraulic family's plan_path without ROS (manipulator_kinematics.hydraulic.path): straight
tool-point lines for the wheel loader and the knuckle crane, checked by the model's own FK of the
planned D (the tool on the polyline), the stroke box, every actuator's max speed, the tip speed,
finite differences of the timing and eq. 8's tool velocity; refusals with their reasons (a point
the loader cannot reach off its plane, a line leaving the stroke box, an avoidance zone)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.hydraulic.path import AT_END, plan_clear, plan_path
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.time_scaling import ACCELERATION, TIP_SPEED
from manipulator_kinematics.tool_path import END_TOLERANCE
from manipulator_kinematics.zones import load_zones

LOADER = HydraulicModel.from_file(config_path("wheel_loader_wl20.yaml"))
CRANE = HydraulicModel.from_file(config_path("knuckle_crane_kc100.yaml"))


def on_polyline(points: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    """Distance (m) of each point to the nearest segment of the polyline."""
    a, b = waypoints[:-1], waypoints[1:]
    d = b - a
    u = np.clip(np.einsum("nkj,kj->nk", points[:, None] - a, d) / np.einsum("kj,kj->k", d, d), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + u[..., None] * d), axis=-1).min(axis=1)


def waypoints_of(h: HydraulicModel) -> np.ndarray:
    """From the reference tool point: the loader up and forward in its plane, then up more steeply
    (its tool point sweeps a band about the lift arm's arc); the crane out, across and up."""
    start = h.pose(h.reference)[:3]
    if h is LOADER:
        return np.array([start, start + [0.25, 0.0, 0.5], start + [0.45, 0.0, 1.6]])
    return np.array([start, start + [0.6, 0.0, 0.0], start + [0.6, 0.8, 0.3]])


@pytest.mark.parametrize("h", [LOADER, CRANE], ids=["wheel_loader", "knuckle_crane"])
@pytest.mark.parametrize(("tip_speed", "acceleration"), [(0.2, 0.5), (2.0, 3.0)])
def test_straight_lines_within_the_stroke_box_and_every_speed(
    h: HydraulicModel, tip_speed: float, acceleration: float
) -> None:
    waypoints = waypoints_of(h)
    plan = plan_path(h, waypoints, 0.02, tip_speed, acceleration, seed=h.reference)
    assert plan.ok and not plan.truncated and plan.last_waypoint == 2, plan.message
    timing = plan.timing
    D = timing.q
    # FK of the planned D (the model's own, through the linkages) is on the lines, ends included.
    Q = h.pose(D)
    assert on_polyline(Q[:, :3], waypoints).max() < 1e-9
    np.testing.assert_allclose(Q[[0, -1], :3], waypoints[[0, -1]], atol=1e-9)
    np.testing.assert_allclose(plan.points, Q[:, :3], atol=1e-9)
    assert np.all((h.lower <= D) & (h.upper >= D))
    if h is CRANE:  # the telescope is held: the tool point fixes the other three actuators
        np.testing.assert_array_equal(D[:, -1], h.reference[-1])
    usage = np.abs(timing.qd) / h.max_speed
    assert usage.max() <= 1.0 + 1e-12 and timing.speed.max() <= tip_speed * (1.0 + 1e-12)
    assert np.abs(timing.sdd).max() <= acceleration * (1.0 + 1e-9)
    assert np.all(timing.qd[[0, -1]] == 0.0) and timing.speed[0] == timing.speed[-1] == 0.0
    # Slowed only where needed: a sample set by an actuator has it at its max speed (at the
    # sample or on a chord next to it: time_scaling's definition), one set by the tip speed is at it.
    chord = np.abs(np.diff(D, axis=0)) / np.diff(timing.s)[:, None]
    along = np.maximum(np.vstack([chord[:1], chord]), np.vstack([chord, chord[-1:]])) * timing.speed[:, None]
    limit_usage = np.maximum(usage, along / h.max_speed)
    joint = timing.active >= 0
    np.testing.assert_allclose(limit_usage[joint, timing.active[joint]], 1.0, rtol=1e-9)
    np.testing.assert_allclose(timing.speed[timing.active == TIP_SPEED], tip_speed, rtol=1e-12)
    assert set(np.unique(timing.active)) <= {TIP_SPEED, ACCELERATION, *range(h.m)}
    # Velocities are the time derivatives of the positions (finite differences), away from the
    # corner, where the path is at rest and the acceleration jumps.
    dt = np.diff(timing.t)
    corner = np.flatnonzero(timing.speed[1:-1] == 0.0) + 1
    assert len(corner) == 1
    smooth = ~np.isin(np.arange(len(dt)), np.concatenate((corner - 1, corner)))
    np.testing.assert_allclose(
        (np.diff(D, axis=0) / dt[:, None])[smooth],
        (0.5 * (timing.qd[1:] + timing.qd[:-1]))[smooth],
        atol=5e-3 * h.max_speed.max(),  # O(step) at 0.02 m: 0.8e-3 x measured at the start
    )
    # The tool's velocity, JC0 Ddot (eq. 8), is the timed speed along the line.
    tool = h.state(D, timing.qd).Q_dot[:, :3]
    np.testing.assert_allclose(np.linalg.norm(tool, axis=1), timing.speed, atol=1e-4)


def test_the_loader_cannot_leave_its_plane() -> None:
    start = LOADER.pose(LOADER.reference)[:3]
    plan = plan_path(LOADER, [start + [0.0, 0.5, 0.0]], 0.05, 0.5, 0.5)
    assert not plan.ok and plan.last_waypoint == -1
    assert "not reachable" in plan.message and "no swing: the tool stays at y = 0" in plan.message


@pytest.mark.parametrize("h", [LOADER, CRANE], ids=["wheel_loader", "knuckle_crane"])
def test_a_line_leaving_the_workspace_ends_at_its_farthest_point(h: HydraulicModel) -> None:
    """Straight up: the loader's tilt cylinder reaches its end (beyond it the other tilt branch
    reaches the line: a jump), the crane's chain its reach; the reason says which, and the state
    at the end agrees."""
    start = h.pose(h.reference)[:3]
    side = [0.25, 0.0, 0.5] if h is LOADER else [0.2, 0.0, 0.0]
    waypoints = np.array([start, start + side, start + side + [0.0, 0.0, 30.0]])
    plan = plan_path(h, waypoints, 0.05, 0.5, 0.5, seed=h.reference)
    assert plan.ok and plan.truncated and plan.last_waypoint == 1, plan.message
    assert "waypoint 2" in plan.message and "the path ends at the farthest reachable point" in plan.message
    assert on_polyline(h.pose(plan.timing.q)[:, :3], waypoints).max() < 1e-9
    # The end is the boundary of the reachable line: a little farther up is not reachable with
    # the same hold on the same branch (the loader's other tilt branch may reach it, by a jump).
    D = plan.timing.q[-1]
    end = h.pose(D)[:3]
    assert end[2] > start[2] + 0.1
    beyond = h.position_ik(end + [0.0, 0.0, 10 * END_TOLERANCE], D)
    assert not bool(beyond.valid) or np.abs(beyond.D - D).max() > 0.1, beyond
    margin = np.minimum(D - h.lower, h.upper - D) / (h.upper - h.lower)
    i = int(np.argmin(margin))
    if h is LOADER:
        assert margin[i] < 1e-6 and f"{h.actuator_names[i]} would jump" in plan.message, plan.message
    else:
        assert margin[i] > AT_END and "beyond the linkage's reach" in plan.message, plan.message


def test_a_path_ends_before_a_ceiling(tmp_path: Path) -> None:
    h = CRANE
    start = h.pose(h.reference)[:3]
    p = h.monitored(h.reference, np.zeros(h.m))[1]
    roof = float(p[:, 2].max()) + 0.4
    file = tmp_path / "zones.yaml"
    file.write_text(f"zones:\n  roof: {{kind: ceiling, height: {roof}, margin: 0.1}}\n")
    zones = load_zones(file)
    waypoints = np.array([start, start + [0.0, 0.0, 2.0]])
    plan = plan_clear(h, zones, waypoints, 0.02, 0.5, 0.5, seed=h.reference)
    assert plan.ok and plan.truncated and plan.last_waypoint == 0, plan.message
    assert "enters zone roof" in plan.message
    highest = h.monitored(plan.timing.q, np.zeros_like(plan.timing.q))[1][..., 2].max()
    assert roof - 0.1 - 0.05 < highest < roof - 0.1  # stopped within a step of the zone's margin
    assert np.all(plan.timing.qd[-1] == 0.0)
    # Started inside one: refused, no trajectory.
    low = tmp_path / "low.yaml"
    low.write_text(f"zones:\n  roof: {{kind: ceiling, height: {float(p[:, 2].max()) - 0.5}}}\n")
    refused = plan_clear(h, load_zones(low), waypoints, 0.02, 0.5, 0.5, seed=h.reference)
    assert not refused.ok and refused.last_waypoint == -1 and "starts inside a zone" in refused.message


@pytest.mark.slow
@pytest.mark.parametrize("h", [LOADER, CRANE], ids=["wheel_loader", "knuckle_crane"])
def test_random_requests_give_a_plan_within_every_limit_or_a_reason(h: HydraulicModel) -> None:
    """Waypoints scattered about the tool (many off the loader's plane or out of reach), seeds
    anywhere (moved into the stroke box): every answer is a plan on the lines, inside the stroke
    box and the speeds, up to its last reached point, or none with the reason; nothing raises."""
    rng = np.random.default_rng(31)
    start = h.pose(h.reference)[:3]
    planned = refused = 0
    for _ in range(12):
        waypoints = start + rng.normal(scale=0.6, size=(int(rng.integers(1, 4)), 3))
        if h is LOADER and rng.random() < 0.7:
            waypoints[:, 1] = 0.0
        if h is CRANE and rng.random() < 0.3:
            waypoints[0, 2] += 15.0  # above its reach
        seed = h.lower + rng.uniform(-0.2, 1.2, h.m) * (h.upper - h.lower)
        plan = plan_path(h, waypoints, float(rng.uniform(0.02, 0.1)), 0.5, 0.5, seed=seed)
        assert plan.message
        if not plan.ok:
            refused += 1
            assert plan.last_waypoint == -1 and "not reachable" in plan.message, plan.message
            continue
        planned += 1
        D = plan.timing.q
        assert np.all(np.isfinite(D)) and np.all(np.isfinite(plan.timing.qd))
        assert np.array_equal(np.clip(D, h.lower, h.upper), D)
        assert np.all(np.abs(plan.timing.qd) <= h.max_speed * (1 + 1e-12))
        reached = waypoints[: plan.last_waypoint + 1]
        if plan.truncated:  # on the lines through the waypoints reached and the next one
            reached = waypoints[: plan.last_waypoint + 2]
        if len(reached) > 1:
            assert on_polyline(h.pose(D)[:, :3], reached).max() < 1e-9
    assert planned and refused  # both kinds were asked
