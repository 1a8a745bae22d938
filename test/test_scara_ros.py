"""SCARA nodes across processes: SolveIK / SolveFK round trips and bad requests against a real
``scara_ik_server`` process, and the ``scara_forward`` node's pose and twist (isolated domain)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped
from ros_harness import IK_FK, RELIABLE_INPUTS, NodeProcess, Probe, start_with_services
from sensor_msgs.msg import JointState

from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.planar import yaw_quaternion
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes as Codes
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK
from scara_kinematics.kinematics import Scara

pytestmark = pytest.mark.ros

DEG = math.pi / 180
NAMES = ["rail_joint", "shoulder_joint", "elbow_joint"]
PARAMS = str(config_path("scara.yaml"))
TIMEOUT = 15.0


@pytest.fixture(scope="module")
def scara() -> Scara:
    return Scara.default()


@pytest.fixture(scope="module")
def server(probe: Probe) -> Iterator[tuple[NodeProcess, object, object]]:
    process, (ik, fk) = start_with_services(
        probe, "scara_ik_server", "--params-file", PARAMS, services=IK_FK, timeout=TIMEOUT
    )
    try:
        yield process, ik, fk
    finally:
        log = process.stop()
        assert "Traceback" not in log, log


def call(probe: Probe, client, request):
    return probe.call(client, request, TIMEOUT)


def ik_request(
    x: float,
    y: float,
    mode: str = "",
    phi: float | None = None,
    seed: list[float] | None = None,
    branch: str = "",
    frame: str = "",
    z: float = 0.0,
) -> SolveIK.Request:
    request = SolveIK.Request(mode=mode, branch=branch, use_orientation=phi is not None)
    request.target.header.frame_id = frame
    request.target.pose.position.x, request.target.pose.position.y, request.target.pose.position.z = x, y, z
    if phi is not None:
        o = request.target.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in yaw_quaternion(phi))
    if seed is not None:
        request.seed = JointState(name=NAMES, position=seed)
    return request


def fk_request(q: list[float], qd: list[float] | None = None, stamp: Time | None = None) -> SolveFK.Request:
    state = JointState(name=NAMES, position=q, velocity=qd or [])
    if stamp is not None:
        state.header.stamp = stamp
    return SolveFK.Request(joint_state=state)


def test_ik_round_trip_with_the_reference_values(probe: Probe, server, scara: Scara) -> None:
    _, ik, fk = server
    q_ref = [0.1, 30 * DEG, 60 * DEG]
    px, py, _ = scara.fk(q_ref)
    assert (px, py) == pytest.approx((0.559808, 0.40), abs=5e-7)
    for request in (
        ik_request(px, py, mode="fixed_phi"),
        ik_request(px, py, phi=90 * DEG),
        ik_request(px, py, frame="base_link"),
        ik_request(px, py, mode="position", seed=q_ref),
    ):
        response = call(probe, ik, request)
        assert response.success and response.error_code.val == Codes.SUCCESS, response.message
        assert list(response.solution.name) == NAMES
        np.testing.assert_allclose(response.solution.position, q_ref, atol=1e-12)
        assert len(response.solutions) == 1  # elbow_b would need the rail at 0.62 m
    # FK of the solution returns the target; its twist is J qd.
    qd = [0.05, 0.2, -0.1]
    stamp = Time(sec=12, nanosec=345)
    response = call(probe, fk, fk_request(q_ref, qd, stamp))
    assert response.success, response.message
    assert response.pose.header.frame_id == "base_link" and response.pose.header.stamp == stamp
    position, orientation = response.pose.pose.position, response.pose.pose.orientation
    np.testing.assert_allclose([position.x, position.y, position.z], [px, py, 0.0], atol=1e-12)
    np.testing.assert_allclose(
        [orientation.x, orientation.y, orientation.z, orientation.w], yaw_quaternion(90 * DEG), atol=1e-12
    )
    twist = response.twist.twist
    expected = scara.velocity_fk(q_ref, qd)
    v, w = twist.linear, twist.angular
    np.testing.assert_allclose(
        [v.x, v.y, v.z, w.x, w.y, w.z], [expected[0], expected[1], 0, 0, 0, expected[2]], atol=1e-12
    )
    assert response.twist.header.stamp == stamp


def test_ik_returns_both_branches_and_honours_seed_and_branch(probe: Probe, server, scara: Scara) -> None:
    _, ik, _ = server
    q_a = [0.05, 70 * DEG, 20 * DEG]
    q_b = [0.05 + 2 * scara.l2 * math.cos(70 * DEG), 110 * DEG, -20 * DEG]
    px, py, _ = scara.fk(q_a)
    response = call(probe, ik, ik_request(px, py, mode="fixed_phi"))
    assert response.success, response.message
    np.testing.assert_allclose([s.position for s in response.solutions], [q_a, q_b], atol=1e-12)
    by_seed = call(probe, ik, ik_request(px, py, mode="fixed_phi", seed=[0.3, 100 * DEG, -10 * DEG]))
    np.testing.assert_allclose(by_seed.solution.position, q_b, atol=1e-12)
    np.testing.assert_allclose(by_seed.solutions[0].position, q_b, atol=1e-12)  # the selected one first
    by_name = call(probe, ik, ik_request(px, py, mode="fixed_phi", branch="elbow_b", seed=q_a))
    np.testing.assert_allclose(by_name.solution.position, q_b, atol=1e-12)
    # Position mode with a seed whose heading (60 deg) is admissible keeps it.
    target = scara.fk([0.2, 20 * DEG, 40 * DEG])
    kept = call(probe, ik, ik_request(target[0], target[1], mode="position", seed=[0.0, 10 * DEG, 50 * DEG]))
    assert kept.success, kept.message
    np.testing.assert_allclose(kept.solution.position, [0.2, 20 * DEG, 40 * DEG], atol=1e-12)


BAD_IK = {
    "nan": (ik_request(math.nan, 0.3, mode="fixed_phi"), Codes.INVALID_GOAL_CONSTRAINTS, "not finite"),
    "unreachable": (
        ik_request(0.3, 0.9, mode="fixed_phi"),
        Codes.NO_IK_SOLUTION,
        "out of the upper arm's reach",
    ),
    "far": (ik_request(0.3, 0.7, mode="position"), Codes.NO_IK_SOLUTION, "farther than l2 + l3"),
    "limits": (
        ik_request(1.3, 0.4, mode="fixed_phi"),
        Codes.JOINT_LIMITS_VIOLATED,
        "rail_joint = 0.840192 m above its limit 0.4 m",
    ),
    "singular": (ik_request(0.5, 0.55, mode="fixed_phi"), Codes.SINGULAR, "|cos theta1|"),
    "mode": (ik_request(0.5, 0.3, mode="sideways"), Codes.INVALID_MODE, "unknown mode 'sideways'"),
    "branch": (ik_request(0.5, 0.3, branch="elbow_up"), Codes.INVALID_MODE, "unknown branch 'elbow_up'"),
    "frame": (ik_request(0.5, 0.3, frame="map"), Codes.FRAME_TRANSFORM_FAILURE, "'map'"),
    "off plane": (ik_request(0.5, 0.3, z=0.1), Codes.NO_IK_SOLUTION, "z = 0.1 m"),
    "seed nan": (ik_request(0.5, 0.3, seed=[0.1, math.nan, 0.0]), Codes.INVALID_ROBOT_STATE, "non-finite"),
    "seed short": (
        ik_request(0.5, 0.3, seed=[0.1, 0.2]),
        Codes.INVALID_ROBOT_STATE,
        "3 names but 2 position values",
    ),
    "fixed vs heading": (
        ik_request(0.5, 0.3, mode="fixed_phi", phi=0.5),
        Codes.INVALID_GOAL_CONSTRAINTS,
        "fixed_phi",
    ),
}


def test_bad_ik_requests_fail_with_a_code_and_a_reason(probe: Probe, server) -> None:
    process, ik, _ = server
    for name, (request, code, text) in BAD_IK.items():
        response = call(probe, ik, request)
        assert not response.success, name
        assert response.error_code.val == code, (name, response.error_code.val, response.message)
        assert text in response.message, (name, response.message)
        assert len(response.solution.position) == 0 and len(response.solutions) == 0, name
    tilted = ik_request(0.5, 0.3, phi=0.2)
    tilted.target.pose.orientation.x = 0.3
    response = call(probe, ik, tilted)
    assert response.error_code.val == Codes.NO_IK_SOLUTION and "tilts the tool z axis" in response.message
    # Still serving, still right.
    response = call(probe, ik, ik_request(0.5598076211353316, 0.4, mode="fixed_phi"))
    assert response.success
    np.testing.assert_allclose(response.solution.position, [0.1, 30 * DEG, 60 * DEG], atol=1e-12)
    assert process.alive()


def test_bad_fk_requests_fail_with_a_code_and_a_reason(probe: Probe, server) -> None:
    process, _, fk = server
    cases = {
        "nan": (fk_request([0.1, math.nan, 0.0]), Codes.INVALID_ROBOT_STATE, "non-finite position"),
        "nan velocity": (
            fk_request([0.1, 0.2, 0.0], [0.0, math.inf, 0.0]),
            Codes.INVALID_ROBOT_STATE,
            "non-finite velocity",
        ),
        "limits": (
            fk_request([0.5, 0.2, 0.0]),
            Codes.JOINT_LIMITS_VIOLATED,
            "rail_joint = 0.5 m above its limit",
        ),
        "missing": (
            SolveFK.Request(joint_state=JointState(name=NAMES[:2], position=[0.1, 0.2])),
            Codes.INVALID_ROBOT_STATE,
            "['elbow_joint'] missing",
        ),
        "frame": (
            SolveFK.Request(joint_state=JointState(name=NAMES, position=[0.1, 0.2, 0.0]), frame_id="odom"),
            Codes.FRAME_TRANSFORM_FAILURE,
            "'odom'",
        ),
    }
    for name, (request, code, text) in cases.items():
        response = call(probe, fk, request)
        assert not response.success and response.error_code.val == code, (name, response.message)
        assert text in response.message, (name, response.message)
    response = call(probe, fk, fk_request([0.1, 30 * DEG, 60 * DEG]))
    assert response.success and response.pose.pose.position.x == pytest.approx(0.5598076211353316, abs=1e-12)
    np.testing.assert_allclose([response.twist.twist.linear.x, response.twist.twist.angular.z], 0.0)
    assert process.alive()


def test_forward_node_publishes_pose_and_twist(probe: Probe, scara: Scara) -> None:
    poses: list[PoseStamped] = []
    twists: list[TwistStamped] = []
    node = probe.node
    publisher = node.create_publisher(JointState, "scara_test/joint_states", 10)
    pose_sub = node.create_subscription(PoseStamped, "scara_test/pose", poses.append, 10)
    twist_sub = node.create_subscription(TwistStamped, "twist_remapped", twists.append, 10)
    # Topic names by parameter (node-scoped, so they win over the params file's section) and by remapping.
    process = NodeProcess(
        "scara_forward",
        "--params-file",
        PARAMS,
        *RELIABLE_INPUTS,
        "-p",
        "scara_forward:topics.joint_states:=scara_test/joint_states",
        "-p",
        "scara_forward:topics.tool_pose:=scara_test/pose",
        "-p",
        "scara_forward:base_frame:=arm_base",
        "-r",
        "tool_twist:=twist_remapped",
    )
    try:
        probe.wait_until(
            lambda: (
                publisher.get_subscription_count() > 0
                and pose_sub.get_publisher_count() > 0
                and twist_sub.get_publisher_count() > 0
            ),
            TIMEOUT,
            "forward node discovery",
        )
        rng = np.random.default_rng(7)
        states = rng.uniform(scara.limits.lower, scara.limits.upper, (5, 3))
        rates = rng.normal(size=(5, 3))
        bad = [
            JointState(name=NAMES, position=[0.1, math.nan, 0.0], velocity=[0.0, 0.0, 0.0]),
            JointState(name=NAMES[:2], position=[0.1, 0.2]),
            JointState(name=NAMES, position=[0.1, 0.2, 0.3], velocity=[0.0]),
        ]
        sent = []
        for i, (q, qd) in enumerate(zip(states, rates, strict=True)):
            for message in bad:  # a bad state before each good one: dropped, never published
                message.header.stamp = Time(sec=1000 + i, nanosec=1)
                publisher.publish(message)
            stamp = Time(sec=100 + i, nanosec=500_000_000)
            sent.append(stamp)
            good = JointState(name=["gripper_joint", *NAMES], position=[9.0, *q], velocity=[1.0, *qd])
            good.header.stamp = stamp
            publisher.publish(good)
            probe.wait_until(
                lambda n=i + 1: len(poses) >= n and len(twists) >= n, TIMEOUT, f"pose and twist {i}"
            )
        no_rates = JointState(name=NAMES, position=[0.2, 0.1, 0.3])
        no_rates.header.stamp = Time(sec=200)
        publisher.publish(no_rates)
        probe.wait_until(lambda: len(poses) >= 6, TIMEOUT, "pose without velocities")
    finally:
        log = process.stop()
    assert [p.header.stamp for p in poses] == [*sent, Time(sec=200)]
    assert [t.header.stamp for t in twists] == sent  # no twist without velocities
    expected_x, expected_xd = scara.fk(states), scara.velocity_fk(states, rates)
    for pose, twist, x, xd in zip(poses, twists, expected_x, expected_xd, strict=False):
        assert pose.header.frame_id == "arm_base" and twist.header.frame_id == "arm_base"
        p, o = pose.pose.position, pose.pose.orientation
        np.testing.assert_allclose([p.x, p.y, p.z], [x[0], x[1], 0.0], atol=1e-12)
        np.testing.assert_allclose([o.x, o.y, o.z, o.w], yaw_quaternion(x[2]), atol=1e-12)
        v, w = twist.twist.linear, twist.twist.angular
        np.testing.assert_allclose([v.x, v.y, v.z, w.x, w.y, w.z], [xd[0], xd[1], 0, 0, 0, xd[2]], atol=1e-12)
    assert "dropped joint_states" in log and "Traceback" not in log, log
