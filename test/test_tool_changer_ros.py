"""Tool changer nodes across processes: SolveIK / SolveFK round trips against a real
``tool_changer_ik_server`` and the ``tool_changer_forward`` node's pose and twist (isolated domain)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped
from ros_harness import IK_FK, RELIABLE_INPUTS, NodeProcess, Probe, start_with_services
from sensor_msgs.msg import JointState

from manipulator_kinematics.model import matrix_quaternion, pose_matrix
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes as Codes
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK
from tool_changer_kinematics.kinematics import ToolChanger

pytestmark = pytest.mark.ros

PARAMS = str(config_path("tool_changer.yaml"))
TIMEOUT = 15.0
PAPER_Q = [math.pi / 2, math.pi / 6, -math.pi / 3, math.pi / 3, math.pi / 2, 0.0]
PAIR_Q = np.radians([-11.06, 128.98, -82.79, 32.96, 82.48, -152.27])


@pytest.fixture(scope="module")
def arm() -> ToolChanger:
    return ToolChanger.default()


def ik_request(T: np.ndarray, names: tuple[str, ...], seed=None, branch: str = "") -> SolveIK.Request:
    request = SolveIK.Request(branch=branch, use_orientation=True)
    p, o = request.target.pose.position, request.target.pose.orientation
    p.x, p.y, p.z = (float(v) for v in T[:3, 3])
    o.x, o.y, o.z, o.w = (float(v) for v in matrix_quaternion(T[:3, :3]))
    if seed is not None:
        request.seed = JointState(name=list(names), position=[float(v) for v in seed])
    return request


def test_ik_and_fk_services_round_trip(probe: Probe, arm: ToolChanger) -> None:
    process, (ik, fk) = start_with_services(
        probe, "tool_changer_ik_server", "--params-file", PARAMS, services=IK_FK, timeout=TIMEOUT
    )
    names = arm.joint_names
    try:
        # The note's verification pose: one valid solution, the generating vector.
        response = probe.call(ik, ik_request(arm.fkine(PAPER_Q), names), TIMEOUT)
        assert response.success and response.error_code.val == Codes.SUCCESS, response.message
        assert list(response.solution.name) == list(names)
        np.testing.assert_allclose(response.solution.position, PAPER_Q, atol=1e-9)
        assert len(response.solutions) == 1
        # The note's two-solution pose: both valid ones, the one closest to the seed first.
        T = arm.fkine(PAIR_Q)
        expected = arm.solve_ik(T).q[[0, 4]]
        for k in range(2):
            response = probe.call(ik, ik_request(T, names, seed=expected[k] + 0.01), TIMEOUT)
            assert response.success, response.message
            np.testing.assert_allclose(response.solution.position, expected[k], atol=1e-9)
            listed = [s.position for s in response.solutions]
            np.testing.assert_allclose(listed, expected[[k, 1 - k]], atol=1e-9)
        # FK of a solution returns the target, stamped with the request's stamp; twist = J qd.
        qd = [0.05, -0.02, 0.03, 0.1, -0.1, 0.2]
        stamp = Time(sec=7, nanosec=11)
        state = JointState(name=list(names), position=[float(v) for v in expected[1]], velocity=qd)
        state.header.stamp = stamp
        response = probe.call(fk, SolveFK.Request(joint_state=state), TIMEOUT)
        assert response.success, response.message
        p, o = response.pose.pose.position, response.pose.pose.orientation
        reached = pose_matrix([p.x, p.y, p.z], [o.x, o.y, o.z, o.w])
        np.testing.assert_allclose(reached, T, atol=1e-9)
        v, w = response.twist.twist.linear, response.twist.twist.angular
        np.testing.assert_allclose([v.x, v.y, v.z, w.x, w.y, w.z], arm.twist(expected[1], qd), atol=1e-12)
        assert response.pose.header.stamp == stamp
        # Failures: a code and a reason, and the server keeps serving.
        far = np.eye(4)
        far[:3, 3] = (4.0, 0.0, 1.0)
        branch_far = np.eye(4)
        branch_far[:3, 3] = (1.5, 0.0, 1.0)
        for request, code, text in (
            (ik_request(far, names), Codes.NO_IK_SOLUTION, "cannot reach"),
            (
                ik_request(arm.fkine([0.3, 1.0, -1.2, 1.5, 1.0, 0.2]), names),
                Codes.JOINT_LIMITS_VIOLATED,
                "wrist_pitch_joint",
            ),
            (ik_request(T, names, branch="elbow_up"), Codes.INVALID_MODE, "unknown branch"),
            # Out of this branch's reach, only other branches have (limit-breaking) solutions.
            (ik_request(branch_far, names, branch="front_up_noflip"), Codes.NO_IK_SOLUTION, "cannot reach"),
        ):
            response = probe.call(ik, request, TIMEOUT)
            assert not response.success and response.error_code.val == code, response.message
            assert text in response.message and len(response.solutions) == 0
        assert probe.call(ik, ik_request(arm.fkine(PAPER_Q), names), TIMEOUT).success
    finally:
        log = process.stop()
    assert "Traceback" not in log, log


def test_forward_node_publishes_pose_and_twist(probe: Probe, arm: ToolChanger) -> None:
    poses: list[PoseStamped] = []
    twists: list[TwistStamped] = []
    node = probe.node
    publisher = node.create_publisher(JointState, "tc_test/joint_states", 10)
    pose_sub = node.create_subscription(PoseStamped, "tool_pose", poses.append, 10)
    twist_sub = node.create_subscription(TwistStamped, "tool_twist", twists.append, 10)
    process = NodeProcess(
        "tool_changer_forward",
        "--params-file",
        PARAMS,
        *RELIABLE_INPUTS,
        "-p",
        "tool_changer_forward:topics.joint_states:=tc_test/joint_states",
    )
    rng = np.random.default_rng(11)
    states = rng.uniform(arm.limits.lower, arm.limits.upper, (4, 6))
    rates = rng.normal(size=(4, 6))
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
        for i, (q, qd) in enumerate(zip(states, rates, strict=True)):
            message = JointState(name=list(arm.joint_names), position=q.tolist(), velocity=qd.tolist())
            message.header.stamp = Time(sec=100 + i)
            publisher.publish(message)
            probe.wait_until(lambda n=i + 1: len(poses) >= n and len(twists) >= n, TIMEOUT, f"output {i}")
    finally:
        log = process.stop()
    assert "Traceback" not in log, log
    for pose, twist, q, qd in zip(poses, twists, states, rates, strict=True):
        p, o = pose.pose.position, pose.pose.orientation
        reached = pose_matrix([p.x, p.y, p.z], [o.x, o.y, o.z, o.w])
        np.testing.assert_allclose(reached, arm.fkine(q), atol=1e-12)
        v, w = twist.twist.linear, twist.twist.angular
        np.testing.assert_allclose([v.x, v.y, v.z, w.x, w.y, w.z], arm.twist(q, qd), atol=1e-12)
        assert pose.header.frame_id == "base_link" and pose.header.stamp == twist.header.stamp
