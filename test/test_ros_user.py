"""What a ROS 2 user trips over (issue #20), checked as a user meets it: parameter precedence for
every node kind, parameter descriptions and ranges, input QoS with both kinds of publisher across
processes, frame prefixes (nodes, URDF, two machines in one bag's TF tree), an empty target
frame_id, the documented frames, and the demo's network isolation."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PoseStamped, TwistStamped
from rcl_interfaces.srv import DescribeParameters, GetParameters
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.parameter import parameter_value_to_python
from rclpy.qos import QoSPolicyKind, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from ros_harness import REPO, NodeProcess, Probe
from sensor_msgs.msg import JointState
from test_bag_visual import read
from visualization_msgs.msg import MarkerArray

from excavator_kinematics.core.kinematics import CYLINDERS, Excavator
from manipulator_kinematics import ros_domain
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.visual import add_visuals
from manipulator_kinematics.bag.writer import BagWriter
from manipulator_kinematics.nodes.base import command_line_values
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.registry import machine
from manipulator_kinematics.urdf import machine_urdf, prefixed_urdf
from manipulator_kinematics_interfaces.srv import SolveIK
from palletizer_kinematics.kinematics import Palletizer

pytestmark = pytest.mark.ros

TIMEOUT = 20.0
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
BEST_EFFORT = qos_profile_sensor_data  # what a sensor driver uses
SCARA_Q = [0.1, 0.3, 1.2]


def write(path: Path, document: dict) -> str:
    path.write_text(yaml.safe_dump(document))
    return str(path)


# ---- precedence --------------------------------------------------------------------------------
def test_the_precedence_rule_without_ros(tmp_path: Path) -> None:
    first = write(
        tmp_path / "a.yaml",
        {
            "/**": {"ros__parameters": {"x": 1, "scara": {"l2": 0.3}}},
            "/**/node": {"ros__parameters": {"y": 1, "z": 1}},
        },
    )
    second = write(
        tmp_path / "b.yaml", {"/**": {"ros__parameters": {"y": 2}}, "/ns/node": {"ros__parameters": {"w": 2}}}
    )
    argv = [
        "exe",
        "--ros-args",
        "-p",
        "z:=3",
        "--params-file",
        first,
        "--params-file",
        second,
        "-p",
        "other:x:=9",
        "-p",
        "node:scara.l2:=0.35",
    ]
    values = command_line_values("/ns/node", argv)
    # a later file's /** beats an earlier file's node section; -p beats every file, wherever it is
    assert values == {"x": 1, "scara.l2": 0.35, "y": 2, "z": 3, "w": 2}
    elsewhere = command_line_values("/node", argv)
    assert elsewhere["scara.l2"] == 0.35 and "w" not in elsewhere
    # values as rcl reads them: a plain 1e3 is a number (PyYAML alone makes it a string)
    exponent = tmp_path / "c.yaml"
    exponent.write_text("/**:\n  ros__parameters:\n    rate: 2e2\n    name: '1e3'\n")
    argv = ["exe", "--ros-args", "--params-file", str(exponent), "-p", "depth:=1e3"]
    assert command_line_values("/node", argv) == {"rate": 200.0, "name": "1e3", "depth": 1000.0}


#: node kind -> executable, machine file, a setting with its value in a node section of a file and
#: on the command line, another setting with its value in that node section and in a later file's /**
KINDS = {
    "serial forward": ("scara_forward", "config/scara.yaml", "warning_period", 3.0, 4.0, "qos_depth", 7, 9),
    "ik server": (
        "scara_ik_server",
        "config/scara.yaml",
        "base_frame",
        "file",
        "odom",
        "frame_prefix",
        "a/",
        "b/",
    ),
    "markers": ("machine_markers", "config/scara.yaml", "warning_period", 3.0, 4.0, "qos_depth", 7, 9),
    "excavator forward": (
        "excavator_forward",
        "config/excavator_cet200.yaml",
        "base_frame",
        "file",
        "odom",
        "qos_depth",
        7,
        9,
    ),
    "velocity ik": (
        "excavator_velocity_ik",
        "config/excavator_cet200.yaml",
        "warning_period",
        3.0,
        4.0,
        "qos_depth",
        7,
        9,
    ),
    "simulator": ("excavator_sim", "config/excavator_cet200.yaml", "rate", 50.0, 60.0, "qos_depth", 7, 9),
}


def get(probe: Probe, node: str, names: list[str]) -> list:
    client = probe.node.create_client(GetParameters, f"/{node}/get_parameters")
    probe.wait_until(client.service_is_ready, TIMEOUT, f"{node}/get_parameters")
    return [
        parameter_value_to_python(v)
        for v in probe.call(client, GetParameters.Request(names=names), TIMEOUT).values
    ]


def test_p_wins_over_every_params_file_for_every_node_kind(probe: Probe, tmp_path: Path) -> None:
    """The issue's case (a machine file with a /** section, so rcl let a node section beat -p),
    -p before the files, and a later file's /** against an earlier node section, per node kind."""
    processes = {}
    try:
        for kind, (exe, machine_file, key, in_file, given, other, early, late) in KINDS.items():
            section = write(
                tmp_path / f"{exe}.yaml", {f"/**/{exe}": {"ros__parameters": {key: in_file, other: early}}}
            )
            later = write(tmp_path / f"{exe}_later.yaml", {"/**": {"ros__parameters": {other: late}}})
            processes[kind] = NodeProcess(
                exe,
                "-p",
                f"{key}:={given}",
                "--params-file",
                str(REPO / machine_file),
                "--params-file",
                section,
                "--params-file",
                later,
            )
        for kind, (exe, _, key, _, given, other, _, late) in KINDS.items():
            values = get(probe, exe, [key, other])
            assert values == [given, late], (kind, values, processes[kind].log())
    finally:
        for process in processes.values():
            process.stop()


