"""The IMU state node over DDS (ros tier): cylinder lengths from simulated sensors, refusals, stale
sensors, bad stamps, and the whole chain on IMUs across processes; the IMU math is checked in
test_excavator_imu.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_excavator_imu import EXC, LIM, readings

from excavator_kinematics.sensing.imu import SENSORS

pytestmark = pytest.mark.ros


def imu_message(stamp_ns: int, q, omega, f, with_orientation: bool):
    from builtin_interfaces.msg import Time
    from sensor_msgs.msg import Imu

    msg = Imu()
    msg.header.stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    msg.header.frame_id = "imu"
    if with_orientation:
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = (float(v) for v in q)
    else:
        msg.orientation_covariance[0] = -1.0
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = (float(v) for v in omega)
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = (float(v) for v in f)
    return msg


def imu_node(namespace: str, settings: dict):
    """excavator_imu_state on the shipped machine and node files in ``namespace`` with
    ``settings`` over them, a probe, the cylinder_lengths it hears, and a publisher per sensor."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from ros_harness import NodeProcess, Probe
    from sensor_msgs.msg import Imu, JointState

    from manipulator_kinematics.param_files import config_path

    files = [config_path("excavator_cet200.yaml"), config_path("excavator_nodes.yaml")]
    process = NodeProcess(
        "excavator_imu_state",
        *[a for p in files for a in ("--params-file", str(p))],
        "-r",
        f"__ns:=/{namespace}",
        params={f"/{namespace}/excavator_imu_state": {"ros__parameters": settings}},
    )
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    probe = Probe(f"{namespace}_probe")
    got: list[JointState] = []
    probe.node.create_subscription(JointState, f"/{namespace}/cylinder_lengths", got.append, qos)
    pubs = [probe.node.create_publisher(Imu, f"/{namespace}/imu/{name}", qos) for name in SENSORS]
    return process, probe, got, pubs


def stamp_of(msg) -> int:
    """A message's header stamp in ns."""
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_imu_state_node_publishes_cylinder_lengths_and_refuses_bad_sensors():
    """excavator_imu_state across processes on the machine file's mounting (all zero, H-link):
    orientation sets and gravity-only sets give back the lengths and rates; a stale boom sensor
    and an implausible arm reading stop the output with a logged reason."""

    from excavator_kinematics.core.kinematics import CYLINDERS

    D = LIM.reference + np.array([0.5, 0.12, -0.3, 0.2])
    D_dot = np.array([0.3, 0.05, -0.08, 0.1])
    q, omega, f = readings(D, D_dot, "h_link", mountings={key: [0.0, 0.0, 0.0] for key in SENSORS})
    process, probe, got, pubs = imu_node("imu_t", {"gravity_time_constant": 0.0})
    node = probe.node

    def send(stamp_ns: int, with_orientation: bool, skip: str = "", arm_rate: float | None = None) -> None:
        for i, (name, pub) in enumerate(zip(SENSORS, pubs, strict=True)):
            if name == skip:
                continue
            w = omega[i] if arm_rate is None or name != "arm" else [0.0, arm_rate, 0.0]
            pub.publish(imu_message(stamp_ns, q[i], w, f[i], with_orientation))

    try:
        probe.wait_until(
            lambda: (
                all(p.get_subscription_count() for p in pubs)
                and node.count_publishers("/imu_t/cylinder_lengths")
            ),
            30.0,
            "excavator_imu_state",
        )
        for k in range(1, 40):
            send(k * 10_000_000, with_orientation=k % 2 == 0)
            try:
                probe.wait_until(lambda: len(got) >= 2, 0.5, "two cylinder states")
                break
            except TimeoutError:
                continue
        assert len(got) >= 2, process.log()[-3000:]
        count = len(got)
        # The boom sensor falls silent: the others go on, nothing is published, the reason is logged.
        for k in range(50, 60):
            send(k * 10_000_000, with_orientation=True, skip="boom")
        # An implausible gyro on the arm.
        send(70 * 10_000_000, with_orientation=True, arm_rate=1e6)
        probe.wait_until(lambda: "rejected imu arm" in process.log(), 10.0, "the rejection")
        probe.wait_until(lambda: "imu boom is" in process.log(), 10.0, "the stale sensor")
        assert len(got) == count
    finally:
        log = process.stop()
        probe.close()
    assert "Traceback" not in log, log
    for message in got:
        assert tuple(message.name) == CYLINDERS
        np.testing.assert_allclose(message.position, D[1:], rtol=0, atol=1e-9)
        np.testing.assert_allclose(message.velocity, D_dot[1:], rtol=0, atol=1e-7)


