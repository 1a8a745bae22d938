"""A site-frame zone across processes: excavator_sim -> excavator_velocity_ik, the site pose
published on ``site_pose`` by the test. The tip driven straight up stops below a ceiling given in
the site frame (the machine's base_link 50 m up in it); when the site pose stops coming the
velocity IK stops the machine with the reason, and moves again once it comes back. The IK
server's plan_path refuses a plan under a site-frame zone without a fresh site pose, and ends
one before the zone with it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Point, PoseStamped, TwistStamped, Vector3Stamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe, start_with_services
from sensor_msgs.msg import JointState
from test_zones_ros import TOLERANCE, uncovered

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.core.path_zones import plan_clear
from excavator_kinematics.grade.design_surface import SitePose
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.zones import Zone
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import PlanPath

pytestmark = [pytest.mark.ros, pytest.mark.slow]

EXC = Excavator.default()
POINTS = MonitoredPoints(EXC)
NAMES = (JOINTS[0], *CYLINDERS)
QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
NS = "/site_zones"
#: base_link in the site frame: 250 m east, 4 km north, 50 m up, heading 1 rad.
POSITION, YAW = (250.0, 4000.0, 50.0), 1.0
#: The ceiling (site frame, m) and its margin: 6.5 m above base_link less the margin.
HEIGHT, MARGIN = 56.5, 0.3
LIMIT = HEIGHT - POSITION[2] - MARGIN
MAX_AGE = 0.3


def start(exe: str, **settings: object) -> NodeProcess:
    params = {f"{NS}/{exe}": {"ros__parameters": settings}} if settings else None
    return NodeProcess(
        exe,
        "--params-file",
        str(config_path("excavator_cet200.yaml")),
        "--params-file",
        str(config_path("excavator_nodes.yaml")),
        *RELIABLE_INPUTS,
        "-r",
        f"__ns:={NS}",
        params=params,
    )


def site_pose(stamp: object) -> PoseStamped:
    pose = PoseStamped()
    pose.header.stamp, pose.header.frame_id = stamp, "site"
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = POSITION
    pose.pose.orientation.z, pose.pose.orientation.w = math.sin(YAW / 2), math.cos(YAW / 2)
    return pose


def zone_file(tmp_path) -> str:
    path = tmp_path / "site_zones.yaml"
    path.write_text(f"zones:\n  line: {{kind: ceiling, frame: site, height: {HEIGHT}, margin: {MARGIN}}}\n")
    return str(path)


def test_a_site_ceiling_stops_the_bucket_and_a_stale_site_pose_stops_the_machine(
    probe: Probe, tmp_path
) -> None:
    zones = zone_file(tmp_path)
    processes = [
        start("excavator_sim"),
        start(
            "excavator_velocity_ik",
            zones_file=zones,
            zones_period=0.05,
            zones_stop_time=0.3,
            site={"site_pose_source": "topic", "site_pose_max_age": MAX_AGE},
        ),
    ]
    try:
        n = probe.node
        states: dict[int, dict[str, float]] = {}
        statuses: list[str] = []
        clearance: list[DiagnosticStatus] = []

        def on_state(msg: JointState) -> None:
            entry = states.setdefault(message_codec.stamp_ns(msg.header.stamp), {})
            entry.update(zip(msg.name, msg.position, strict=False))

        def machine() -> np.ndarray:
            """Every complete simulated state so far, in stamp order (N, 4)."""
            return np.array([[s[k] for k in NAMES] for _, s in complete()])

        def complete() -> list[tuple[int, dict[str, float]]]:
            return [(t, s) for t, s in sorted(states.items()) if all(k in s for k in NAMES)]

        n.create_subscription(JointState, f"{NS}/cylinder_lengths", on_state, QOS)
        n.create_subscription(JointState, f"{NS}/joint_states", on_state, QOS)
        n.create_subscription(
            DiagnosticArray, f"{NS}/velocity_ik_status", lambda m: statuses.append(m.status[0].message), QOS
        )
        n.create_subscription(
            DiagnosticArray, f"{NS}/zone_clearance", lambda m: clearance.append(m.status[0]), QOS
        )
        target = n.create_publisher(TwistStamped, f"{NS}/target_bucket_twist", QOS)
        site = n.create_publisher(PoseStamped, f"{NS}/site_pose", QOS)
        drive = {"linear": np.array([0.0, 0.0, 0.6]), "site": True}

        def send() -> None:
            now = n.get_clock().now().to_msg()
            target.publish(message_codec.bucket_twist(now, "", drive["linear"], np.zeros(3)))
            if drive["site"]:
                site.publish(site_pose(now))

        n.create_timer(0.02, send)
        # Straight up: slowed and stopped by the ceiling, its margin not crossed.
        # The stop, and the states up to it (under load the states' first messages may come after
        # the first status).
        probe.wait_until(
            lambda: (
                any(s.startswith("stopped: ") and "at zone line" in s for s in statuses) and bool(complete())
            ),
            60.0,
            "the ceiling",
        )
        top = POINTS.positions(machine())[..., 2].max(axis=-1)
        probe.wait_until(lambda: len(machine()) > len(top) + 30, 10.0, "states at the stop")
        points = POINTS.positions(machine())
        top = points[..., 2].max(axis=-1)
        stamps = np.array([t for t, _ in complete()[: len(points)]]) * 1e-9
        allowed = TOLERANCE + uncovered(stamps, points)
        print(
            f"highest point {top.max():.4f} m, the ceiling's margin at {LIMIT:.4f} m (base_link), "
            f"{allowed * 1000:.3f} mm allowed past it"
        )
        assert top.max() <= LIMIT + allowed
        assert top.max() > LIMIT - 0.03  # it got there: stopped at the ceiling, not before it
        assert clearance[-1].level == DiagnosticStatus.WARN
        assert float(next(v.value for v in clearance[-1].values if v.key == "clearance")) < 0.03

        # The site pose stops coming: the machine, now told to go down, stops with the reason.
        # Only the statuses from here on: the first targets may have come before the first pose.
        drive["site"], drive["linear"] = False, np.array([0.0, 0.0, -0.3])
        since = len(statuses)
        probe.wait_until(
            lambda: any("site-frame zones cannot be checked" in s for s in statuses[since:]),
            10.0,
            "the stale stop",
        )
        stale = next(s for s in statuses[since:] if "site-frame zones cannot be checked" in s)
        assert stale.startswith("stopped: ") and "site_pose_max_age" in stale, stale
        probe.wait_until(
            lambda: clearance[-1].level == DiagnosticStatus.STALE, 5.0, "the clearance reported STALE"
        )
        assert clearance[-1].message == "no site pose"
        # Stopped: the actuators come to rest and stay there while the targets keep coming.
        count = len(machine())
        probe.wait_until(lambda: len(machine()) > count + 60, 10.0, "states while stale")
        held = machine()[-30:]
        np.testing.assert_allclose(held, np.broadcast_to(held[-1], held.shape), atol=1e-9)

        # The site pose comes back: the machine moves down again (the stop is not held).
        drive["site"] = True
        stopped_at = EXC.pose(held[-1])[2]
        probe.wait_until(lambda: EXC.pose(machine()[-1])[2] < stopped_at - 0.05, 20.0, "moving again")
        assert all(p.alive() for p in processes), [p.log() for p in processes]
    finally:
        logs = [p.stop() for p in processes]
    ik_log = logs[1]
    assert "site pose from" in ik_log and "at zone line" in ik_log, ik_log[-3000:]
    assert "site-frame zones cannot be checked" in ik_log, ik_log[-3000:]


def test_plan_path_needs_a_fresh_site_pose_for_a_site_zone(probe: Probe, tmp_path) -> None:
    ns = "/site_plan"
    process, (plan,) = start_with_services(
        probe,
        "excavator_ik_server",
        "--params-file",
        str(config_path("excavator_cet200.yaml")),
        "--params-file",
        str(config_path("excavator_nodes.yaml")),
        "-r",
        f"__ns:={ns}",
        "-p",
        f"zones_file:={zone_file(tmp_path)}",
        "-p",
        "site.site_pose_source:=topic",
        "-p",
        f"site.site_pose_max_age:={MAX_AGE}",
        services=((PlanPath, "plan_path"),),
        timeout=30.0,
        namespace=ns,
    )
    tip = EXC.pose(EXC.limits.reference)[:3]
    waypoints = [tip, tip + [0.5, 0.0, 0.0], tip + [0.5, 0.0, 5.0]]  # then straight up at the ceiling
    request = PlanPath.Request()
    request.waypoints = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in waypoints]
    site = probe.node.create_publisher(PoseStamped, f"{ns}/site_pose", QOS)
    try:
        refused = probe.call(plan, request, 30.0)
        assert not refused.success and refused.error_code.val == KinematicsErrorCodes.FAILURE
        assert "site-frame zone(s) line cannot be checked: no site pose received" in refused.message
        assert not refused.trajectory.points

        # With the pose on its topic the path ends before the ceiling, as the library's does.
        timer = probe.node.create_timer(
            0.05, lambda: site.publish(site_pose(probe.node.get_clock().now().to_msg()))
        )
        answers: list = []

        def planned() -> bool:
            answers.append(probe.call(plan, request, 30.0))
            return "enters zone line" in answers[-1].message

        probe.wait_until(planned, 30.0, "a plan with the site pose")
        ended = answers[-1]
        pose = SitePose.from_rpy(POSITION, [0.0, 0.0, YAW])
        ceiling = [Zone("line", "ceiling", "site", MARGIN, {"height": HEIGHT})]
        expected = plan_clear(
            EXC, POINTS, ceiling, waypoints, 0.05, 0.5, 0.5, site=(pose.rotation, pose.translation)
        )
        assert not ended.success and ended.error_code.val == KinematicsErrorCodes.NO_IK_SOLUTION
        assert ended.last_reachable_waypoint == expected.last_waypoint == 1
        assert len(ended.trajectory.points) == len(expected.timing.q)
        np.testing.assert_allclose(ended.trajectory.points[-1].positions, expected.timing.q[-1], atol=1e-6)

        # The pose stops coming: refused again once it is older than site_pose_max_age.
        probe.node.destroy_timer(timer)

        def stale() -> bool:
            answers.append(probe.call(plan, request, 30.0))
            return "site_pose_max_age" in answers[-1].message

        probe.wait_until(stale, 10.0, "a refusal with a stale site pose")
        assert not answers[-1].success and not answers[-1].trajectory.points
        assert process.alive()
    finally:
        probe.node.destroy_publisher(site)
        log = process.stop()
    assert "Traceback" not in log, log


def test_the_cab_tilt_places_a_site_ceiling(probe: Probe, tmp_path) -> None:
    """site.tilt: the standing machine's clearance under a site ceiling follows the measured
    pitch (closed form: a point x ahead at height z is x sin(beta) + z cos(beta) above base_link's
    origin), and is STALE while no tilt has come."""
    process = start(
        "excavator_velocity_ik",
        zones_file=zone_file(tmp_path),
        site={
            "site_pose_source": "fixed",
            "site_position": list(POSITION),
            "site_rpy": [0.0, 0.0, YAW],
            "tilt": True,
            "tilt_max_age": 0.1,
        },
    )
    sim = start("excavator_sim")
    try:
        n = probe.node
        clearance: list[DiagnosticStatus] = []
        n.create_subscription(
            DiagnosticArray, f"{NS}/zone_clearance", lambda m: clearance.append(m.status[0]), QOS
        )
        probe.wait_until(lambda: bool(clearance), 30.0, "zone_clearance")
        assert clearance[-1].level == DiagnosticStatus.STALE and clearance[-1].message == "no site pose"

        beta = math.radians(5.0)
        tilt = n.create_publisher(Vector3Stamped, f"{NS}/machine_tilt", QOS)

        def send() -> None:
            msg = Vector3Stamped()
            msg.header.stamp = n.get_clock().now().to_msg()
            msg.vector.x, msg.vector.z = math.sin(beta), math.cos(beta)  # nose up, swing 0
            tilt.publish(msg)

        n.create_timer(0.02, send)
        probe.wait_until(lambda: clearance[-1].level != DiagnosticStatus.STALE, 10.0, "a tilted clearance")
        value = float(next(v.value for v in clearance[-1].values if v.key == "clearance"))
        p = POINTS.positions(EXC.limits.reference)  # the sim's start: swing 0, reference lengths
        up = p[:, 0] * math.sin(beta) + p[:, 2] * math.cos(beta)
        expected = HEIGHT - POSITION[2] - MARGIN - up.max()
        level = HEIGHT - POSITION[2] - MARGIN - p[:, 2].max()
        print(f"clearance {value:.6f} m tilted (expected {expected:.6f} m), {level:.6f} m level")
        assert value == pytest.approx(expected, abs=1e-5)
        assert abs(expected - level) > 0.1  # the tilt matters here
        assert process.alive() and sim.alive()
    finally:
        log = process.stop()
        sim.stop()
    assert "roll and pitch from" in log, log[-2000:]