def test_machine_parameters_are_described_with_their_range(probe: Probe) -> None:
    with NodeProcess("excavator_forward") as process:
        client = probe.node.create_client(DescribeParameters, "/excavator_forward/describe_parameters")
        probe.wait_until(client.service_is_ready, TIMEOUT, "describe_parameters")
        names = [
            "hydraulic_machine.links.h_link.length",
            "hydraulic_machine.bodies.boom.pins.arm_pin",
            "input_reliability",
            "frame_prefix",
        ]
        length, pin, reliability, prefix = probe.call(
            client, DescribeParameters.Request(names=names), TIMEOUT
        ).descriptors
        assert length.description == "number in (0, 30] m", process.log()
        (bounds,) = length.floating_point_range
        assert (bounds.from_value, bounds.to_value) == (0.0, 30.0)
        assert pin.description.startswith("list of 2 numbers, each a number in [-30, 30] m")
        assert "one of reliable, best_effort" in reliability.additional_constraints
        assert "robot_state_publisher" in prefix.description and all(
            d.read_only for d in (length, pin, reliability, prefix)
        )


# ---- input QoS -------------------------------------------------------------------------------
def joint_state(names, positions, velocities=(), sec: int = 1) -> JointState:
    msg = JointState(
        name=list(names), position=[float(v) for v in positions], velocity=[float(v) for v in velocities]
    )
    msg.header.stamp.sec = sec
    return msg


class Outputs:
    def __init__(self, probe: Probe, kind: type, topic: str) -> None:
        self.messages: list = []
        probe.node.create_subscription(kind, topic, self.messages.append, RELIABLE)


def test_both_kinds_of_publisher_are_heard_where_the_default_is_best_effort(probe: Probe) -> None:
    node = probe.node
    scara = NodeProcess("scara_forward", "-r", "__ns:=/qos", "-p", "frame_prefix:=m1/")
    markers = NodeProcess(
        "machine_markers", "-r", "__ns:=/qos", "--params-file", str(REPO / "config/scara.yaml")
    )
    excavator = NodeProcess("excavator_forward", "-r", "__ns:=/qos")
    velocity_ik = NodeProcess("excavator_velocity_ik", "-r", "__ns:=/qos")
    try:
        poses = Outputs(probe, PoseStamped, "/qos/tool_pose")
        drawn = Outputs(probe, MarkerArray, "/qos/machine_markers")
        buckets = Outputs(probe, PoseStamped, "/qos/bucket_pose")
        commands = Outputs(probe, JointState, "/qos/cylinder_rate_commands")
        for sec, qos in ((1, BEST_EFFORT), (2, RELIABLE)):
            joints = node.create_publisher(JointState, "/qos/joint_states", qos)
            cylinders = node.create_publisher(JointState, "/qos/cylinder_lengths", qos)
            target = node.create_publisher(TwistStamped, "/qos/target_bucket_twist", qos)
            probe.wait_until(
                lambda j=joints, c=cylinders, t=target: (
                    j.get_subscription_count() >= 4
                    and c.get_subscription_count() >= 3
                    and t.get_subscription_count() >= 1
                ),
                TIMEOUT,
                f"every node subscribed ({qos.reliability.name})",
            )
            D = Excavator.default().limits.reference
            twist = TwistStamped()  # frame_id empty: the base frame
            twist.header.stamp.sec = sec
            twist.twist.linear.x = -0.05

            def send(sec=sec, joints=joints, cylinders=cylinders, target=target, twist=twist, D=D) -> None:
                joints.publish(
                    joint_state(
                        ["rail_joint", "shoulder_joint", "elbow_joint", "swing_joint"],
                        [*SCARA_Q, D[0]],
                        [0.0, 0.0, 0.0, 0.0],
                        sec,
                    )
                )
                cylinders.publish(joint_state(CYLINDERS, D[1:], [0.0] * 3, sec))
                target.publish(twist)

            def heard(sec=sec) -> bool:
                return (
                    any(m.header.stamp.sec == sec for m in poses.messages)
                    and any(m.header.stamp.sec == sec for m in buckets.messages)
                    and any(m.markers[0].header.stamp.sec == sec for m in drawn.messages)
                    and any(m.header.stamp.sec == sec for m in commands.messages)
                )

            while not heard():  # best effort may drop one; every round is a complete state
                send()
                try:
                    probe.wait_until(heard, 0.5, "outputs")
                except TimeoutError:
                    if not all(p.alive() for p in (scara, markers, excavator, velocity_ik)):
                        raise
            node.destroy_publisher(joints)
            node.destroy_publisher(cylinders)
            node.destroy_publisher(target)
        assert {m.header.frame_id for m in poses.messages} == {"m1/base_link"}
        assert any(np.any(m.velocity) for m in commands.messages)  # the empty frame_id was taken
    finally:
        for process in (scara, markers, excavator, velocity_ik):
            log = process.stop()
            assert "rejected target_bucket_twist" not in log, log


