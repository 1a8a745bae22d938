"""A continuous swing (open swing limits in the machine file) through the real nodes over DDS.

excavator_sim + excavator_forward + excavator_velocity_ik driven through the +-pi heading (the
velocity IK must not stop the swing there, the sim wraps its angle, the forward node follows);
the forward node fed a wound-up swing angle from joint_states; the IK server seeded with one. The
same machine with stops at +-pi is the control: its velocity IK stops the swing at pi.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe, start_with_services
from sensor_msgs.msg import JointState

from excavator_kinematics.core.kinematics import ACTUATORS, CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.twist import bucket_angles, twist_from_q_dot
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics_interfaces.srv import SolveIK

pytestmark = pytest.mark.ros

QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
PARAMS = (
    "--params-file",
    str(config_path("excavator_cet200.yaml")),
    "--params-file",
    str(config_path("excavator_nodes.yaml")),
)
OPEN = {"hydraulic_machine": {"swing": {"min_angle": -math.inf, "max_angle": math.inf}}}
SECTIONS = load_parameters(config_path("excavator_cet200.yaml"))
GEOMETRY = SECTIONS["hydraulic_machine"]
CONTINUOUS = Excavator.from_parameters(
    {
        **SECTIONS,
        "hydraulic_machine": {
            **GEOMETRY,
            "swing": {**GEOMETRY["swing"], "min_angle": -math.inf, "max_angle": math.inf},
        },
    }
)
LIMITED = Excavator.default()
START_SWING = 2.9  # rad, 0.24 rad before the +-pi heading
SWING_RATE = 0.5  # rad/s of the driver


def start(exe: str, namespace: str, continuous: bool, **settings: object) -> NodeProcess:
    overrides = {**(OPEN if continuous else {}), **settings}
    params = {f"{namespace}/{exe}": {"ros__parameters": overrides}} if overrides else None
    return NodeProcess(exe, *PARAMS, *RELIABLE_INPUTS, "-r", f"__ns:={namespace}", params=params)


@pytest.fixture(scope="module")
def probe() -> Iterator[Probe]:
    p = Probe("excavator_continuous_swing_test")
    yield p
    p.close()


def drive_through_pi(probe: Probe, namespace: str, continuous: bool) -> tuple[list[float], list[float]]:
    """Sim, forward and velocity IK in ``namespace``, driven at SWING_RATE about z from START_SWING
    (once this probe has the sim's joint_states: a subscription matched late must not miss the
    crossing) until the swing has crossed pi (continuous) or has come within 0.04 rad of its stop at pi and
    1 s of the sim's states (100) have followed; the sim's swing angles and the forward node's
    bucket headings. A healthy run: no ERROR line in any log (start-up, where the
    topics begin at different moments, included; issue 28 item 7)."""
    reference = CONTINUOUS.limits.reference
    processes = [
        start(
            "excavator_sim",
            namespace,
            continuous,
            initial_swing_angle=START_SWING,
            initial_cylinder_lengths=[float(v) for v in reference[1:]],
        ),
        start("excavator_forward", namespace, continuous),
        start("excavator_velocity_ik", namespace, continuous),
    ]
    try:
        n = probe.node
        target = n.create_publisher(TwistStamped, f"{namespace}/target_bucket_twist", QOS)
        swings: list[float] = []
        headings: list[float] = []
        started: list[int] = []

        def on_swing(msg: JointState) -> None:
            swings.append(msg.position[0])

        def drive(msg: PoseStamped) -> None:
            if not swings:  # not yet: the swing must be seen before it moves (discovery under load)
                return
            if not started:
                started.append(message_codec.stamp_ns(msg.header.stamp))
            o, p = msg.pose.orientation, msg.pose.position
            theta1, _ = bucket_angles(np.array([o.x, o.y, o.z, o.w]))
            headings.append(float(theta1))
            tip = np.array([p.x, p.y, p.z])
            q_dot = np.array([-SWING_RATE * tip[1], SWING_RATE * tip[0], 0.0, 0.0])  # turn about z
            target.publish(
                message_codec.bucket_twist(
                    msg.header.stamp, "base_link", *twist_from_q_dot(theta1, tip, q_dot)
                )
            )

        n.create_subscription(JointState, f"{namespace}/joint_states", on_swing, QOS)
        n.create_subscription(PoseStamped, f"{namespace}/bucket_pose", drive, 1)
        probe.wait_until(lambda: bool(started), 30.0, f"bucket_pose from {namespace}")

        def done() -> bool:
            if continuous:
                crossed = any(s > 3.0 for s in swings) and any(s < -2.9 for s in swings)
                return crossed and any(h < -2.9 for h in headings)
            near = next((i for i, s in enumerate(swings) if s > math.pi - 0.04), None)
            return near is not None and len(swings) > near + 100

        probe.wait_until(done, 60.0, "the swing to cross or reach pi")
        assert all(p.alive() for p in processes)
    finally:
        logs = [process.stop() for process in processes]
        print(*logs, sep="\n")
    errors = [line for log in logs for line in log.splitlines() if "[ERROR]" in line]
    assert not errors, errors
    return swings, headings


def test_a_continuous_swing_turns_through_pi_and_a_limited_one_stops_there(probe: Probe) -> None:
    swings, headings = drive_through_pi(probe, "/open", continuous=True)
    assert all(-math.pi < s <= math.pi for s in swings), "the sim publishes wrapped angles"
    assert max(swings) > 3.0 and min(swings) < -2.9, f"no crossing of pi: {swings[0]:.3f} .. {swings[-1]:.3f}"
    assert min(headings) < -2.9, "the forward node's heading followed the swing through pi"
    stopped, _ = drive_through_pi(probe, "/stops", continuous=False)
    assert max(stopped) <= math.pi and min(stopped) > 2.8, "the swing with stops crossed pi"
    assert max(stopped) > 3.1, f"the swing with stops did not reach its stop: max {max(stopped):.3f}"


def test_the_forward_node_and_ik_server_take_a_wound_up_swing(probe: Probe) -> None:
    """joint_states with swing 3.3 rad (one turn past 3.3 - 2 pi): the forward node's pose is the
    model's at the wrapped angle; the IK server seeded with 3.3 + 2 pi answers 3.3 - 2 pi."""
    D = CONTINUOUS.limits.reference.copy()
    D[0] = 3.3
    wrapped = D.copy()
    wrapped[0] = 3.3 - 2.0 * math.pi
    forward = start("excavator_forward", "/fwdopen", True)
    server, (ik,) = start_with_services(
        probe,
        "excavator_ik_server",
        *PARAMS,
        "-r",
        "__ns:=/ikopen",
        "-p",
        "hydraulic_machine.swing.min_angle:=-.inf",
        "-p",
        "hydraulic_machine.swing.max_angle:=.inf",
        services=[(SolveIK, "/ikopen/solve_ik")],
        timeout=60.0,
    )
    try:
        n = probe.node
        cylinders = n.create_publisher(JointState, "/fwdopen/cylinder_lengths", QOS)
        swing = n.create_publisher(JointState, "/fwdopen/joint_states", QOS)
        poses: list[PoseStamped] = []
        n.create_subscription(PoseStamped, "/fwdopen/bucket_pose", poses.append, QOS)
        probe.wait_until(
            lambda: min(cylinders.get_subscription_count(), swing.get_subscription_count()) > 0,
            30.0,
            "the forward node's inputs",
        )

        def send() -> bool:
            when = Time(sec=1)
            swing.publish(message_codec.joint_state(when, JOINTS[:1], D[:1], [0.0]))
            cylinders.publish(message_codec.joint_state(when, CYLINDERS, D[1:], [0.0, 0.0, 0.0]))
            probe.executor.spin_once(timeout_sec=0.2)
            return bool(poses)

        probe.wait_until(send, 30.0, "a bucket pose for swing 3.3 rad")
        p = poses[0].pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], LIMITED.pose(wrapped)[:3], atol=1e-9)

        request = SolveIK.Request(mode="position", use_orientation=False)
        request.target.pose.position.x, request.target.pose.position.y, request.target.pose.position.z = (
            float(v) for v in CONTINUOUS.pose(D)[:3]
        )
        seed = D.copy()
        seed[0] = 3.3 + 2.0 * math.pi
        request.seed = JointState(name=list(ACTUATORS), position=[float(v) for v in seed])
        response = probe.call(ik, request, 30.0)
        assert response.success, response.message
        np.testing.assert_allclose(response.solution.position, wrapped, atol=1e-9)
    finally:
        print(forward.stop())
        print(server.stop())
