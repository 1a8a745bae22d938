"""The hydraulic family's plan_path, grade and old executable names over DDS (isolated domain):
hydraulic_ik_server plans straight tool-point lines for the wheel loader and the knuckle crane (the
planned D's FK on the lines, inside the stroke box, within every speed, the library's plan) and
refuses what it cannot do; hydraulic_forward publishes the tool's grade above a LandXML surface
(heights against the plane by hand); excavator_forward and excavator_ik_server given a family
machine file run the family nodes (the loader's pose; the crane's plan ended before a zone)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Point, PointStamped, PoseStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_harness import NodeProcess, Probe, start_with_services
from sensor_msgs.msg import JointState

from manipulator_kinematics.hydraulic.path import plan_clear, plan_path
from manipulator_kinematics.landxml import Tin, write_landxml
from manipulator_kinematics.registry import machine
from manipulator_kinematics.zones import load_zones
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes as Codes
from manipulator_kinematics_interfaces.srv import PlanPath

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: s. The crane's plan up past its reach takes 3.8 s alone (its position IK is numerical, 0.12 s a
#: call, and the farthest reachable point is found by bisection); a loaded CI machine (load 8-13
#: on 2 cores) stretches that past 30 s.
TIMEOUT = 90.0
QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: The server's plan_path defaults (config/hydraulic_nodes.yaml): step, tip speed, acceleration.
DEFAULTS = (0.05, 0.5, 0.5)


def on_polyline(points: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    """Distance (m) of each point to the nearest segment of the polyline."""
    a, b = waypoints[:-1], waypoints[1:]
    d = b - a
    u = np.clip(np.einsum("nkj,kj->nk", points[:, None] - a, d) / np.einsum("kj,kj->k", d, d), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + u[..., None] * d), axis=-1).min(axis=1)


def path_request(waypoints, names, seed=None, step: float = 0.0) -> PlanPath.Request:
    request = PlanPath.Request(step=step)
    request.waypoints = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in waypoints]
    if seed is not None:
        request.seed = JointState(name=list(names), position=[float(v) for v in seed])
    return request


def positions(response: PlanPath.Response) -> np.ndarray:
    return np.array([p.positions for p in response.trajectory.points])


#: From the reference tool point (as test_hydraulic_path.py): the loader up and forward in its
#: plane, then up more steeply; the crane out, across and up.
LEGS = {
    "wheel_loader": ([0.25, 0.0, 0.5], [0.45, 0.0, 1.6]),
    "knuckle_crane": ([0.6, 0.0, 0.0], [0.6, 0.8, 0.3]),
}


@pytest.mark.parametrize("name", list(LEGS))
def test_plan_path_follows_the_lines_within_the_stroke_box_and_speeds(probe: Probe, name: str) -> None:
    entry = machine(name)
    arm = entry.model()
    h = arm.hydraulic
    names = list(arm.joint_names)
    ns = f"/plan_{name}"
    process, (planner,) = start_with_services(
        probe,
        "hydraulic_ik_server",
        *entry.node_arguments,
        "-r",
        f"__ns:={ns}",
        services=((PlanPath, "plan_path"),),
        timeout=TIMEOUT,
        namespace=ns,
    )
    try:
        start = h.pose(h.reference)[:3]
        waypoints = np.array([start, *(start + np.array(leg) for leg in LEGS[name])])
        response = probe.call(planner, path_request(waypoints, names, seed=h.reference), TIMEOUT)
        assert response.success and response.error_code.val == Codes.SUCCESS, response.message
        assert response.last_reachable_waypoint == 2
        assert list(response.trajectory.joint_names) == names
        D = positions(response)
        # FK of the planned D (the tool pose the forward node would publish) is on the lines.
        tool = arm.fkine(D)[:, :3, 3]
        assert on_polyline(tool, waypoints).max() < 1e-9
        np.testing.assert_allclose(tool[[0, -1]], waypoints[[0, -1]], atol=1e-9)
        assert np.array_equal(np.clip(D, arm.limits.lower, arm.limits.upper), D)  # the stroke box
        velocities = np.array([p.velocities for p in response.trajectory.points])
        assert np.all(np.abs(velocities) <= h.max_speed * (1 + 1e-12))
        assert np.all(velocities[[0, -1]] == 0.0)
        t = np.array(
            [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in response.trajectory.points]
        )
        speed = np.linalg.norm(np.diff(tool, axis=0), axis=1) / np.diff(t)
        assert speed.max() <= DEFAULTS[1] * 1.01  # chords of the timed path: within the tip speed
        # The library's plan, sent as it is.
        expected = plan_path(h, waypoints, *DEFAULTS, seed=h.reference).timing
        np.testing.assert_allclose(D, expected.q, atol=1e-12)
        np.testing.assert_allclose(t, expected.t, atol=1e-9)

        # Refusals: the loader off its plane, the crane up beyond its reach (the part up to there
        # is sent), and a request beyond the bounds of every plan.
        if name == "wheel_loader":
            off = probe.call(planner, path_request([start + [0.0, 0.5, 0.0]], names), TIMEOUT)
            assert not off.success and off.error_code.val == Codes.NO_IK_SOLUTION
            assert off.last_reachable_waypoint == -1 and not off.trajectory.points
            assert "no swing: the tool stays at y = 0" in off.message, off.message
        else:
            up = [start, start + [0.2, 0.0, 0.0], start + [0.2, 0.0, 30.0]]
            short = probe.call(planner, path_request(up, names, seed=h.reference), TIMEOUT)
            assert not short.success and short.error_code.val == Codes.NO_IK_SOLUTION
            assert short.last_reachable_waypoint == 1 and "farthest reachable point" in short.message
            assert "beyond the linkage's reach" in short.message, short.message
            reached = arm.fkine(positions(short))[:, :3, 3]
            assert on_polyline(reached, np.array(up)).max() < 1e-9 and reached[-1, 2] > start[2] + 1.0
            assert list(short.trajectory.points[-1].velocities) == [0.0] * h.m
        bad = probe.call(planner, path_request([start], names, step=-1.0), TIMEOUT)
        assert not bad.success and bad.error_code.val == Codes.INVALID_GOAL_CONSTRAINTS
        assert "step -1 m is outside" in bad.message
        nan = probe.call(planner, path_request([start, [math.nan, 0.0, 0.0]], names), TIMEOUT)
        assert not nan.success and nan.error_code.val == Codes.INVALID_GOAL_CONSTRAINTS
        far = probe.call(planner, path_request([start, [1e300, 0.0, 0.0]], names), TIMEOUT)
        assert not far.success and "implausible" in far.message
        seed = probe.call(planner, path_request([start], names[:-1], seed=h.reference[:-1]), TIMEOUT)
        assert not seed.success and seed.error_code.val == Codes.INVALID_ROBOT_STATE, seed.message
        mode = PlanPath.Request(mode="region", waypoints=[Point(x=start[0], y=start[1], z=start[2])])
        assert probe.call(planner, mode, TIMEOUT).error_code.val == Codes.INVALID_MODE
        # A seed outside the stroke box is moved into it (as the excavator's): a plan from there.
        outside = probe.call(planner, path_request(waypoints[:2], names, seed=h.upper + 0.5), TIMEOUT)
        assert outside.success or outside.error_code.val == Codes.NO_IK_SOLUTION, outside.message
        assert process.alive()
    finally:
        log = process.stop()
    assert "Traceback" not in log, log


def plane_tin(path: Path, origin: np.ndarray, slope: float) -> None:
    """A plane z = origin_z + slope (x - origin_x) over 40 m x 40 m about ``origin``, two triangles."""
    x0, y0, z0 = origin
    corners = np.array([[-20.0, -20.0], [20.0, -20.0], [20.0, 20.0], [-20.0, 20.0]])
    vertices = np.column_stack((x0 + corners[:, 0], y0 + corners[:, 1], z0 + slope * corners[:, 0]))
    write_landxml(path, Tin(vertices, np.array([[0, 1, 2], [0, 2, 3]]), "plane"))


def test_forward_node_publishes_the_tool_grade_over_a_surface(probe: Probe, tmp_path: Path) -> None:
    """hydraulic_forward for the wheel loader with a sloped design plane: tool point and the ends
    of its edge (the machine file's width across the boom plane) in the site frame, heights above
    the plane computed by hand; a site pose turned by a yaw."""
    entry = machine("wheel_loader")
    arm = entry.model()
    h = arm.hydraulic
    origin, slope, yaw = np.array([1000.0, 2000.0, 100.0]), 0.1, 0.3
    plane_tin(tmp_path / "plane.xml", origin, slope)
    position = origin + [2.0, -1.0, 0.5]
    surface = {
        "file": str(tmp_path / "plane.xml"),
        "surface": "",
        "site_frame": "site",
        "site_pose_source": "fixed",
        "site_position": position.tolist(),
        "site_rpy": [0.0, 0.0, yaw],
        "site_pose_max_age": 0.5,
    }
    ns = "/grade"
    got: dict[str, list] = {p: [] for p in ("tip", "left", "right", "status")}
    for p in ("tip", "left", "right"):
        probe.node.create_subscription(PointStamped, f"{ns}/grade/{p}", got[p].append, QOS)
    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    probe.node.create_subscription(DiagnosticArray, f"{ns}/grade/status", got["status"].append, latched)
    states = probe.node.create_publisher(JointState, f"{ns}/joint_states", QOS)
    D = 0.4 * h.lower + 0.6 * h.upper
    process = NodeProcess(
        "hydraulic_forward",
        *entry.node_arguments,
        "-r",
        f"__ns:={ns}",
        params={f"{ns}/hydraulic_forward": {"ros__parameters": {"design_surface": surface}}},
    )
    try:

        def heard() -> bool:
            msg = JointState(name=list(arm.joint_names), position=D.tolist())
            msg.header.stamp.sec = 7
            states.publish(msg)
            return bool(got["tip"] and got["left"] and got["right"]) or not process.alive()

        probe.wait_until(heard, TIMEOUT, "the grade of the tool")
        probe.wait_until(lambda: got["status"] or not process.alive(), TIMEOUT, "the grade status")
        assert process.alive(), process.log()
    finally:
        log = process.stop()
    assert "Traceback" not in log, log
    assert [s.level for s in got["status"][-1].status] == [DiagnosticStatus.OK] * 3
    # By hand: the tool point and the edge's ends (no swing: across is base y), turned by the
    # yaw into the site frame and moved to the machine's position; the plane's height below.
    tip = arm.fkine(D)[:3, 3]
    half = 0.5 * h.description.width
    assert half > 0.0
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    for p, across in (("tip", 0.0), ("left", half), ("right", -half)):
        site = R @ (tip + [0.0, across, 0.0]) + position
        height = site[2] - (origin[2] + slope * (site[0] - origin[0]))
        message = got[p][0]
        assert message.header.frame_id == "site" and message.header.stamp.sec == 7
        np.testing.assert_allclose(
            [message.point.x, message.point.y, message.point.z], [site[0], site[1], height], atol=1e-9
        )


def test_excavator_executables_run_the_family_node_for_a_family_file(probe: Probe, tmp_path: Path) -> None:
    """excavator_forward --params-file config/wheel_loader_wl20.yaml publishes the loader's tool
    pose; excavator_ik_server with the crane's file and a zone file plans the crane's path and
    ends it before the zone (the family server's plan_path)."""
    loader = machine("wheel_loader")
    arm = loader.model()
    ns = "/old_names"
    poses: list[np.ndarray] = []
    probe.node.create_subscription(
        PoseStamped,
        f"{ns}/tool_pose",
        lambda m: poses.append(np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])),
        QOS,
    )
    states = probe.node.create_publisher(JointState, f"{ns}/joint_states", QOS)
    D = 0.3 * arm.hydraulic.lower + 0.7 * arm.hydraulic.upper
    forward = NodeProcess("excavator_forward", *loader.node_arguments, "-r", f"__ns:={ns}")
    try:

        def heard() -> bool:
            states.publish(JointState(name=list(arm.joint_names), position=D.tolist()))
            return bool(poses) or not forward.alive()

        probe.wait_until(heard, TIMEOUT, "the loader's tool pose from excavator_forward")
        assert forward.alive(), forward.log()
    finally:
        log = forward.stop()
    assert "Traceback" not in log, log
    assert "wheel_loader" in log, log  # the family node's start-up line names the machine
    np.testing.assert_allclose(poses[0], arm.fkine(D)[:3, 3], atol=1e-9)

    crane = machine("knuckle_crane")
    h = crane.model().hydraulic
    top = float(h.monitored(h.reference, np.zeros(h.m))[1][:, 2].max())
    zones = tmp_path / "zones.yaml"
    zones.write_text(f"zones:\n  roof: {{kind: ceiling, height: {top + 0.4}, margin: 0.1}}\n")
    ns = "/old_names_crane"
    process, (planner,) = start_with_services(
        probe,
        "excavator_ik_server",
        *crane.node_arguments,
        "-p",
        f"zones_file:={zones}",
        "-r",
        f"__ns:={ns}",
        services=((PlanPath, "plan_path"),),
        timeout=TIMEOUT,
        namespace=ns,
    )
    try:
        start = h.pose(h.reference)[:3]
        waypoints = np.array([start, start + [0.0, 0.0, 2.0]])
        response = probe.call(planner, path_request(waypoints, h.actuator_names, seed=h.reference), TIMEOUT)
    finally:
        log = process.stop()
    assert "Traceback" not in log, log
    assert not response.success and response.error_code.val == Codes.NO_IK_SOLUTION
    assert "enters zone roof" in response.message and response.last_reachable_waypoint == 0, response.message
    expected = plan_clear(h, load_zones(zones), waypoints, *DEFAULTS, seed=h.reference).timing
    np.testing.assert_allclose(positions(response), expected.q, atol=1e-12)