def test_the_simulator_hears_reliable_commands_only_unless_told(probe: Probe) -> None:
    """Its default is reliable (the velocity IK's single stop must arrive); best_effort is a
    setting away."""
    with (
        NodeProcess("excavator_sim", "-r", "__ns:=/sim_a"),
        NodeProcess("excavator_sim", "-r", "__ns:=/sim_b", "-p", "input_reliability:=best_effort"),
    ):
        incompatible = []
        events = PublisherEventCallbacks(
            incompatible_qos=lambda event: incompatible.append(event.last_policy_kind)
        )
        reliable_a = probe.node.create_publisher(JointState, "/sim_a/cylinder_rate_commands", RELIABLE)
        sensor_a = probe.node.create_publisher(
            JointState, "/sim_a/cylinder_rate_commands", BEST_EFFORT, event_callbacks=events
        )
        sensor_b = probe.node.create_publisher(JointState, "/sim_b/cylinder_rate_commands", BEST_EFFORT)
        probe.wait_until(lambda: reliable_a.get_subscription_count() > 0, TIMEOUT, "sim_a subscribed")
        probe.wait_until(lambda: sensor_b.get_subscription_count() > 0, TIMEOUT, "sim_b, best effort")
        probe.wait_until(lambda: bool(incompatible), TIMEOUT, "sim_a refusing a best-effort publisher")
        assert set(incompatible) == {QoSPolicyKind.RELIABILITY} and sensor_a.get_subscription_count() == 0


# ---- frame prefixes, two machines in one TF tree ---------------------------------------------
def test_the_urdf_takes_a_prefix_on_every_link() -> None:
    text = prefixed_urdf(machine_urdf("scara"), "m1/")
    root = ET.fromstring(text)
    links = [link.get("name") for link in root.iter("link")]
    ends = [e.get("link") for j in root.iter("joint") for e in (j.find("parent"), j.find("child"))]
    assert links and all(name.startswith("m1/") for name in links + ends)
    assert "m1/base_link" in links and "m1/tool" in links


@pytest.mark.parametrize("name", ["excavator", "scara", "pump_boom", "tool_changer", "palletizer"])
def test_the_urdf_robot_name_comes_from_the_machine_file(name: str) -> None:
    record = machine(name)
    values = record.parameters()
    # the excavator's name is in its linkage's section (hydraulic_machine), the others' in their own
    key = next(iter(record.also), None)
    named = values[key] if key else values
    shipped = ET.fromstring(machine_urdf(name)).get("name")
    assert (
        shipped
        == named["name"]
        == load_parameters(config_path(record.config_file))[key or record.section]["name"]
    )
    renamed = record.model_from(
        {**values, key: {**named, "name": "left_machine"}} if key else {**values, "name": "left_machine"}
    )
    assert ET.fromstring(record.urdf(renamed)).get("name") == "left_machine"


def tree(messages: dict[str, list]) -> dict[str, str]:
    """child frame -> parent frame of every transform in /tf and /tf_static; a child with two
    parents (two machines' frames colliding) fails."""
    parents: dict[str, str] = {}
    for topic in ("/tf", "/tf_static"):
        for message in messages.get(topic, []):
            for t in message.transforms:
                known = parents.setdefault(t.child_frame_id, t.header.frame_id)
                assert known == t.header.frame_id, (t.child_frame_id, known, t.header.frame_id)
    return parents


