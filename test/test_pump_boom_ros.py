"""Pump boom nodes across processes (isolated domain): solve_ik / solve_fk round trips and their
failures against a real ``pump_boom_ik_server``, ``plan_path`` for the paper's typical pours and a
truncated one (the trajectory, with its velocities and accelerations, equals the library's plan),
every degenerate plan request refused with INVALID_GOAL_CONSTRAINTS and its reason, solve_ik
answered while a long plan runs, a server on a changed geometry (FK yes, region IK refused with
the fix), and ``pump_boom_forward``'s tip pose and twist."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import pytest
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, PoseStamped, TwistStamped
from ros_harness import IK_FK, RELIABLE_INPUTS, NodeProcess, Probe, start_with_services
from sensor_msgs.msg import JointState

from manipulator_kinematics.model import matrix_quaternion
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes as Codes
from manipulator_kinematics_interfaces.srv import PlanPath, SolveFK, SolveIK
from pump_boom_kinematics.kinematics import PumpBoom
from pump_boom_kinematics.pour import MAX_POINTS, MAX_WAYPOINTS, TYPICAL_POURS, plan_path, pour_line

pytestmark = pytest.mark.ros

NAMES = [
    "slew_joint",
    "section_1_joint",
    "section_2_joint",
    "section_3_joint",
    "section_4_joint",
    "section_5_joint",
]
PARAMS = str(config_path("pump_boom.yaml"))
TIMEOUT = 20.0
CHANGED_LENGTHS = [9.7, 8.4, 8.2, 8.6, 6.7]  # section 1 0.1 m longer than the table was built for


@pytest.fixture(scope="module")
def boom() -> PumpBoom:
    return PumpBoom.default()


def start_server(
    probe: Probe, *ros_args: str, namespace: str = ""
) -> tuple[NodeProcess, object, object, object]:
    process, clients = start_with_services(
        probe,
        "pump_boom_ik_server",
        "--params-file",
        PARAMS,
        *ros_args,
        services=(*IK_FK, (PlanPath, "plan_path")),
        timeout=TIMEOUT,
        namespace=namespace,
    )
    return process, *clients


@pytest.fixture(scope="module")
def server(probe: Probe, boom: PumpBoom) -> Iterator[tuple[NodeProcess, object, object, object]]:
    process, ik, fk, plan = start_server(probe)
    try:
        yield process, ik, fk, plan
    finally:
        log = process.stop()
        assert "Traceback" not in log and f"region table: {len(boom.table)} squares" in log, log


def call(probe: Probe, client, request):
    return probe.call(client, request, TIMEOUT)


def ik_request(
    point, use_orientation: bool = False, seed=None, mode: str = "", branch: str = "", frame: str = ""
) -> SolveIK.Request:
    request = SolveIK.Request(mode=mode, branch=branch, use_orientation=use_orientation)
    request.target.header.frame_id = frame
    p = request.target.pose.position
    p.x, p.y, p.z = (float(v) for v in point)
    if seed is not None:
        request.seed = JointState(name=NAMES, position=[float(v) for v in seed])
    return request


def fk_request(q, qd=None, stamp: Time | None = None) -> SolveFK.Request:
    state = JointState(
        name=NAMES, position=[float(v) for v in q], velocity=[] if qd is None else [float(v) for v in qd]
    )
    if stamp is not None:
        state.header.stamp = stamp
    return SolveFK.Request(joint_state=state)


def plan_request(
    waypoints, step: float = 0.0, tip_speed: float = 0.0, seed=None, mode: str = ""
) -> PlanPath.Request:
    request = PlanPath.Request(step=step, tip_speed=tip_speed, mode=mode)
    request.waypoints = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in waypoints]
    if seed is not None:
        request.seed = JointState(name=NAMES, position=[float(v) for v in seed])
    return request


def seconds(duration: Duration) -> float:
    return duration.sec + 1e-9 * duration.nanosec


def assert_trajectory_is_the_plan(trajectory, plan) -> None:
    """Times, positions, velocities and accelerations of the trajectory are the plan's, at rest at
    both ends."""
    t = np.array([seconds(point.time_from_start) for point in trajectory.points])
    np.testing.assert_allclose(t, plan.t, atol=1e-9)
    for field, expected in (("positions", plan.q), ("velocities", plan.qd), ("accelerations", plan.qdd)):
        np.testing.assert_allclose(
            np.array([getattr(p, field) for p in trajectory.points]), expected, atol=1e-12, err_msg=field
        )
    np.testing.assert_array_equal(trajectory.points[0].velocities, 0.0)
    np.testing.assert_array_equal(trajectory.points[-1].velocities, 0.0)


def test_solve_ik_round_trip_over_the_table_and_solve_fk(probe: Probe, server, boom: PumpBoom) -> None:
    _, ik, fk, _ = server
    rng = np.random.default_rng(5)
    squares = boom.table.index[rng.integers(0, len(boom.table), 12)]
    plane = np.stack(boom.grid.corner(squares[:, 0] + 0.05, squares[:, 1] + 0.05, squares[:, 2]), axis=-1)
    plane += 0.9 * boom.grid.side(squares[:, 2])[:, None] * rng.random((12, 2))
    heading = rng.uniform(-math.pi, math.pi, 12)
    targets = np.stack([plane[:, 0] * np.cos(heading), plane[:, 0] * np.sin(heading), plane[:, 1]], axis=-1)
    for k, target in enumerate(targets):
        response = call(probe, ik, ik_request(target, mode="region" if k % 2 else ""))
        assert response.success and response.error_code.val == Codes.SUCCESS, response.message
        assert list(response.solution.name) == NAMES and "region mode: square" in response.message
        q = np.array(response.solution.position)
        assert len(response.solutions) == 1
        np.testing.assert_array_equal(response.solutions[0].position, q)
        np.testing.assert_allclose(q, boom.region_ik(target).q, atol=1e-12)
        np.testing.assert_allclose(boom.tip(q), target, atol=1e-9)  # the plane geometry, not the D-H chain
        # solve_fk of the solution returns the target; the twist is the tip Jacobian times the rates.
        qd = rng.normal(scale=0.05, size=6)
        stamp = Time(sec=40 + k, nanosec=7)
        answer = call(probe, fk, fk_request(q, qd, stamp))
        assert answer.success and answer.error_code.val == Codes.SUCCESS, answer.message
        assert answer.pose.header.stamp == stamp and answer.pose.header.frame_id == "base_link"
        p, o = answer.pose.pose.position, answer.pose.pose.orientation
        np.testing.assert_allclose([p.x, p.y, p.z], target, atol=1e-9)
        np.testing.assert_allclose([o.x, o.y, o.z, o.w], matrix_quaternion(boom.fkine(q)[:3, :3]), atol=1e-12)
        v, w = answer.twist.twist.linear, answer.twist.twist.angular
        np.testing.assert_allclose([v.x, v.y, v.z], boom.tip_jacobian(q) @ qd, atol=1e-9)
        np.testing.assert_allclose([w.x, w.y, w.z], boom.jacob0(q)[3:] @ qd, atol=1e-12)


def test_behind_the_slew_axis_the_seed_picks_the_slew_turn(probe: Probe, server, boom: PumpBoom) -> None:
    _, ik, _, _ = server
    behind = [-20.0, 5.0, 17.5]
    plain = call(probe, ik, ik_request(behind))
    assert plain.success, plain.message
    assert plain.solution.position[0] == pytest.approx(math.atan2(5.0, -20.0), abs=1e-12)
    turned = call(probe, ik, ik_request(behind, seed=[-3.0, 1.0, 2.0, 2.0, 2.0, 2.0]))
    assert turned.success, turned.message
    assert turned.solution.position[0] == pytest.approx(math.atan2(5.0, -20.0) - 2 * math.pi, abs=1e-12)
    np.testing.assert_allclose(boom.tip(turned.solution.position), behind, atol=1e-9)


BAD_IK = {
    "outside the table": (
        ik_request([40.7, 0.0, 12.0]),
        Codes.NO_IK_SOLUTION,
        "outside the region table: no square covers it (its 5 m square (8, 2)",
    ),
    "beyond the reach": (ik_request([60.0, 0.0, 3.6]), Codes.NO_IK_SOLUTION, "beyond the boom's reach"),
    "on the slew axis": (ik_request([0.0, 0.0, 10.0]), Codes.NO_IK_SOLUTION, "behind the boom root pin"),
    "behind the root pin": (ik_request([-0.1, 0.05, 10.0]), Codes.NO_IK_SOLUTION, "behind the boom root pin"),
    "orientation": (
        ik_request([20.0, 5.0, 17.5], use_orientation=True),
        Codes.INVALID_GOAL_CONSTRAINTS,
        "position only",
    ),
    "nan": (ik_request([math.nan, 0.0, 17.5]), Codes.INVALID_GOAL_CONSTRAINTS, "not finite"),
    "mode": (ik_request([20.0, 5.0, 17.5], mode="phi"), Codes.INVALID_MODE, "unknown IK mode 'phi'"),
    "branch": (ik_request([20.0, 5.0, 17.5], branch="elbow_a"), Codes.INVALID_MODE, "unknown branch"),
    "frame": (ik_request([20.0, 5.0, 17.5], frame="map"), Codes.FRAME_TRANSFORM_FAILURE, "'map'"),
    "seed nan": (
        ik_request([20.0, 5.0, 17.5], seed=[0.0, math.nan, 2.0, 2.0, 2.0, 2.0]),
        Codes.INVALID_ROBOT_STATE,
        "non-finite",
    ),
}


def test_bad_ik_and_fk_requests_fail_with_a_code_and_a_reason(probe: Probe, server) -> None:
    process, ik, fk, _ = server
    for name, (request, code, text) in BAD_IK.items():
        response = call(probe, ik, request)
        assert not response.success, name
        assert response.error_code.val == code, (name, response.error_code.val, response.message)
        assert text in response.message, (name, response.message)
        assert len(response.solution.position) == 0 and len(response.solutions) == 0, name
    straight = [0.0, math.pi / 2, math.pi, math.pi, math.pi, math.pi]
    fk_cases = {
        "nan": (fk_request([0.0, math.nan, 3.0, 3.0, 3.0, 3.0]), Codes.INVALID_ROBOT_STATE, "non-finite"),
        "limits": (
            fk_request([0.0, 2.0, 3.0, 3.0, 3.0, 3.0]),
            Codes.JOINT_LIMITS_VIOLATED,
            "section_1_joint",
        ),
        "missing": (
            SolveFK.Request(joint_state=JointState(name=NAMES[:5], position=straight[:5])),
            Codes.INVALID_ROBOT_STATE,
            "['section_5_joint'] missing",
        ),
    }
    for name, (request, code, text) in fk_cases.items():
        response = call(probe, fk, request)
        assert not response.success and response.error_code.val == code, (name, response.message)
        assert text in response.message, (name, response.message)
    # Still serving: the boom straight up, 41.5 m above the root pin.
    response = call(probe, fk, fk_request(straight))
    assert response.success
    p = response.pose.pose.position
    np.testing.assert_allclose([p.x, p.y, p.z], [0.25, 0.0, 3.6 + 41.5], atol=1e-12)
    assert process.alive()


@pytest.mark.parametrize("name", list(TYPICAL_POURS))
def test_plan_path_of_the_papers_typical_pours(probe: Probe, server, boom: PumpBoom, name: str) -> None:
    _, _, _, plan_client = server
    _, start, end = TYPICAL_POURS[name]
    for step, speed in ((0.0, 0.0), (0.25, 0.5)):  # 0 = the machine's 100 mm and 0.2 m/s
        response = call(probe, plan_client, plan_request([start, end], step, speed))
        assert response.success and response.error_code.val == Codes.SUCCESS, response.message
        assert response.last_reachable_waypoint == 1
        plan = pour_line(boom, start, end, step or None, speed or None)
        trajectory = response.trajectory
        assert list(trajectory.joint_names) == NAMES and trajectory.header.frame_id == "base_link"
        assert (
            len(trajectory.points)
            == len(plan.q)
            == math.ceil(np.linalg.norm(np.subtract(end, start)) / (step or 0.1) - 1e-9) + 1
        )
        q = np.array([point.positions for point in trajectory.points])
        np.testing.assert_allclose(q, plan.q, atol=1e-12)
        np.testing.assert_allclose(boom.tip(q), plan.points, atol=1e-9)
        assert_trajectory_is_the_plan(trajectory, plan)
        assert f"{len(plan.q)} points" in response.message and "speed set at" in response.message


def test_plan_path_through_several_waypoints_with_a_seed(probe: Probe, server, boom: PumpBoom) -> None:
    _, _, _, plan_client = server
    waypoints = [[-20.0, 5.0, 17.5], [-25.0, -5.0, 17.5], [-25.0, -5.0, 12.5]]
    seed = [-3.0, 1.0, 2.0, 2.0, 2.0, 2.0]
    response = call(probe, plan_client, plan_request(waypoints, seed=seed))
    assert response.success, response.message
    assert response.last_reachable_waypoint == 2
    q = np.array([point.positions for point in response.trajectory.points])
    assert_trajectory_is_the_plan(response.trajectory, plan_path(boom, waypoints, seed=np.array(seed)))
    assert q[0, 0] < -math.pi  # the seed's slew turn, kept (unwrapped) along the path
    assert np.abs(np.diff(q[:, 0])).max() < 0.1


def test_plan_path_truncated_and_refused(probe: Probe, server, boom: PumpBoom) -> None:
    process, _, _, plan_client = server
    start, end = (20.0, 0.0, 17.5), (45.0, 0.0, 17.5)
    response = call(probe, plan_client, plan_request([start, end]))
    assert not response.success and response.error_code.val == Codes.NO_IK_SOLUTION
    assert "farthest reachable point" in response.message and "outside the region table" in response.message
    assert response.last_reachable_waypoint == 0
    plan = pour_line(boom, start, end)
    q = np.array([point.positions for point in response.trajectory.points])
    assert_trajectory_is_the_plan(response.trajectory, plan)  # stopping at rest at the farthest point
    np.testing.assert_allclose(boom.tip(q[-1]), plan.end, atol=1e-9)  # the end of the reachable part
    assert boom.region_ik(plan.end).ok and not boom.region_ik(plan.end + [2e-6, 0.0, 0.0]).ok
    nothing = call(probe, plan_client, plan_request([[60.0, 0.0, 3.6], [20.0, 0.0, 17.5]]))
    assert not nothing.success and nothing.error_code.val == Codes.NO_IK_SOLUTION
    assert nothing.last_reachable_waypoint == -1 and len(nothing.trajectory.points) == 0
    assert "first waypoint is not reachable" in nothing.message
    invalid = Codes.INVALID_GOAL_CONSTRAINTS
    line = [start, end]
    cases = {
        "no waypoint": (plan_request([]), invalid, "waypoints: need 1 to 1000, got 0"),
        "too many waypoints": (
            plan_request([start] * (MAX_WAYPOINTS + 1)),
            invalid,
            f"need 1 to {MAX_WAYPOINTS}, got {MAX_WAYPOINTS + 1}",
        ),
        "nan": (plan_request([start, [math.nan, 0.0, 1.0]]), invalid, "finite"),
        "huge waypoint": (
            plan_request([start, [1e300, 0.0, 17.5]]),
            invalid,
            "waypoint 1 [1e+300, 0.0, 17.5] is beyond 1000 x the machine's reach",
        ),
        "too many points": (
            plan_request([start, [20.0, 20.0, 17.5]], step=0.001),
            invalid,
            f"would have 2e+04 points at step 0.001 m; at most {MAX_POINTS}",
        ),
        "too long": (
            plan_request([start, [20.0, 20.0, 17.5]] * 3, tip_speed=0.001),
            invalid,
            "would take at least 1e+05 s at 0.001 m/s; at most 86400 s",
        ),
        "step negative": (plan_request(line, step=-0.1), invalid, "step -0.1 m is outside [0.001, 10] m"),
        "step tiny": (plan_request(line, step=1e-10), invalid, "step 1e-10 m is outside"),
        "step nan": (plan_request(line, step=math.nan), invalid, "step nan m is outside"),
        "speed inf": (plan_request(line, tip_speed=math.inf), invalid, "tip_speed inf m/s is outside"),
        "speed tiny": (plan_request(line, tip_speed=1e-300), invalid, "tip_speed 1e-300 m/s is outside"),
        "speed denormal": (
            plan_request(line, tip_speed=5e-324),
            invalid,
            "tip_speed 4.94066e-324 m/s is outside",
        ),
        "speed huge": (plan_request(line, tip_speed=1e300), invalid, "tip_speed 1e+300 m/s is outside"),
        "speed nan": (plan_request(line, tip_speed=math.nan), invalid, "tip_speed nan m/s is outside"),
        "speed negative": (plan_request(line, tip_speed=-0.2), invalid, "tip_speed -0.2 m/s is outside"),
        "mode": (plan_request(line, mode="phi"), Codes.INVALID_MODE, "unknown mode 'phi'"),
        "seed": (plan_request(line, seed=[0.0, 1.0]), Codes.INVALID_ROBOT_STATE, "seed:"),
        "seed huge": (
            plan_request(line, seed=[1e300, 1.0, 2.0, 2.0, 2.0, 2.0]),
            Codes.INVALID_ROBOT_STATE,
            "seed: slew_joint = 1e+300 is beyond 1000 x its range",
        ),
    }
    for name, (request, code, text) in cases.items():
        response = call(probe, plan_client, request)
        assert not response.success and response.error_code.val == code, (name, response.message)
        assert text in response.message, (name, response.message)
        assert response.last_reachable_waypoint == -1 and len(response.trajectory.points) == 0, name
    assert process.alive()


def test_solve_ik_is_answered_while_a_long_plan_runs(probe: Probe, server, boom: PumpBoom) -> None:
    # plan_path runs in a callback group of its own on a multi-threaded executor: solve_ik keeps
    # being answered while the largest plan there is (1000 waypoints, ~19,000 points) is computed.
    # A server serving one callback at a time answers no solve_ik until the plan is done.
    _, ik, _, plan_client = server
    assert call(probe, plan_client, plan_request([[20.0, 5.0, 17.5], [21.0, 5.0, 17.5]])).success  # matched
    waypoints = np.array([[16.0 + 12.0 * (k % 2), -6.0 + 12.0 * k / 999, 12.5] for k in range(MAX_WAYPOINTS)])
    step = float(np.sum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))) / (MAX_POINTS - 2000)
    sent = time.monotonic()
    future = plan_client.call_async(plan_request(waypoints, step=step))
    answered = []
    while not future.done():
        response = call(probe, ik, ik_request([20.0, 5.0, 17.5]))
        assert response.success, response.message
        if not future.done():
            answered.append(time.monotonic())
    finished = time.monotonic()
    plan = future.result()
    assert plan.success, plan.message
    assert MAX_POINTS - 2000 <= len(plan.trajectory.points) <= MAX_POINTS
    took = finished - sent
    gaps = np.diff([sent, *answered, finished])
    assert took > 0.3 and len(answered) >= 3, (took, len(answered))
    assert gaps.max() < 0.5 * took, (took, gaps.max(), len(answered))
    print(
        f"plan of {len(plan.trajectory.points)} points answered after {took:.2f} s; "
        f"{len(answered)} solve_ik answered meanwhile, longest gap {gaps.max():.3f} s"
    )


def test_a_server_on_a_changed_geometry_solves_fk_and_refuses_region_ik(probe: Probe, boom: PumpBoom) -> None:
    lengths = "[" + ", ".join(map(str, CHANGED_LENGTHS)) + "]"
    process, ik, fk, plan_client = start_server(
        probe, "-p", f"pump_boom.lengths:={lengths}", "-r", "__ns:=/changed", namespace="/changed"
    )
    try:
        q = [0.4, 1.0, 2.5, 2.8, 3.3, 2.6]
        response = call(probe, fk, fk_request(q))
        assert response.success, response.message
        p = response.pose.pose.position
        # Section 1 is 0.1 m longer: the tip moves 0.1 m along it.
        c1, s1 = math.cos(q[1]), math.sin(q[1])
        shift = 0.1 * np.array([c1 * math.cos(q[0]), c1 * math.sin(q[0]), s1])
        np.testing.assert_allclose([p.x, p.y, p.z], boom.tip(q) + shift, atol=1e-9)
        for client, request in (
            (ik, ik_request([20.0, 5.0, 17.5])),
            (plan_client, plan_request([[20.0, 0.0, 17.5], [25.0, 0.0, 17.5]])),
        ):
            answer = call(probe, client, request)
            assert not answer.success and answer.error_code.val == Codes.FAILURE, answer.message
            assert "built_for.lengths" in answer.message, answer.message
            assert "pump_boom_regions --config" in answer.message, answer.message
        assert process.alive()
    finally:
        log = process.stop()
    assert "solve_ik and plan_path will fail, solve_fk works" in log and "Traceback" not in log, log


def test_forward_node_publishes_the_tip_pose_and_twist(probe: Probe, boom: PumpBoom) -> None:
    poses: list[PoseStamped] = []
    twists: list[TwistStamped] = []
    node = probe.node
    publisher = node.create_publisher(JointState, "pump_boom_test/joint_states", 10)
    pose_sub = node.create_subscription(PoseStamped, "pump_boom_test/tool_pose", poses.append, 10)
    twist_sub = node.create_subscription(TwistStamped, "pump_boom_test/tool_twist", twists.append, 10)
    process = NodeProcess(
        "pump_boom_forward",
        "--params-file",
        PARAMS,
        *RELIABLE_INPUTS,
        "-p",
        "pump_boom_forward:topics.joint_states:=pump_boom_test/joint_states",
        "-p",
        "pump_boom_forward:topics.tool_pose:=pump_boom_test/tool_pose",
        "-p",
        "pump_boom_forward:topics.tool_twist:=pump_boom_test/tool_twist",
    )
    # Joint states along the slanted pour, with the plan's joint rates.
    plan = pour_line(boom, *TYPICAL_POURS["slanted_line"][1:])
    index = np.linspace(1, len(plan.q) - 2, 5).astype(int)
    states = plan.q[index]
    rates = plan.qd[index]
    try:
        probe.wait_until(
            lambda: (
                (
                    publisher.get_subscription_count() > 0
                    and pose_sub.get_publisher_count() > 0
                    and twist_sub.get_publisher_count() > 0
                )
                or not process.alive()
            ),
            TIMEOUT,
            "forward node discovery",
        )
        assert process.alive(), process.log()
        bad = JointState(name=NAMES, position=[0.0, math.nan, 3.0, 3.0, 3.0, 3.0])
        for i, (q, qd) in enumerate(zip(states, rates, strict=True)):
            bad.header.stamp = Time(sec=1000 + i)
            publisher.publish(bad)  # dropped with a log line, never published
            message = JointState(name=NAMES, position=q.tolist(), velocity=qd.tolist())
            message.header.stamp = Time(sec=300 + i, nanosec=250)
            publisher.publish(message)
            probe.wait_until(
                lambda n=i + 1: len(poses) >= n and len(twists) >= n, TIMEOUT, f"pose and twist {i}"
            )
    finally:
        log = process.stop()
    assert "dropped joint_states" in log and "Traceback" not in log, log
    assert [p.header.stamp for p in poses] == [Time(sec=300 + i, nanosec=250) for i in range(len(states))]
    for pose, twist, q, qd, speed in zip(poses, twists, states, rates, plan.speed[index], strict=True):
        assert pose.header.frame_id == "base_link"
        p = pose.pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], boom.tip(q), atol=1e-9)
        v = twist.twist.linear
        velocity = boom.tip_jacobian(q) @ qd
        np.testing.assert_allclose([v.x, v.y, v.z], velocity, atol=1e-9)
        # The rates are the plan's: the tip moves at the plan's speed along the line.
        assert np.linalg.norm(velocity) == pytest.approx(speed, rel=1e-3)
    np.testing.assert_allclose([p.pose.position.z for p in poses], 12.5, atol=1e-9)
