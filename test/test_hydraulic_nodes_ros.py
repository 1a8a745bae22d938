"""The hydraulic family's nodes as processes over DDS (isolated domain), run from the machine files
alone: hydraulic_sim -> hydraulic_velocity_ik -> hydraulic_forward closes the loop for the wheel
loader and the knuckle crane (the published tool pose, urdf_joint_states and machine_markers'
tool are the model's of the published state,
and the tool moves in the commanded direction: the loader's height rises with its bucket angle
held, the crane's rotator pin along the commanded line), and hydraulic_ik_server answers solve_fk
and solve_ik (a round trip) and refuses what it cannot do."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import IK_FK, NodeProcess, Probe, runtime_warnings, start_with_services
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from manipulator_kinematics.hydraulic.drawing import urdf_joint_values
from manipulator_kinematics.model import quaternion_matrix
from manipulator_kinematics.registry import machine
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes as Codes
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TIMEOUT = 30.0
QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
#: Target tool twists [vx, vy, vz, wx, wy, wz]: the loader lifts its edge, bucket angle held (its
#: velocity IK commands z and alpha); the crane moves its rotator pin along a slanted line.
TARGETS = {"wheel_loader": [0.0, 0.0, 0.1, 0.0, 0.0, 0.0], "knuckle_crane": [0.06, 0.05, 0.06, 0.0, 0.0, 0.0]}
TRAVEL = 0.05  # m the tool must move before the run is judged


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def pose_matrix_of(msg: PoseStamped) -> np.ndarray:
    p, o = msg.pose.position, msg.pose.orientation
    T = np.eye(4)
    T[:3, :3] = quaternion_matrix([o.x, o.y, o.z, o.w])
    T[:3, 3] = [p.x, p.y, p.z]
    return T


#: A measure-up's zero offsets (true = reading + offset), as mk_calibrate writes them.
CALIBRATED = {"lift_cylinder": 0.013, "tilt_cylinder": -0.008}


@pytest.mark.parametrize(("name", "calibrated"), [(n, False) for n in TARGETS] + [("wheel_loader", True)])
def test_sim_velocity_ik_forward_loop_follows_the_target(
    probe: Probe, name: str, calibrated: bool, tmp_path: Path
) -> None:
    """Also with a calibrated file (issue 33): the nodes publish and take sensor readings, the
    geometry runs on D = reading + zero_offset."""
    entry = machine(name)
    arm = entry.model()
    args = entry.node_arguments
    ns = f"/{name}{'_calibrated' if calibrated else ''}"
    if calibrated:
        document = yaml.safe_load(Path(entry.node_arguments[1]).read_text())
        section = document["/**"]["ros__parameters"]["hydraulic_machine"]
        for cylinder, offset in CALIBRATED.items():
            section["cylinders"][cylinder]["zero_offset"] = offset
        (tmp_path / "calibrated.yaml").write_text(yaml.safe_dump(document))
        args = ("--params-file", str(tmp_path / "calibrated.yaml"))
        arm = entry.model_from(section)
    args = (*args, "-r", f"__ns:={ns}")
    states: dict[int, np.ndarray] = {}
    poses: dict[int, np.ndarray] = {}
    probe.node.create_subscription(
        JointState,
        f"{ns}/joint_states",
        lambda m: states.__setitem__(stamp_ns(m.header), np.array(m.position)),
        QOS,
    )
    probe.node.create_subscription(
        PoseStamped,
        f"{ns}/tool_pose",
        lambda m: poses.__setitem__(stamp_ns(m.header), pose_matrix_of(m)),
        QOS,
    )
    urdf: dict[int, dict[str, float]] = {}
    probe.node.create_subscription(
        JointState,
        f"{ns}/urdf_joint_states",
        lambda m: urdf.__setitem__(stamp_ns(m.header), dict(zip(m.name, m.position, strict=True))),
        QOS,
    )
    markers: dict[int, np.ndarray] = {}  # stamp -> the tool sphere's centre
    probe.node.create_subscription(
        MarkerArray,
        f"{ns}/machine_markers",
        lambda m: markers.__setitem__(
            stamp_ns(m.markers[0].header),
            np.array(
                [
                    [k.pose.position.x, k.pose.position.y, k.pose.position.z]
                    for k in m.markers
                    if k.ns == "tool"
                ]
            ),
        ),
        QOS,
    )
    target = probe.node.create_publisher(TwistStamped, f"{ns}/target_twist", QOS)
    message = TwistStamped()
    message.header.frame_id = "base_link"
    t = message.twist
    t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z = TARGETS[name]
    executables = ("hydraulic_sim", "hydraulic_velocity_ik", "hydraulic_forward", "machine_markers")
    nodes = [NodeProcess(exe, *args) for exe in executables]
    try:
        probe.wait_until(lambda: len(poses) >= 5 or not all(n.alive() for n in nodes), TIMEOUT, "tool poses")
        assert all(n.alive() for n in nodes), [n.log() for n in nodes]
        start = poses[min(poses)][:3, 3]

        def moved() -> bool:
            target.publish(message)
            return np.linalg.norm(poses[max(poses)][:3, 3] - start) >= TRAVEL or not all(
                n.alive() for n in nodes
            )

        probe.wait_until(moved, TIMEOUT, f"the {name}'s tool to move {TRAVEL} m")
        # The markers (at most 30 Hz) and urdf_joint_states of a state the probe heard: on a fast
        # run the tool travels before the first of them arrives.
        probe.wait_until(
            lambda: (
                (set(markers) & set(states) and set(urdf) & set(states)) or not all(n.alive() for n in nodes)
            ),
            TIMEOUT,
            "markers and urdf_joint_states of a heard state",
        )
        assert all(n.alive() for n in nodes), [n.log() for n in nodes]
    finally:
        logs = [n.stop() for n in nodes]
    assert not any("Traceback" in log for log in logs), logs
    # Every published pose is the model's FK of the state with its stamp.
    common = sorted(set(states) & set(poses))
    assert len(common) >= 10
    D = np.array([states[s] for s in common])
    np.testing.assert_allclose(np.array([poses[s] for s in common]), arm.fkine(D), atol=1e-9)
    # urdf_joint_states: every URDF joint at the state of its stamp (robot_state_publisher's input).
    drawn = sorted(set(urdf) & set(states))
    assert drawn
    for s in drawn[:20]:
        expected = urdf_joint_values(arm, arm.true_state(states[s]))
        assert set(urdf[s]) == set(expected)
        np.testing.assert_allclose([urdf[s][k] for k in expected], list(expected.values()), atol=1e-12)
    # machine_markers draws the family machine from the same file: its tool sphere on the tool point.
    shown = sorted(set(markers) & set(states))
    assert shown
    for s in shown[:20]:
        np.testing.assert_allclose(markers[s], arm.fkine(states[s])[None, :3, 3], atol=1e-9)
    # The direction: the commanded task rows moved along the target, nothing else commanded moved.
    h = arm.hydraulic
    Q = h.pose(np.clip(arm.true_state(D), h.lower, h.upper))
    move = Q[-1] - Q[0]
    rows = list(h.description.velocity_rows)
    wanted = np.array(TARGETS[name][:3] + ([0.0] if h.description.has_angle else []))[rows]
    got = move[rows]
    cosine = got @ wanted / (np.linalg.norm(got) * np.linalg.norm(wanted))
    assert cosine > 0.999, (got, wanted)
    if h.description.has_angle:
        assert abs(move[3]) < 1e-2 * np.linalg.norm(move[:3]), move  # the bucket angle held


def test_ik_server_answers_fk_and_ik_for_both_machines(probe: Probe) -> None:
    for name in ("wheel_loader", "knuckle_crane"):
        entry = machine(name)
        arm = entry.model()
        h = arm.hydraulic
        ns = f"/ik_{name}"
        process, (ik, fk) = start_with_services(
            probe,
            "hydraulic_ik_server",
            *entry.node_arguments,
            "-r",
            f"__ns:={ns}",
            services=IK_FK,
            timeout=TIMEOUT,
            namespace=ns,
        )
        try:
            D = 0.3 * h.lower + 0.7 * h.upper
            request = SolveFK.Request(joint_state=JointState(name=list(arm.joint_names), position=D.tolist()))
            answer = probe.call(fk, request, TIMEOUT)
            assert answer.success, answer.message
            np.testing.assert_allclose(pose_matrix_of(answer.pose), arm.fkine(D), atol=1e-9)

            orient = h.description.has_angle
            ik_request = SolveIK.Request(target=answer.pose, use_orientation=orient)
            # The seed: the reference, with D's telescope (the crane's IK keeps the seed's extension).
            seed = h.reference.copy()
            seed[-1] = D[-1]
            ik_request.seed = JointState(name=list(arm.joint_names), position=seed.tolist())
            solved = probe.call(ik, ik_request, TIMEOUT)
            assert solved.success, solved.message
            assert list(solved.solution.name) == list(arm.joint_names)
            np.testing.assert_allclose(
                arm.fkine(np.array(solved.solution.position))[:3, 3], arm.fkine(D)[:3, 3], atol=1e-9
            )

            far = SolveIK.Request(target=answer.pose, use_orientation=orient)
            far.target.pose.position.z = 50.0
            refused = probe.call(ik, far, TIMEOUT)
            assert not refused.success and refused.error_code.val == Codes.NO_IK_SOLUTION, refused.message
            if not orient:  # the crane's tool has no angle: an orientation cannot be asked for
                asked = probe.call(ik, SolveIK.Request(target=answer.pose, use_orientation=True), TIMEOUT)
                assert not asked.success and "no tool angle" in asked.message
        finally:
            log = process.stop()
        assert "Traceback" not in log, log


def test_bad_inputs_are_refused_and_nothing_non_finite_goes_out(probe: Probe) -> None:
    """Each family node survives what its inputs carry: NaN, 1e300, a missing actuator, a foreign
    frame; it says why (log, status) and publishes nothing non-finite."""
    entry = machine("knuckle_crane")
    arm = entry.model()
    h = arm.hydraulic
    ns = "/bad_inputs"
    args = (*entry.node_arguments, "-r", f"__ns:={ns}")
    poses: list[np.ndarray] = []
    rates: list[np.ndarray] = []
    sim_states: list[np.ndarray] = []
    statuses: list[str] = []
    probe.node.create_subscription(
        PoseStamped, f"{ns}/tool_pose", lambda m: poses.append(pose_matrix_of(m)), QOS
    )
    probe.node.create_subscription(
        JointState, f"{ns}/rate_commands", lambda m: rates.append(np.array(m.velocity)), QOS
    )
    probe.node.create_subscription(
        JointState, f"{ns}/sim/joint_states", lambda m: sim_states.append(np.array(m.position)), QOS
    )
    probe.node.create_subscription(
        DiagnosticArray, f"{ns}/velocity_ik_status", lambda m: statuses.append(m.status[0].message), QOS
    )
    states = probe.node.create_publisher(JointState, f"{ns}/joint_states", QOS)
    targets = probe.node.create_publisher(TwistStamped, f"{ns}/target_twist", QOS)
    commands = probe.node.create_publisher(JointState, f"{ns}/sim/rate_commands", QOS)
    names = list(arm.joint_names)

    def state(position: list[float], names: list[str] = names) -> JointState:
        msg = JointState(name=names, position=position)
        msg.header.stamp = probe.node.get_clock().now().to_msg()
        return msg

    def twist(values: list[float], frame: str = "base_link") -> TwistStamped:
        msg = TwistStamped()
        msg.header.frame_id = frame
        t = msg.twist
        t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z = values
        return msg

    good = h.reference.tolist()
    nodes = [
        NodeProcess("hydraulic_forward", *args),
        NodeProcess("hydraulic_velocity_ik", *args),
        # The simulator on topics of its own: the probe's bad commands are not the velocity IK's.
        NodeProcess(
            "hydraulic_sim",
            *args,
            "-r",
            "joint_states:=sim/joint_states",
            "-r",
            "rate_commands:=sim/rate_commands",
        ),
    ]
    try:
        bad_states = [
            state([np.nan, *good[1:]]),
            state([1e300, *good[1:]]),
            state(good[1:], names[1:]),
            state([0.0, 1e6, 1e6, 1e6]),  # finite, the linkage cannot close: no output
        ]
        bad_targets = [
            twist([np.nan, 0, 0, 0, 0, 0]),
            twist([1e300, 0, 0, 0, 0, 0]),
            twist([0.1, 0, 0, 0, 0, 0], "elsewhere"),
        ]
        bad_commands = [
            JointState(name=names, velocity=[np.nan, 0.0, 0.0, 0.0]),
            JointState(name=names, velocity=[0.0, 1e6, 0.0, 0.0]),
            JointState(name=names[:2], velocity=[0.0, 0.0]),
        ]

        def sent() -> bool:
            for msg in bad_states:
                states.publish(msg)
            for msg in bad_targets:
                targets.publish(msg)
            for msg in bad_commands:
                commands.publish(msg)
            states.publish(state(good))
            targets.publish(twist([0.1, 0.0, 0.0, 0.0, 0.0, 0.0]))
            rejected = sum("rejected target_twist" in s for s in statuses)
            return (
                len(poses) >= 3 and len(rates) >= 3 and len(sim_states) >= 3 and rejected >= 1
            ) or not all(n.alive() for n in nodes)

        probe.wait_until(sent, TIMEOUT, "outputs of the good inputs among the bad")
        assert all(n.alive() for n in nodes), [n.log() for n in nodes]
    finally:
        logs = [n.stop() for n in nodes]
    assert not any("Traceback" in log for log in logs), logs
    assert not [w for log in logs for w in runtime_warnings(log)], logs
    assert "dropped joint_states" in logs[0]
    assert "rejected rate command" in logs[2]
    for pose in poses:
        np.testing.assert_allclose(pose, arm.fkine(h.reference), atol=1e-9)  # only the good state's
    assert all(np.all(np.isfinite(r)) and np.all(np.abs(r) <= h.max_speed) for r in rates)
    assert all(np.all(np.isfinite(s)) and np.all((s >= h.lower) & (s <= h.upper)) for s in sim_states)
