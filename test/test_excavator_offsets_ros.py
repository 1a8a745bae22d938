"""The excavator nodes apply a calibrated file's zero offsets (issue 33, item 3), over real DDS.

A CET200 file with offsets (test_excavator_offsets.OFFSETS: 0.5 deg, 1-2 cm): excavator_forward
publishes the pose of reading + offset (the zero-offset model's pose there); excavator_sim
publishes what the sensors read (true - offset) and the forward node, fed by it, the pose of the
sim's true state; excavator_ik_server answers and takes readings.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import IK_FK, RELIABLE_INPUTS, NodeProcess, Probe, start_with_services
from sensor_msgs.msg import JointState
from test_excavator_offsets import OFFSETS, calibrated_sections

from excavator_kinematics.core.kinematics import ACTUATORS, CYLINDERS, Excavator
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics.param_files import config_path, dump_parameters
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK

pytestmark = pytest.mark.ros

TIMEOUT = 30.0
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
ZERO = Excavator.default()
CALIBRATED = Excavator.from_parameters(calibrated_sections())


@pytest.fixture(scope="module")
def probe() -> Iterator[Probe]:
    p = Probe("excavator_offsets_test")
    yield p
    p.close()


@pytest.fixture(scope="module")
def params(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, ...]:
    path = Path(tmp_path_factory.mktemp("offsets")) / "calibrated.yaml"
    path.write_text(dump_parameters({"/**": {"ros__parameters": calibrated_sections()}}))
    return ("--params-file", str(path), "--params-file", str(config_path("excavator_nodes.yaml")))


def start(exe: str, namespace: str, params: tuple[str, ...]) -> NodeProcess:
    return NodeProcess(exe, *params, *RELIABLE_INPUTS, "-r", f"__ns:={namespace}")


def poses(probe: Probe, namespace: str) -> list[PoseStamped]:
    received: list[PoseStamped] = []
    probe.node.create_subscription(PoseStamped, f"{namespace}/bucket_pose", received.append, QOS)
    return received


def position(msg: PoseStamped) -> np.ndarray:
    p = msg.pose.position
    return np.array([p.x, p.y, p.z])


def test_forward_publishes_the_pose_of_reading_plus_offset(probe: Probe, params: tuple[str, ...]) -> None:
    readings = ZERO.limits.reference - OFFSETS + np.array([0.3, 0.05, -0.1, 0.08])
    expected = ZERO.pose(readings + OFFSETS)
    ns = "/fwd"
    swing = probe.node.create_publisher(JointState, f"{ns}/joint_states", QOS)
    cylinders = probe.node.create_publisher(JointState, f"{ns}/cylinder_lengths", QOS)
    received = poses(probe, ns)
    with start("excavator_forward", ns, params) as process:
        stamp = Time(sec=1)

        def answered() -> bool:
            # Swing first, then the cylinders with the same stamp, until the pose of that stamp comes.
            if not received:
                swing.publish(message_codec.joint_state(stamp, ("swing_joint",), readings[:1], np.zeros(1)))
                cylinders.publish(message_codec.joint_state(stamp, CYLINDERS, readings[1:], np.zeros(3)))
            return bool(received) or not process.alive()

        probe.wait_until(answered, TIMEOUT, "bucket_pose")
        assert received, process.log()
    np.testing.assert_allclose(position(received[0]), expected[:3], rtol=0, atol=1e-9)
    # Read without the offsets the tip would be centimetres away: the test can fail.
    assert np.linalg.norm(ZERO.pose(readings)[:3] - expected[:3]) > 0.01


def test_sim_and_forward_agree_on_the_calibrated_file(probe: Probe, params: tuple[str, ...]) -> None:
    ns = "/simfwd"
    sim_readings: list[JointState] = []
    probe.node.create_subscription(JointState, f"{ns}/cylinder_lengths", sim_readings.append, QOS)
    received = poses(probe, ns)
    with start("excavator_sim", ns, params) as sim, start("excavator_forward", ns, params) as forward:
        try:
            # Two nodes starting at once on a shared machine (each loads its kernels): 2 x TIMEOUT.
            probe.wait_until(
                lambda: (bool(received) and bool(sim_readings)) or not (sim.alive() and forward.alive()),
                2 * TIMEOUT,
                "cylinder_lengths from excavator_sim and bucket_pose from excavator_forward",
            )
        except TimeoutError:
            print(sim.log(), forward.log())
            raise
        assert received and sim_readings, sim.log() + forward.log()
    true = CALIBRATED.limits.reference  # the sim stands at its initial (true) state
    np.testing.assert_allclose(list(sim_readings[-1].position), true[1:] - OFFSETS[1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(position(received[-1]), ZERO.pose(true)[:3], rtol=0, atol=1e-9)


def test_ik_server_takes_and_answers_readings(probe: Probe, params: tuple[str, ...]) -> None:
    ns = "/ik"
    readings = ZERO.limits.reference - OFFSETS + np.array([-0.2, 0.1, 0.05, -0.05])
    process, (ik, fk) = start_with_services(
        probe,
        "excavator_ik_server",
        *params,
        "-r",
        f"__ns:={ns}",
        services=IK_FK,
        timeout=TIMEOUT,
        namespace=ns,
    )
    with process:
        fk_answer = probe.call(
            fk,
            SolveFK.Request(joint_state=JointState(name=list(ACTUATORS), position=readings.tolist())),
            TIMEOUT,
        )
        assert fk_answer.success, fk_answer.message
        np.testing.assert_allclose(
            position(fk_answer.pose), ZERO.pose(readings + OFFSETS)[:3], rtol=0, atol=1e-9
        )
        request = SolveIK.Request(use_orientation=True)
        request.target.pose = fk_answer.pose.pose
        request.seed = JointState(name=list(ACTUATORS), position=readings.tolist())
        ik_answer = probe.call(ik, request, TIMEOUT)
        assert ik_answer.success, ik_answer.message
        np.testing.assert_allclose(list(ik_answer.solution.position), readings, rtol=0, atol=1e-6)
