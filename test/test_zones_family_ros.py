"""The hydraulic family's avoidance zones across processes: hydraulic_sim -> hydraulic_velocity_ik
(zones_file) -> hydraulic_forward, for the wheel loader and the knuckle crane, driven by random
target twists at 100 Hz (simulated time is wall time) against a ceiling, a wall, a floor and a
LandXML TIN (test/family_zone_scenario.py). No monitored point of any simulated state, nor the
tool point of any forward pose, crosses a zone by more than the excavator's test allows
(test_zones_ros.py), and the machine still gets to the zones; a bad zone file is refused at start
in one line naming the key."""

from __future__ import annotations

import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from family_zone_scenario import SCENARIOS
from geometry_msgs.msg import PoseStamped, TwistStamped
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe
from sensor_msgs.msg import JointState
from test_zones_ros import QOS, TOLERANCE, smallest_reported, start, uncovered, vec
from zone_scenario import PERIOD, STOP_TIME

from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.param_files import config_path

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: Wall-clock seconds of driving each machine (the sim runs in real time).
DRIVE = 60.0


def family(exe: str, name: str, **settings: object) -> NodeProcess:
    return start(exe, SCENARIOS[name].config, "hydraulic_nodes.yaml", f"/fz_{name}", **settings)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_random_targets_never_cross_a_zone_and_the_machine_reaches_them(probe: Probe, name: str) -> None:
    scenario = SCENARIOS[name]
    h = HydraulicModel.from_file(config_path(scenario.config))
    ns = f"/fz_{name}"
    processes = [
        family("hydraulic_sim", name),
        family("hydraulic_forward", name),
        family(
            "hydraulic_velocity_ik",
            name,
            zones_file=str(scenario.zones),
            zones_period=PERIOD,
            zones_stop_time=STOP_TIME,
        ),
    ]
    n = probe.node
    subscriptions = []
    try:
        states: dict[int, np.ndarray] = {}
        poses: list[np.ndarray] = []
        reported: list[DiagnosticArray] = []

        def on_state(msg: JointState) -> None:
            order = [list(msg.name).index(a) for a in h.actuator_names]
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            states[stamp] = np.array(msg.position)[order]

        subscriptions += [
            n.create_subscription(JointState, f"{ns}/joint_states", on_state, QOS),
            n.create_subscription(
                PoseStamped, f"{ns}/tool_pose", lambda m: poses.append(vec(m.pose.position)), QOS
            ),
            n.create_subscription(DiagnosticArray, f"{ns}/zone_clearance", reported.append, QOS),
        ]
        target = n.create_publisher(TwistStamped, f"{ns}/target_twist", QOS)
        targets = scenario.targets(34, h.pose(h.reference)[:3])
        began: list[float] = []

        def send() -> None:
            if poses:
                began[:] = began or [time.monotonic()]
                linear, angular = targets(time.monotonic() - began[0], poses[-1])
                msg = TwistStamped()
                msg.header.stamp = n.get_clock().now().to_msg()
                t = msg.twist
                t.linear.x, t.linear.y, t.linear.z = linear.tolist()
                t.angular.x, t.angular.y, t.angular.z = angular.tolist()
                target.publish(msg)

        timer = n.create_timer(0.01, send)
        probe.wait_until(lambda: len(poses) > 5 and target.get_subscription_count() > 0, 30.0, "the nodes")
        probe.wait_until(lambda: bool(began) and time.monotonic() - began[0] > DRIVE, DRIVE + 30.0, "driving")
        assert all(p.alive() for p in processes), [p.log() for p in processes]
    finally:
        logs = [p.stop() for p in processes]
        for s in subscriptions:
            n.destroy_subscription(s)
        if "timer" in locals():
            n.destroy_timer(timer)
    D = h.zero_offset + np.array([states[k] for k in sorted(states)])  # true states of the readings
    assert len(D) > 0.5 * 100 * DRIVE, f"{len(D)} states in {DRIVE} s"  # the sim publishes at 100 Hz
    points = h.monitored(D, np.zeros_like(D))[1]
    clear = scenario.clearances(points)
    tips = scenario.clearances(np.array(poses)[:, None, :])  # the forward node's poses, independently
    allowed = TOLERANCE + uncovered(np.array(sorted(states)) * 1e-9, points)
    print(f"{name}: crossing allowed {allowed * 1000:.3f} mm (time no check covered)")
    for zone, c in clear.items():
        assert c.min() >= -allowed, f"{zone}: crossed by {-c.min():.4f} m, {allowed:.4f} m allowed"
        assert tips[zone].min() >= -allowed, f"{zone}: the tool crossed by {-tips[zone].min():.4f} m"
    print(
        f"{name}: {len(D)} states: smallest clearances "
        + ", ".join(f"{zone} {c.min() * 1000:.2f} mm" for zone, c in clear.items())
        + f"; actuator spans {(np.ptp(D, axis=0) / (h.upper - h.lower)).round(2).tolist()} of their strokes"
    )
    for zone in scenario.reached:
        assert clear[zone].min() < 0.03, f"{zone}: never within 3 cm ({clear[zone].min():.3f} m)"
    cylinders = slice(1 if h.swing else 0, None)  # it moved about, not just stopped
    assert np.all(np.ptp(D, axis=0)[cylinders] > 0.3 * (h.upper - h.lower)[cylinders])
    # The monitor topic says the same: every zone's smallest clearance, never below the tolerance.
    smallest = smallest_reported(reported)
    assert set(smallest) == set(clear) and min(smallest.values()) >= -allowed, smallest
    assert "approaching zone" in logs[2] or "at zone" in logs[2], logs[2][-2000:]