def test_two_machines_share_one_tf_tree_in_one_bag(tmp_path: Path) -> None:
    """Two SCARAs (the same link names) recorded in /m1 and /m2: with frame prefixes m1/ and m2/
    and a root frame, /tf + /tf_static compose one tree holding every link of both URDFs once."""
    golden = BagReader(REPO / "test/data/scara_forward_golden")
    both = tmp_path / "two_scaras"
    with BagWriter(both) as writer:
        for ns in ("/m1", "/m2"):
            writer.add_topic(f"{ns}/joint_states", golden.topics["/joint_states"].msgtype)
        for _, log_time, raw in golden.messages(["/joint_states"]):
            for offset, ns in enumerate(("/m1", "/m2")):
                writer.write(f"{ns}/joint_states", log_time + offset, raw)
    out = tmp_path / "visual"
    added = add_visuals(both, out, frame_prefix={"/m1": "m1/", "m2": "m2/"}, root_frame="world")
    assert sorted(a.namespace for a in added) == ["/m1", "/m2"]
    messages = read(out)
    parents = tree(messages)
    links = [link.get("name") for link in ET.fromstring(machine_urdf("scara")).iter("link")]
    for prefix in ("m1/", "m2/"):
        assert {prefix + name for name in links} - {"m1/base_link", "m2/base_link"} <= set(parents)
        assert parents[prefix + "base_link"] == "world"
    for frame in parents:  # one tree: every frame reaches the root
        seen = set()
        while frame != "world":
            assert frame not in seen, "cycle"
            seen.add(frame)
            frame = parents[frame]
    descriptions = [m.data for ns in ("/m1", "/m2") for m in messages[f"{ns}/robot_description"]]
    assert 'name="m1/base_link"' in descriptions[0] and 'name="m2/base_link"' in descriptions[1]
    markers = {
        m.markers[0].header.frame_id for ns in ("/m1", "/m2") for m in messages[f"{ns}/machine_markers"]
    }
    assert markers == {"m1/base_link", "m2/base_link"}


# ---- what the docs say -------------------------------------------------------------------------
def test_the_excavator_base_frame_does_not_swing() -> None:
    """docs/excavator.md: swing theta1 = 90 deg puts the tip at +y (the base frame stays put)."""
    exc = Excavator.default()
    D = exc.limits.reference.copy()
    x0, y0 = exc.pose(D)[:2]
    D[0] = np.pi / 2
    x, y = exc.pose(D)[:2]
    assert abs(y0) < 1e-12 and x0 > 1.0
    np.testing.assert_allclose([x, y], [0.0, x0], atol=1e-9)


def test_palletizer_dh_mode_answers_in_dh_names(probe: Probe) -> None:
    """docs/palletizer.md: mode dh returns theta1, theta2, theta3, theta5, named so."""
    model = Palletizer.default()
    target = model.fkine(np.array([0.3, 0.2, 0.5, 1.0]))
    with NodeProcess("palletizer_ik_server") as process:
        client = probe.node.create_client(SolveIK, "solve_ik")
        probe.wait_until(client.service_is_ready, TIMEOUT, "solve_ik")
        request = SolveIK.Request(mode="dh")
        p = request.target.pose.position
        p.x, p.y, p.z = target[:3, 3].tolist()
        response = probe.call(client, request, TIMEOUT)
        assert response.success, (response.message, process.log())
        assert list(response.solution.name) == ["theta1", "theta2", "theta3", "theta5"]


# ---- network isolation ---------------------------------------------------------------------------
def test_isolated_takes_a_free_domain_and_localhost_unless_set(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE", raising=False)
    with ros_domain.isolated() as note:
        domain = int(os.environ["ROS_DOMAIN_ID"])
        assert 1 <= domain < ros_domain.EXAMPLES_DOMAIN
        assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        assert f"ROS_DOMAIN_ID={domain}" in note
        with ros_domain.reserved_domain() as other:
            assert other != domain  # held while the run lasts
    assert "ROS_DOMAIN_ID" not in os.environ and "ROS_AUTOMATIC_DISCOVERY_RANGE" not in os.environ
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")
    with ros_domain.isolated() as note:
        assert os.environ["ROS_DOMAIN_ID"] == "7" and os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
        assert "set by you" in note


def test_the_scripts_keep_the_examples_and_the_demo_local() -> None:
    env_sh = (REPO / "scripts/env.sh").read_text(encoding="utf-8")
    assert f'ROS_DOMAIN_ID="${{ROS_DOMAIN_ID:-{ros_domain.EXAMPLES_DOMAIN}}}"' in env_sh
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"' in env_sh
    demo_sh = (REPO / "scripts/demo.sh").read_text(encoding="utf-8")
    assert demo_sh.index('user_domain="${ROS_DOMAIN_ID-}"') < demo_sh.index("env.sh")
    assert '[ -n "$user_domain" ] || unset ROS_DOMAIN_ID' in demo_sh
