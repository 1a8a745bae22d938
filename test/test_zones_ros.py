"""Avoidance zones across processes: excavator_sim -> excavator_velocity_ik (zones_file) ->
excavator_forward, driven by random target twists at 100 Hz for about a minute (simulated time
is wall time here) against a ceiling, a wall, a floor and a LandXML TIN (test/zone_scenario.py).
No monitored point of any simulated state, nor the tip of any forward pose, crosses a zone, and
the machine still gets to the zones: within a few cm of the ceiling, the wall and the TIN."""

from __future__ import annotations

import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe
from sensor_msgs.msg import JointState
from zone_loop import CURVE_TOLERANCE
from zone_scenario import PERIOD, STOP_TIME, ZONES, Targets, clearances

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics.param_files import config_path

pytestmark = [pytest.mark.ros, pytest.mark.slow]

EXC = Excavator.default()
QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
NS = "/zones"
#: Wall-clock seconds of driving (the sim runs in real time).
DRIVE = 60.0
#: Crossing allowed beyond :func:`uncovered`, m: round-off and the third-order term of the
#: check's path prediction (test/zone_loop.py).
TOLERANCE = CURVE_TOLERANCE
#: Straight at the ceiling, the wall and the TIN first, then random targets.
OPENING = (
    (8.0, np.array([0.0, 0.0, 0.6])),
    (6.0, np.array([0.6, 0.0, 0.0])),
    (8.0, np.array([0.0, 0.0, -0.6])),
)


def uncovered(stamps: np.ndarray, points: np.ndarray) -> float:
    """How far a monitored point went in time no zone check covered (m), from the simulated
    states (``stamps`` (N,) s, ``points`` (N, P, 3)): the check counts a command acting for
    PERIOD at the least, and the simulator holds the last command it received over each of its
    steps, so a step longer than PERIOD (the simulator stalled on a loaded machine) moved the
    points beyond it; what moves the machine then is no command the zones could slow but its
    actuators' watchdog's to stop (docs/zones.md). The largest distance a point covered beyond
    PERIOD in one step (its part of the step's straight move), 0 where no step is that long."""
    steps = np.diff(stamps)
    moved = np.linalg.norm(np.diff(points, axis=0), axis=-1).max(axis=-1)
    return float(np.max(moved * np.maximum(steps - PERIOD, 0.0) / steps, initial=0.0))


def smallest_reported(reported: list[DiagnosticArray]) -> dict[str, float]:
    """Each zone's smallest clearance over every zone_clearance message (the monitor topic)."""
    return {
        s.name: min(
            float(v.value)
            for m in reported
            for t in m.status
            if t.name == s.name
            for v in t.values
            if v.key == "clearance"
        )
        for s in reported[-1].status
    }


def start(
    exe: str,
    machine: str = "excavator_cet200.yaml",
    nodes: str = "excavator_nodes.yaml",
    ns: str = NS,
    **settings: object,
) -> NodeProcess:
    """Node ``exe`` of the machine file ``machine`` with its node defaults ``nodes`` and
    ``settings``, in namespace ``ns``, its inputs reliable."""
    params = {f"{ns}/{exe}": {"ros__parameters": settings}} if settings else None
    return NodeProcess(
        exe,
        "--params-file",
        str(config_path(machine)),
        "--params-file",
        str(config_path(nodes)),
        *RELIABLE_INPUTS,
        "-r",
        f"__ns:={ns}",
        params=params,
    )