def test_a_bad_zone_file_is_refused_at_start_naming_the_key(tmp_path) -> None:
    path = tmp_path / "zones.yaml"
    path.write_text("zones:\n  roof: {kind: ceiling, height: .nan}\n")
    process = family("hydraulic_velocity_ik", "wheel_loader", zones_file=str(path))
    code = process.process.wait(30.0)
    log = process.stop()
    assert code == 2, log
    assert f"configuration error: zones_file: {path}: zones.roof.height: expected a finite number" in log, log


def test_the_markers_draw_the_zones_and_the_crane_s_monitored_points(probe: Probe) -> None:
    """machine_markers with zones_file for a family machine (the registry's monitored and
    read_surface hooks): every zone, and the KC100's 13 points at the state drawn."""
    from visualization_msgs.msg import MarkerArray

    from manipulator_kinematics.registry import machine

    scenario = SCENARIOS["knuckle_crane"]
    record = machine("knuckle_crane")
    arm = record.model()
    reading = arm.hydraulic.reference - arm.hydraulic.zero_offset
    received: list[MarkerArray] = []
    sub = probe.node.create_subscription(MarkerArray, "/fzm/machine_markers", received.append, QOS)
    pub = probe.node.create_publisher(JointState, "/fzm/joint_states", QOS)
    state = JointState(name=list(arm.joint_names), position=reading.tolist())
    state.header.stamp = probe.node.get_clock().now().to_msg()
    process = NodeProcess(
        "machine_markers",
        "--params-file",
        str(config_path(scenario.config)),
        *RELIABLE_INPUTS,
        "-r",
        "__ns:=/fzm",
        "-p",
        f"zones_file:={scenario.zones}",
    )

    def arrived() -> bool:
        assert process.alive(), process.log()
        if pub.get_subscription_count():
            pub.publish(state)
        return bool(received)

    try:
        probe.wait_until(arrived, 30.0, "machine_markers")
    finally:
        log = process.stop()
        probe.node.destroy_publisher(pub)
        probe.node.destroy_subscription(sub)
    assert "Traceback" not in log, log
    by_ns: dict[str, list] = {}
    for m in received[-1].markers:
        by_ns.setdefault(m.ns, []).append(m)
    assert len(by_ns["zone"]) == len(by_ns["zone_margin"]) == 4
    (points,) = by_ns["monitored_point"]
    _, expected, _ = arm.hydraulic.monitored(arm.hydraulic.reference, np.zeros(arm.hydraulic.m))
    np.testing.assert_allclose([[p.x, p.y, p.z] for p in points.points], expected, atol=1e-9)
    assert len(expected) == 13 and all(c.g > 0.5 for c in points.colors)  # all clear at the reference
