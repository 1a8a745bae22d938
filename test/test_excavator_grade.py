"""Grade indication and the URDF joints' rates (excavator_kinematics.nodes.display_outputs) against hand
geometry, finite differences and the forward node across processes."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PointStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe
from sensor_msgs.msg import JointState

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.urdf_joints import URDF_JOINTS, joint_positions
from excavator_kinematics.nodes.display_outputs import DesignPlane, urdf_joint_states
from manipulator_kinematics.param_files import ConfigError, config_path

EXC = Excavator.default()
LIM = EXC.limits
RNG = np.random.default_rng(13)


def plane(**grade) -> DesignPlane:
    return DesignPlane.from_settings({"point": [0.0, 0.0, 0.0], **grade})


def test_level_plane_height_is_z_difference():
    p = plane(point=[3.0, -1.0, -0.5])
    tips = RNG.uniform(-5, 5, (100, 3))
    np.testing.assert_allclose(p.height(tips), tips[:, 2] + 0.5, atol=1e-15)
    np.testing.assert_allclose(p.local(tips), tips - [3.0, -1.0, -0.5], atol=1e-15)


def test_slope_by_hand():
    # 100 % slope along x through the origin: the plane z = x, 45 deg. A tip at (2, 0, 0) is 2 m below
    # the surface point above it, so sqrt(2) m below the plane, perpendicular.
    p = plane(slope=100.0)
    assert p.height([2.0, 0.0, 0.0]) == pytest.approx(-math.sqrt(2.0), abs=1e-15)
    assert p.height([0.0, 7.0, 1.0]) == pytest.approx(1.0 / math.sqrt(2.0), abs=1e-15)
    # On the plane: height 0, and its x in the surface frame is the distance up the slope.
    np.testing.assert_allclose(p.local([1.0, 0.0, 1.0]), [math.sqrt(2.0), 0.0, 0.0], atol=1e-15)
    # Cross-slope -2 % along y: the point (0, 10, -0.2) lies on it; straight above it by 1 m is
    # cos(atan(0.02)) m above the plane.
    q = plane(cross_slope=-2.0)
    assert q.height([0.0, 10.0, -0.2]) == pytest.approx(0.0, abs=1e-15)
    assert q.height([0.0, 10.0, 0.8]) == pytest.approx(math.cos(math.atan(0.02)), abs=1e-15)


def test_slopes_and_normal_agree_and_frame_is_orthonormal():
    s, c = 3.5, -1.25
    by_slope, by_normal = plane(slope=s, cross_slope=c), plane(normal=[-s, -c, 100.0])
    tips = RNG.uniform(-10, 10, (50, 3))
    np.testing.assert_allclose(by_slope.height(tips), by_normal.height(tips), atol=1e-14)
    r = by_slope.rotation
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-14)
    # x is the base x projected onto the plane: in the plane of base x and the normal, forward.
    assert r[0] @ np.cross(r[2], [1.0, 0.0, 0.0]) == pytest.approx(0.0, abs=1e-15) and r[0, 0] > 0
    # A point of the surface z = s x + c y (percent) has height 0 whatever x, y.
    xy = RNG.uniform(-20, 20, (50, 2))
    on = np.column_stack([xy, xy @ [s / 100, c / 100]])
    np.testing.assert_allclose(by_slope.height(on), 0.0, atol=1e-13)


@pytest.mark.parametrize(
    "grade, key",
    [
        ({"normal": [0.0, 0.0, 1.0], "slope": 1.0}, "grade.normal"),
        ({"normal": [1.0, 0.0, 0.0]}, "grade.normal"),
        ({"normal": [0.0, 0.0, -1.0]}, "grade.normal"),
        ({"normal": [0.0, 0.0, 0.0]}, "grade.normal"),
    ],
)
def test_inconsistent_planes_name_the_key(grade, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        plane(**grade)


def test_urdf_joint_rates_match_finite_differences():
    """Each passive joint depends on one cylinder (the module's claim): its rate equals the central
    difference of joint_positions along the whole state rate."""
    D = RNG.uniform(LIM.d_min + 0.05, LIM.d_max - 0.05, (20, 4))
    D_dot = RNG.uniform(-1, 1, (20, 4)) * LIM.max_rates
    positions, rates = urdf_joint_states(EXC, D, D_dot)
    np.testing.assert_array_equal(positions, joint_positions(EXC, D))
    h = 1e-6
    diff = joint_positions(EXC, D + h * D_dot) - joint_positions(EXC, D - h * D_dot)
    diff = (diff + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(rates, diff / (2 * h), atol=1e-7)
    # The open chain's against the model's exact joint rates.
    exact = EXC.state(D, D_dot).theta_dot
    np.testing.assert_allclose(rates[:, :4], exact, atol=1e-8)
    # At the stroke ends (one-sided difference), still the model's rates.
    ends = np.column_stack([D[:2, 0], np.stack([LIM.d_min[1:], LIM.d_max[1:]])])
    _, end_rates = urdf_joint_states(EXC, ends, D_dot[:2])
    np.testing.assert_allclose(end_rates[:, :4], EXC.state(ends, D_dot[:2]).theta_dot, atol=1e-5)


@pytest.mark.ros
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
