"""The forward node publishing grade and the URDF joints over DDS (ros tier); the geometry is checked
in test_excavator_grade.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PointStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe
from sensor_msgs.msg import JointState
from test_excavator_grade import EXC, LIM

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS
from excavator_kinematics.core.urdf_joints import URDF_JOINTS
from excavator_kinematics.nodes.display_outputs import urdf_joint_states
from manipulator_kinematics.param_files import config_path

pytestmark = pytest.mark.ros


def test_forward_node_publishes_grade_and_urdf_joints(tmp_path):
    """The forward node across processes: grade_height and urdf_joint_states for a state."""
    grade = {"enabled": True, "point": [5.0, 0.5, -1.0], "slope": -3.0, "cross_slope": 2.0, "frame": "design"}
    settings = tmp_path / "grade.yaml"
    settings.write_text(yaml.safe_dump({"/gr/excavator_forward": {"ros__parameters": {"grade": grade}}}))
    files = [config_path("excavator_cet200.yaml"), config_path("excavator_nodes.yaml"), settings]
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    probe = Probe("grade_probe")
    node = probe.node
    process = NodeProcess(
        "excavator_forward",
        *[a for f in files for a in ("--params-file", str(f))],
        *RELIABLE_INPUTS,
        "-r",
        "__ns:=/gr",
    )
    got: dict[str, list] = {"grade": [], "urdf": []}
    node.create_subscription(PointStamped, "/gr/grade_height", got["grade"].append, qos)
    node.create_subscription(JointState, "/gr/urdf_joint_states", got["urdf"].append, qos)
    swing_pub = node.create_publisher(JointState, "/gr/joint_states", qos)
    cylinder_pub = node.create_publisher(JointState, "/gr/cylinder_lengths", qos)
    D = LIM.reference + np.array([0.3, 0.1, -0.05, 0.08])
    D_dot = np.array([0.1, 0.03, -0.02, 0.04])
    try:
        outputs = ("/gr/grade_height", "/gr/urdf_joint_states")
        probe.wait_until(
            lambda: (
                all(node.count_publishers(t) for t in outputs)
                and cylinder_pub.get_subscription_count()
                and swing_pub.get_subscription_count()
            ),
            30.0,
            "excavator_forward",
        )
        for _ in range(20):
            swing_pub.publish(JointState(name=[JOINTS[0]], position=[D[0]], velocity=[D_dot[0]]))
            cylinder_pub.publish(
                JointState(name=list(CYLINDERS), position=list(D[1:]), velocity=list(D_dot[1:]))
            )
            try:
                probe.wait_until(lambda: got["grade"] and got["urdf"], 1.0, "the outputs")
                break
            except TimeoutError:
                continue
        assert got["grade"] and got["urdf"], process.log()[-2000:]
    finally:
        log = process.stop()
        probe.close()
    assert "Traceback" not in log, log
    message = got["grade"][0]
    assert message.header.frame_id == "design"
    p = message.point
    tip = EXC.pose(D)[:3]
    # By hand: the plane z = -1 - 0.03 (x - 5) + 0.02 (y - 0.5); height along its unit normal.
    normal = np.array([0.03, -0.02, 1.0]) / math.sqrt(1 + 0.03**2 + 0.02**2)
    assert p.z == pytest.approx(float((tip - [5.0, 0.5, -1.0]) @ normal), abs=1e-12)
    assert math.hypot(p.x, p.y) == pytest.approx(
        float(np.linalg.norm(tip - [5.0, 0.5, -1.0] - p.z * normal)), abs=1e-12
    )
    joints = got["urdf"][0]
    assert tuple(joints.name) == URDF_JOINTS
    positions, rates = urdf_joint_states(EXC, D, D_dot)
    np.testing.assert_allclose(joints.position, positions, atol=1e-12)
    np.testing.assert_allclose(joints.velocity, rates, atol=1e-12)