def test_imu_state_node_says_which_sensors_fell_silent():
    """Gap a: the max_age timer. Before any message: "since start-up"; the boom falling silent
    while the others go on, then all four: a reason naming them, and no set stamped after the
    last complete one; all four back: output again."""
    import re

    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.time import Time
    from ros_harness import NodeProcess, Probe
    from sensor_msgs.msg import Imu, JointState

    from manipulator_kinematics.param_files import config_path

    D = LIM.reference + np.array([0.5, 0.12, -0.3, 0.2])
    q, omega, f = readings(D, np.zeros(4), "h_link", mountings={key: [0.0, 0.0, 0.0] for key in SENSORS})
    files = [config_path("excavator_cet200.yaml"), config_path("excavator_nodes.yaml")]
    process = NodeProcess(
        "excavator_imu_state",
        *[a for p in files for a in ("--params-file", str(p))],
        "-r",
        "__ns:=/imu_stale",
        params={
            "/imu_stale/excavator_imu_state": {"ros__parameters": {"max_age": 0.3, "warning_period": 0.2}}
        },
    )
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    probe = Probe("imu_stale_probe")
    node = probe.node
    got: list[JointState] = []
    node.create_subscription(JointState, "/imu_stale/cylinder_lengths", got.append, qos)
    pubs = dict(
        zip(SENSORS, (node.create_publisher(Imu, f"/imu_stale/imu/{n}", qos) for n in SENSORS), strict=True)
    )
    clock = {"k": 0}

    def send(names) -> bool:
        """One message from each of ``names`` with the next stamp (10 ms apart); False, for wait_until."""
        clock["k"] += 1
        for i, name in enumerate(SENSORS):
            if name in names:
                pubs[name].publish(imu_message(clock["k"] * 10_000_000, q[i], omega[i], f[i], True))
        return False

    def stamp_ns(msg: JointState) -> int:
        return Time.from_msg(msg.header.stamp).nanoseconds

    def stale_lines(pattern: str) -> int:
        return len(re.findall(pattern, process.log()))

    def keep_sending(names, pattern: str, lines: int, timeout: float = 15.0) -> None:
        """Send ``names`` every spin until ``pattern`` is logged ``lines`` more times."""
        before = stale_lines(pattern)
        probe.wait_until(lambda: send(names) or stale_lines(pattern) >= before + lines, timeout, pattern)

    try:
        probe.wait_until(lambda: "no message since start-up" in process.log(), 15.0, "the start-up reason")
        probe.wait_until(
            lambda: all(p.get_subscription_count() for p in pubs.values()), 30.0, "subscriptions"
        )
        probe.wait_until(lambda: send(SENSORS) or len(got) >= 3, 15.0, "cylinder states")
        last_full = clock["k"] * 10_000_000
        # The boom falls silent, the others go on: the boom is named (twice: time passes), no output.
        keep_sending(("cab", "arm", "bucket_linkage"), r"imu boom \(no message for [\d.]+ s\) stale", 2)
        assert all(stamp_ns(m) <= last_full for m in got), [stamp_ns(m) for m in got][-5:]
        # All four back: output resumes (the stale boom recovered with its next message).
        count = len(got)
        probe.wait_until(lambda: send(SENSORS) or len(got) > count + 2, 15.0, "output after recovery")
        last_full = clock["k"] * 10_000_000
        # All four fall silent: one reason names all of them.
        all_four = (
            r"imu cab \(no message for [\d.]+ s\), boom \(.*\), arm \(.*\), "
            r"bucket_linkage \(.*\) stale"
        )
        keep_sending((), all_four, 2)
        assert all(stamp_ns(m) <= last_full for m in got)
        assert process.alive()
    finally:
        log = process.stop()
        probe.close()
    assert "Traceback" not in log, log
    assert "max_age 0.3 s" in log


