"""The forward node publishing the cutting edge's grade over a design TIN, over DDS (ros tier); the
TIN itself is checked in test_design_surface.py."""

from __future__ import annotations

import numpy as np
import pytest
from test_design_surface import DITCH, E0, N0, ditch_by_hand

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.grade.design_surface import SitePose, cutting_edge, read_landxml

pytestmark = pytest.mark.ros


def test_forward_node_publishes_cutting_edge_grade_over_the_tin():
    """excavator_forward across processes with the ditch TIN and a GNSS pose topic: the three
    heights equal the core's, a point beyond the surface gets no message but a WARN status, and
    no site pose gives an ERROR status."""
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import PointStamped, PoseStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from ros_harness import NodeProcess, Probe
    from sensor_msgs.msg import JointState

    from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS
    from manipulator_kinematics.param_files import config_path

    exc = Excavator.default()
    surface = {
        "file": str(DITCH),
        "surface": "Ditch design",
        "site_frame": "site",
        "site_pose_source": "topic",
        "site_pose_max_age": 0.5,
    }
    files = [config_path("excavator_cet200.yaml"), config_path("excavator_nodes.yaml")]
    process = NodeProcess(
        "excavator_forward",
        *[a for f in files for a in ("--params-file", str(f))],
        "-r",
        "__ns:=/tin",
        params={"/tin/excavator_forward": {"ros__parameters": {"design_surface": surface}}},
    )
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    probe = Probe("tin_probe")
    node = probe.node
    got: dict[str, list] = {p: [] for p in ("tip", "left", "right", "status")}
    for p in ("tip", "left", "right"):
        node.create_subscription(PointStamped, f"/tin/grade/{p}", got[p].append, qos)
    node.create_subscription(DiagnosticArray, "/tin/grade/status", got["status"].append, latched)
    swing_pub = node.create_publisher(JointState, "/tin/joint_states", qos)
    cylinder_pub = node.create_publisher(JointState, "/tin/cylinder_lengths", qos)
    pose_pub = node.create_publisher(PoseStamped, "/tin/site_pose", qos)
    # Machine 6 m west of the ditch axis, facing east (yaw 0), standing 1 m below the banks' level:
    # the reach of about 5.5 m puts the cutting edge over the ditch.
    D = exc.limits.reference + np.array([0.0, 0.1, -0.25, 0.05])
    position = [E0 - 6.0, N0 + 10.0, 99.0]

    def send(stamp_sec: int, with_pose: bool) -> None:
        stamp = Time(sec=stamp_sec)
        if with_pose:
            pose = PoseStamped()
            pose.header.stamp, pose.header.frame_id = stamp, "site"
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = position
            pose.pose.orientation.w = 1.0
            pose_pub.publish(pose)
        swing = JointState(name=[JOINTS[0]], position=[D[0]], velocity=[0.0])
        cylinders = JointState(name=list(CYLINDERS), position=list(D[1:]), velocity=[0.0] * 3)
        swing.header.stamp = cylinders.header.stamp = stamp
        swing_pub.publish(swing)
        cylinder_pub.publish(cylinders)

    try:
        probe.wait_until(
            lambda: (
                node.count_publishers("/tin/grade/tip")
                and cylinder_pub.get_subscription_count()
                and pose_pub.get_subscription_count()
            ),
            30.0,
            "excavator_forward",
        )
        # No site pose yet: every point ERROR.
        for stamp in range(1, 30):
            send(stamp, with_pose=False)
            try:
                probe.wait_until(lambda: got["status"], 1.0, "the status")
                break
            except TimeoutError:
                continue
        assert got["status"], process.log()[-2000:]
        assert [s.level for s in got["status"][-1].status] == [DiagnosticStatus.ERROR] * 3
        for stamp in range(30, 60):
            send(stamp, with_pose=True)
            try:
                probe.wait_until(lambda: got["tip"] and got["left"] and got["right"], 1.0, "the grade")
                break
            except TimeoutError:
                continue
        assert got["tip"], process.log()[-2000:]
        probe.wait_until(lambda: got["status"][-1].status[0].level == DiagnosticStatus.OK, 5.0, "OK status")
        # Swing 1.2 rad left with the machine 12 m west of the axis: the edge is beyond the west edge.
        D[0] = 1.2
        position[0] = E0 - 12.0
        for stamp in range(60, 90):
            send(stamp, with_pose=True)
            try:
                probe.wait_until(
                    lambda: got["status"][-1].status[0].level == DiagnosticStatus.WARN, 1.0, "WARN"
                )
                break
            except TimeoutError:
                continue
    finally:
        log = process.stop()
        probe.close()
    assert "Traceback" not in log, log
    assert got["status"][-1].status[0].level == DiagnosticStatus.WARN, log[-2000:]
    assert got["status"][-1].status[0].message == "outside the design surface"
    tin = read_landxml(DITCH, "Ditch design")
    D[0] = 0.0
    position[0] = E0 - 6.0
    edge = SitePose.from_rpy(position, [0.0, 0.0, 0.0]).apply(cutting_edge(exc.pose(D)[:3], 0.0, 1.0))
    expected = tin.heights(edge)
    assert expected.inside.all()
    for i, p in enumerate(("tip", "left", "right")):
        message = got[p][0]
        assert message.header.frame_id == "site"
        np.testing.assert_allclose(
            [message.point.x, message.point.y, message.point.z],
            [*edge[i, :2], expected.height[i]],
            rtol=0,
            atol=1e-9,
        )
    # By hand for the tip: the ditch surface below it from the V-ditch formula.
    e, n = edge[0, 0] - E0, edge[0, 1] - N0
    assert got["tip"][0].point.z == pytest.approx(edge[0, 2] - float(ditch_by_hand(e, n)), abs=1e-9)