def test_random_targets_never_cross_a_zone_and_the_machine_reaches_them(probe: Probe) -> None:
    processes = [
        start("excavator_sim"),
        start("excavator_forward"),
        start(
            "excavator_velocity_ik",
            zones_file=str(ZONES),
            zones_period=PERIOD,
            zones_stop_time=STOP_TIME,
            bucket_angle_gives_way=True,  # the tip goes on at a stroke end: the random walk moves on
        ),
    ]
    try:
        n = probe.node
        states: dict[int, dict[str, np.ndarray]] = {}
        poses: list[np.ndarray] = []
        reported: list[DiagnosticArray] = []

        def on_state(msg: JointState) -> None:
            entry = states.setdefault(message_codec.stamp_ns(msg.header.stamp), {})
            entry.update(zip(msg.name, msg.position, strict=False))

        n.create_subscription(JointState, f"{NS}/cylinder_lengths", on_state, QOS)
        n.create_subscription(JointState, f"{NS}/joint_states", on_state, QOS)
        n.create_subscription(
            PoseStamped, f"{NS}/bucket_pose", lambda m: poses.append(vec(m.pose.position)), QOS
        )
        n.create_subscription(DiagnosticArray, f"{NS}/zone_clearance", reported.append, QOS)
        target = n.create_publisher(TwistStamped, f"{NS}/target_bucket_twist", QOS)
        targets = Targets(34, EXC.pose(EXC.limits.reference)[:3], OPENING)
        began: list[float] = []

        def send() -> None:
            if poses:
                began[:] = began or [time.monotonic()]
                linear, angular = targets(time.monotonic() - began[0], poses[-1])
                target.publish(message_codec.bucket_twist(n.get_clock().now().to_msg(), "", linear, angular))

        n.create_timer(0.01, send)
        probe.wait_until(lambda: len(poses) > 5 and target.get_subscription_count() > 0, 30.0, "the nodes")
        probe.wait_until(lambda: bool(began) and time.monotonic() - began[0] > DRIVE, DRIVE + 30.0, "driving")
        assert all(p.alive() for p in processes), [p.log() for p in processes]
    finally:
        logs = [p.stop() for p in processes]
    names = (JOINTS[0], *CYLINDERS)
    both = [(t, s) for t, s in sorted(states.items()) if all(k in s for k in names)]
    D = np.array([[s[k] for k in names] for _, s in both])
    assert len(D) > 0.5 * 100 * DRIVE, f"{len(D)} states in {DRIVE} s"  # the sim publishes at 100 Hz
    points = MonitoredPoints(EXC).positions(D)
    clear = clearances(points)
    tips = clearances(np.array(poses)[:, None, :])  # the forward node's poses, independently
    allowed = TOLERANCE + uncovered(np.array([t for t, _ in both]) * 1e-9, points)
    print(f"crossing allowed: {allowed * 1000:.3f} mm (time no check covered)")
    for zone, c in clear.items():
        assert c.min() >= -allowed, f"{zone}: crossed by {-c.min():.4f} m, {allowed:.4f} m allowed"
        assert tips[zone].min() >= -allowed, f"{zone}: the tip crossed by {-tips[zone].min():.4f} m"
    for zone in ("power_line", "road_edge", "gas_main"):
        assert clear[zone].min() < 0.03, f"{zone}: never within 3 cm ({clear[zone].min():.3f} m)"
    tip = points[:, MonitoredPoints(EXC).names.index("bucket_tip")]
    print(
        f"{len(D)} states: smallest clearances "
        + ", ".join(f"{zone} {c.min() * 1000:.2f} mm" for zone, c in clear.items())
        + f"; tip z range {np.ptp(tip[:, 2]):.2f} m, x range {np.ptp(tip[:, 0]):.2f} m"
    )
    assert np.ptp(tip[:, 2]) > 3.0 and np.ptp(tip[:, 0]) > 1.0  # it moved about, not just stopped
    # The monitor topic says the same: every zone's smallest clearance, never below the tolerance.
    smallest = smallest_reported(reported)
    assert set(smallest) == set(clear) and min(smallest.values()) >= -allowed, smallest
    ik_log = logs[2]
    assert "approaching zone" in ik_log or "at zone" in ik_log, ik_log[-2000:]


def vec(v: object) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def test_the_markers_draw_the_zones_and_the_monitored_points(probe: Probe) -> None:
    """machine_markers with zones_file: every zone of the file (boundary and margin), and the 23
    monitored points at the state drawn, coloured by clearance (the reference state: all clear)."""
    from visualization_msgs.msg import MarkerArray

    received: list[MarkerArray] = []
    sub = probe.node.create_subscription(MarkerArray, "/zm/machine_markers", received.append, QOS)
    pubs = [
        probe.node.create_publisher(JointState, f"/zm/{t}", QOS) for t in ("joint_states", "cylinder_lengths")
    ]
    D = EXC.limits.reference
    when = probe.node.get_clock().now().to_msg()
    states = [
        message_codec.joint_state(when, (JOINTS[0],), positions=D[:1]),
        message_codec.joint_state(when, CYLINDERS, positions=D[1:]),
    ]
    process = NodeProcess(
        "machine_markers",
        "--params-file",
        str(config_path("excavator_cet200.yaml")),
        *RELIABLE_INPUTS,
        "-r",
        "__ns:=/zm",
        "-p",
        f"zones_file:={ZONES}",
    )

    def arrived() -> bool:
        assert process.alive(), process.log()
        for pub, msg in zip(pubs, states, strict=True):
            if pub.get_subscription_count():
                pub.publish(msg)
        return bool(received)

    try:
        probe.wait_until(arrived, 30.0, "machine_markers")
    finally:
        log = process.stop()
        for pub in pubs:
            probe.node.destroy_publisher(pub)
        probe.node.destroy_subscription(sub)
    assert "Traceback" not in log, log
    markers = received[-1].markers
    by_ns: dict[str, list] = {}
    for m in markers:
        by_ns.setdefault(m.ns, []).append(m)
    assert len(by_ns["zone"]) == len(by_ns["zone_margin"]) == 4  # every zone of the file has a margin
    (points,) = by_ns["monitored_point"]
    names = MonitoredPoints(EXC).names
    expected = MonitoredPoints(EXC).positions(D)
    np.testing.assert_allclose([[p.x, p.y, p.z] for p in points.points], expected, atol=1e-9)
    assert len(points.colors) == len(names) and all(c.g > 0.5 for c in points.colors)  # all clear
    ceiling = next(m for m in by_ns["zone"] if m.type == m.CUBE and m.scale.z < 0.1 and m.pose.position.z > 0)
    assert ceiling.pose.position.z == pytest.approx(7.0)
    tin = [m for m in by_ns["zone"] if m.type == m.TRIANGLE_LIST]
    assert len(tin) == 1 and len(tin[0].points) == 3 * 32  # the 32 triangles of service.xml