def test_whole_chain_on_imus_across_processes():
    """excavator_imu_state -> excavator_forward over DDS on a machine standing on a 5 % slope
    (pitch 2.86 deg) and a 2 % cross slope: bucket_pose equals the core's pose of D (the chain runs
    on IMUs unchanged) and bucket_pose_level's z the tip's height along gravity."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from ros_harness import NodeProcess, Probe
    from sensor_msgs.msg import Imu, JointState

    from excavator_kinematics.core.kinematics import JOINTS
    from manipulator_kinematics.param_files import config_path

    tilt = (math.atan(0.02), -math.atan(0.05), 0.0)
    D = LIM.reference + np.array([0.3, 0.1, -0.2, 0.1])
    D_dot = np.zeros(4)
    q, omega, f = readings(D, D_dot, "h_link", tilt, mountings={key: [0.0, 0.0, 0.0] for key in SENSORS})
    files = [config_path("excavator_cet200.yaml"), config_path("excavator_nodes.yaml")]
    args = [a for p in files for a in ("--params-file", str(p))]
    imu_node = NodeProcess("excavator_imu_state", *args, "-r", "__ns:=/chain")
    forward = NodeProcess(
        "excavator_forward",
        *args,
        "-r",
        "__ns:=/chain",
        params={"/chain/excavator_forward": {"ros__parameters": {"level": {"enabled": True}}}},
    )
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    probe = Probe("chain_probe")
    node = probe.node
    got: dict[str, list] = {"pose": [], "level": []}
    node.create_subscription(PoseStamped, "/chain/bucket_pose", got["pose"].append, qos)
    node.create_subscription(PoseStamped, "/chain/bucket_pose_level", got["level"].append, qos)
    pubs = [node.create_publisher(Imu, f"/chain/imu/{name}", qos) for name in SENSORS]
    swing_pub = node.create_publisher(JointState, "/chain/joint_states", qos)
    try:
        probe.wait_until(
            lambda: (
                all(p.get_subscription_count() for p in pubs)
                and swing_pub.get_subscription_count()
                and node.count_publishers("/chain/bucket_pose_level")
            ),
            30.0,
            "both nodes",
        )

        def send(stamp: int) -> bool:
            swing = JointState(name=[JOINTS[0]], position=[D[0]], velocity=[0.0])
            swing.header.stamp.sec, swing.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            swing_pub.publish(swing)
            for i, pub in enumerate(pubs):
                pub.publish(imu_message(stamp, q[i], omega[i], f[i], with_orientation=True))
            return False

        # Until the three processes have found each other: send sets 10 ms apart.
        sent = iter(range(10_000_000, 10_000_000_000, 10_000_000))
        probe.wait_until(lambda: send(next(sent)) or got["pose"], 30.0, "the first pose")
        probe.wait_until(lambda: got["level"], 5.0, "the first level pose")
        # Then ten sets at 5 Hz (stamps 0.2 s apart, beyond tilt_max_age 0.1 s): each set's tilt and
        # lengths carry one stamp, so each set gets its level pose, whichever topic arrives first.
        start = 10 * 1_000_000_000
        sets = [start + k * 200_000_000 for k in range(10)]
        for stamp in sets:
            send(stamp)
            probe.wait_until(
                lambda stamp=stamp: any(stamp_of(m) == stamp for m in got["level"]),
                5.0,
                f"the level pose of the set at {stamp} ns",
            )
        assert [stamp_of(m) for m in got["level"] if stamp_of(m) >= start] == sets
    finally:
        logs = imu_node.stop() + forward.stop()
        probe.close()
    assert "Traceback" not in logs, logs
    tip = EXC.pose(D)[:3]
    p = got["pose"][-1].pose.position
    np.testing.assert_allclose([p.x, p.y, p.z], tip, rtol=0, atol=1e-9)
    height = Rotation.from_euler("xyz", tilt).apply(tip)[2]
    for level in got["level"]:
        assert level.header.frame_id == "base_level"
        assert level.pose.position.z == pytest.approx(height, abs=1e-9)
    assert abs(height - tip[2]) > 0.2  # the slope matters at this reach


def test_imu_state_node_refuses_bad_stamps_and_answers_the_sets_after_them():
    """Issue 29 defect 1: a set stamped an hour ahead held back every later set for good, and a
    negative stamp raised in the callback. Now a stamp ahead of the node clock by more than max_age,
    a negative one and one behind the sensor's previous message are each refused with a reason,
    and every valid set after them is answered; a clock that went back (a bag played again) starts
    the sets over."""
    import time

    D = LIM.reference + np.array([0.5, 0.12, -0.3, 0.2])
    q, omega, f = readings(D, np.zeros(4), "h_link", mountings={key: [0.0, 0.0, 0.0] for key in SENSORS})
    process, probe, got, pubs = imu_node("imu_stamps", {"warning_period": 0.1})

    sent = []

    def send(stamp_ns: int, sec: int | None = None) -> bool:
        sent.append(stamp_ns)
        for i, pub in enumerate(pubs):
            msg = imu_message(stamp_ns, q[i], omega[i], f[i], True)
            if sec is not None:
                msg.header.stamp.sec = sec
            pub.publish(msg)
        return False

    def answered(stamp_ns: int) -> bool:
        return any(stamp_of(m) == stamp_ns for m in got)

    def window_passed() -> None:
        """On a fast machine the refusals come as ten kinds of line within one warning_period:
        the log's cap (ten kinds per period, the rest held back and counted) would hold the
        next one back. The sensors' stale line, max_age after the last message, is logged
        after the window has passed."""
        seen = len(process.log())
        probe.wait_until(lambda: "stale, max_age" in process.log()[seen:], 10.0, "the stale line")

    try:
        probe.wait_until(lambda: all(p.get_subscription_count() for p in pubs), 30.0, "subscriptions")
        probe.wait_until(lambda: send(time.time_ns()) or got, 30.0, "a first set")
        last = sent[-1]
        # The last warm-up set is the reference the out-of-order case must be behind.
        probe.wait_until(lambda: answered(last), 10.0, "the answer to the last warm-up set")
        cases = (
            (time.time_ns() + 3600 * 1_000_000_000, None, "s ahead of the node clock"),
            (0, -1, "negative stamp (sec -1)"),
            (last - 50_000_000, None, "s behind (or equal to)"),
        )  # the previous message is newer
        for stamp, sec, pattern in cases:
            send(stamp, sec)
            try:
                probe.wait_until(lambda pattern=pattern: pattern in process.log(), 10.0, pattern)
            except TimeoutError:
                raise AssertionError(f"no {pattern!r} in {process.log()}") from None
        count = len(got)
        sets = []
        for _ in range(10):
            sets.append(time.time_ns())
            send(sets[-1])
            probe.wait_until(lambda: answered(sets[-1]), 10.0, f"the answer to set {len(sets)}")
        assert len(got) == count + 10
        window_passed()
        # Gyros saying the arm turns at 5 rad/s (under max_angular_rate): a cylinder rate the
        # machine cannot have, refused with the reason (issue 29 defect 2).
        fast = time.time_ns()
        for i, pub in enumerate(pubs):
            w = [0.0, 5.0, 0.0] if SENSORS[i] == "arm" else omega[i]
            pub.publish(imu_message(fast, q[i], w, f[i], True))
        probe.wait_until(
            lambda: "not a motion this machine can make" in process.log(), 10.0, "the rate refusal"
        )
        assert not answered(fast)
        # The clock goes back 60 s: the sets start over from there.
        window_passed()
        back = sets[-1] - 60 * 1_000_000_000
        send(back)
        probe.wait_until(lambda: answered(back), 10.0, "the set after the clock went back")
        # The answer can reach the probe before the node's log line reaches its file.
        probe.wait_until(lambda: "the clock went back" in process.log(), 10.0, "the clock-back line")
        assert process.alive()
    finally:
        log = process.stop()
        probe.close()
    assert "Traceback" not in log and "failed on" not in log, log
