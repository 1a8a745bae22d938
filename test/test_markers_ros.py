"""machine_markers across processes: the MarkerArray it publishes for a known state is the machine's
scene (Machine.scene) of that state, for the excavator (joint_states + cylinder_lengths) and a
serial machine (joint_states); a command line without a machine file is refused (isolated domain)."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.registry import machine
from manipulator_kinematics.scene import solids

pytestmark = pytest.mark.ros

TIMEOUT = 20.0
STAMP = Time(sec=1_700_000_123, nanosec=456_000_000)


def markers_for(probe: Probe, config: str, messages: dict[str, JointState]) -> MarkerArray:
    """Start machine_markers on ``config``, publish ``messages`` (topic -> state) until a
    MarkerArray arrives, return it."""
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    received: list[MarkerArray] = []
    sub = probe.node.create_subscription(MarkerArray, "machine_markers", received.append, qos)
    pubs = {topic: probe.node.create_publisher(JointState, topic, qos) for topic in messages}
    process = NodeProcess("machine_markers", "--params-file", str(config_path(config)), *RELIABLE_INPUTS)

    def arrived() -> bool:
        assert process.alive(), process.log()
        for topic, msg in messages.items():
            if pubs[topic].get_subscription_count():
                pubs[topic].publish(msg)
        return bool(received)

    try:
        probe.wait_until(arrived, TIMEOUT, "machine_markers")
    finally:
        log = process.stop()
        for pub in pubs.values():
            probe.node.destroy_publisher(pub)
        probe.node.destroy_subscription(sub)
    assert "Traceback" not in log and "not drawn" not in log, log
    return received[-1]


def check(array: MarkerArray, name: str, state: np.ndarray) -> None:
    m = machine(name)
    model = m.model()
    expected = solids(m.scene(model, state))
    markers = array.markers
    assert len(markers) == len(expected.names)
    for i, marker in enumerate(markers):
        assert marker.header.frame_id == "base_link" and marker.header.stamp == STAMP
        assert (marker.ns, marker.id, marker.action) == (expected.kinds[i], i, Marker.ADD)
        assert marker.type == (Marker.CYLINDER if expected.cylinder[i] else Marker.SPHERE)
        p, o, s = marker.pose.position, marker.pose.orientation, marker.scale
        np.testing.assert_allclose([p.x, p.y, p.z], expected.position[i], atol=1e-12)
        np.testing.assert_allclose([o.x, o.y, o.z, o.w], expected.orientation[i], atol=1e-12)
        np.testing.assert_allclose([s.x, s.y, s.z], expected.scale[i], atol=1e-12)
    # The tool sphere sits on the machine's tool point: FK, not only the scene, agrees.
    tool = next(mk for mk in markers if mk.ns == "tool").pose.position
    if name == "excavator":
        np.testing.assert_allclose([tool.x, tool.y, tool.z], model.pose(state)[:3], atol=1e-12)
    else:
        np.testing.assert_allclose([tool.x, tool.y, tool.z], model.fkine(state)[:3, 3], atol=1e-12)


def joint_state(names, positions) -> JointState:
    return JointState(header=Header(stamp=STAMP), name=list(names), position=[float(v) for v in positions])


def test_excavator_markers_are_its_scene(probe: Probe) -> None:
    model = machine("excavator").model()
    D = model.limits.reference + np.array([0.4, 0.2, -0.3, 0.25])
    messages = {
        "joint_states": joint_state(["swing_joint"], D[:1]),
        "cylinder_lengths": joint_state(["boom_cylinder", "arm_cylinder", "bucket_cylinder"], D[1:]),
    }
    array = markers_for(probe, "excavator_cet200.yaml", messages)
    check(array, "excavator", D)
    kinds = {mk.ns for mk in array.markers}
    assert {"barrel", "rod", "linkage", "link", "joint", "tool", "base"} <= kinds


def test_serial_markers_are_its_scene(probe: Probe) -> None:
    model = machine("tool_changer").model()
    lo, hi = np.asarray(model.limits.lower), np.asarray(model.limits.upper)
    q = lo + (hi - lo) * np.array([0.2, 0.7, 0.4, 0.6, 0.3, 0.8])
    # An unrelated joint and a cylinder topic with nothing on it change nothing.
    messages = {"joint_states": joint_state([*model.joint_names, "other_joint"], [*q, 9.0])}
    check(markers_for(probe, "tool_changer.yaml", messages), "tool_changer", q)


def test_without_a_machine_file_the_node_refuses_to_start() -> None:
    result = subprocess.run([console_script("machine_markers")], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    assert "no machine section" in result.stderr and "excavator_cet200.yaml" in result.stderr


def test_absurd_and_non_finite_states_are_not_drawn(probe: Probe) -> None:
    """Issue 29 defect 6: a SCARA rail position of 1e308 drew markers of infinite scale and position.
    Now a value beyond a joint's limits by more than their span is ignored with a reason, nothing
    non-finite is published, and the next valid state is drawn."""
    model = machine("scara").model()
    lo, hi = np.asarray(model.limits.lower), np.asarray(model.limits.upper)
    q = lo + (hi - lo) * np.array([0.3, 0.6, 0.4, 0.5][: len(lo)])
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    received: list[MarkerArray] = []
    sub = probe.node.create_subscription(MarkerArray, "machine_markers", received.append, qos)
    pub = probe.node.create_publisher(JointState, "joint_states", qos)
    process = NodeProcess(
        "machine_markers", "--params-file", str(config_path("scara.yaml")), *RELIABLE_INPUTS
    )
    names = list(model.joint_names)
    try:
        probe.wait_until(lambda: pub.get_subscription_count(), TIMEOUT, "machine_markers")
        for value in (1e308, -1e308, hi[0] + 3.0 * (hi[0] - lo[0])):
            pub.publish(joint_state(names, [value, *q[1:]]))
        probe.wait_until(lambda: "ignored" in process.log(), TIMEOUT, "the reason")
        assert not received
        pub.publish(joint_state(names, q))
        probe.wait_until(lambda: received, TIMEOUT, "the valid state's markers")
    finally:
        log = process.stop()
        probe.node.destroy_publisher(pub)
        probe.node.destroy_subscription(sub)
    assert "Traceback" not in log, log
    assert f"ignored {names[0]} = 1e+308" in log
    check(received[-1], "scara", q)
