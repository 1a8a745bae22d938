"""excavator_forward, excavator_velocity_ik and excavator_sim as real processes over DDS.

Each group of tests starts its processes once (module-scoped fixtures, each in its own namespace)
and talks to them from an in-test node; every wait is on a condition with a timeout. Expected
numbers come from the numpy core, from closed forms the test knows (constant accelerations,
damped least squares in normal-equations form) and from geometry (distance to a line).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from excavator_kinematics.core.kinematics import (
    CYLINDERS,
    JOINTS,
    Excavator,
    bucket_angular_acceleration,
    bucket_angular_velocity,
    bucket_quaternion,
)
from excavator_kinematics.core.twist import bucket_angles, twist_from_q_dot
from excavator_kinematics.demo.bucket_path import follow
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics.param_files import config_path

pytestmark = pytest.mark.ros

EXC = Excavator.default()
LIMITS = EXC.limits
QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
PARAMS = (
    "--params-file",
    str(config_path("excavator_cet200.yaml")),
    "--params-file",
    str(config_path("excavator_nodes.yaml")),
)
COMMAND_NAMES = (JOINTS[0], *CYLINDERS)


def start(exe: str, namespace: str, **overrides: object) -> NodeProcess:
    """Console script ``exe`` (node of the same name) in ``namespace`` with the package's config,
    reliable inputs (the tests check an output per input), plus ``overrides`` in one more params
    file for this node (a later file wins)."""
    params = {f"{namespace}/{exe}": {"ros__parameters": overrides}} if overrides else None
    return NodeProcess(exe, *PARAMS, *RELIABLE_INPUTS, "-r", f"__ns:={namespace}", params=params)


class Collector:
    """Every message of a topic, in arrival order."""

    def __init__(self, probe: Probe, msg_type: type, topic: str) -> None:
        self.messages: list = []
        self.topic = topic
        probe.node.create_subscription(msg_type, topic, self.messages.append, QOS)

    def stamped(self, stamp_ns: int) -> list:
        return [m for m in self.messages if message_codec.stamp_ns(m.header.stamp) == stamp_ns]


def wait_connected(probe: Probe, publishers: list, collectors: list[Collector]) -> None:
    probe.wait_until(
        lambda: (
            all(p.get_subscription_count() > 0 for p in publishers)
            and all(probe.node.count_publishers(c.topic) > 0 for c in collectors)
        ),
        20.0,
        "discovery of the nodes under test",
    )


def wait_for_log(probe: Probe, process: NodeProcess, text: str, timeout: float = 5.0) -> None:
    probe.wait_until(lambda: text in process.log(), timeout, f"log line {text!r}")


def stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def state_messages(when: Time, D: np.ndarray, D_dot: np.ndarray) -> tuple[JointState, JointState]:
    """(cylinder_lengths, joint_states) of state D with rates D_dot."""
    return (
        message_codec.joint_state(when, CYLINDERS, D[1:], D_dot[1:]),
        message_codec.joint_state(when, JOINTS[:1], D[:1], D_dot[:1]),
    )


def finite(msg: object) -> bool:
    """No NaN/inf anywhere in a pose/twist/accel/joint-state message."""
    if isinstance(msg, JointState):
        values = [*msg.position, *msg.velocity, *msg.effort]
    elif isinstance(msg, PoseStamped):
        p, o = msg.pose.position, msg.pose.orientation
        values = [p.x, p.y, p.z, o.x, o.y, o.z, o.w]
    else:
        body = msg.twist if isinstance(msg, TwistStamped) else msg.accel
        values = [body.linear.x, body.linear.y, body.linear.z, body.angular.x, body.angular.y, body.angular.z]
    return bool(np.all(np.isfinite(values)))


def vec(v: object) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


@pytest.fixture(scope="class")
def probe() -> Iterator[Probe]:
    p = Probe("excavator_nodes_test")
    yield p
    p.close()


# ---------------------------------------------------------------------------------------- forward
class Forward:
    def __init__(self, probe: Probe, process: NodeProcess) -> None:
        self.probe, self.process = probe, process
        n = probe.node
        self.cylinders = n.create_publisher(JointState, "/fwd/cylinder_lengths", QOS)
        self.swing = n.create_publisher(JointState, "/fwd/joint_states", QOS)
        self.pose = Collector(probe, PoseStamped, "/fwd/bucket_pose")
        self.twist = Collector(probe, TwistStamped, "/fwd/bucket_twist")
        self.accel = Collector(probe, AccelStamped, "/fwd/bucket_accel")
        self.joints = Collector(probe, JointState, "/fwd/open_chain_joint_states")
        wait_connected(probe, [self.cylinders, self.swing], [self.pose, self.twist, self.accel, self.joints])

    def outputs(self) -> list[Collector]:
        return [self.pose, self.twist, self.accel, self.joints]

    def prime(self, stamp_ns: int, D: np.ndarray, D_dot: np.ndarray) -> None:
        """Publish swing and cylinders at ``stamp_ns`` until the pose for it comes out, so the node
        holds this swing state (the two topics are not ordered with respect to each other; a
        repeated stamp only restarts the acceleration differencing)."""
        cylinders, swing = state_messages(stamp(stamp_ns), D, D_dot)
        deadline = time.monotonic() + 10.0
        while not self.pose.stamped(stamp_ns):
            self.swing.publish(swing)
            self.cylinders.publish(cylinders)
            try:
                self.probe.wait_until(lambda: bool(self.pose.stamped(stamp_ns)), 0.3, "pose")
            except TimeoutError:
                if time.monotonic() > deadline:
                    raise


@pytest.fixture(scope="class")
def forward(probe: Probe) -> Iterator[Forward]:
    process = start("excavator_forward", "/fwd")
    try:
        yield Forward(probe, process)
    finally:
        print(process.stop())  # shown with a failing test


class TestForwardNode:
    """excavator_forward against the core."""

    def test_forward_outputs_equal_the_core_for_published_inputs(self, forward: Forward) -> None:
        """Cylinders at constant accelerations a and a constant swing rate: finite differences of the
        rates are exactly a, so every output is the core's state(D, D_dot, [0, a]) at the input stamp."""
        t0 = 1_000 * 1_000_000_000
        D0 = np.array([0.3, 2.6, 3.1, 2.1])
        v0 = np.array([0.2, 0.05, -0.08, 0.1])
        a = np.array([0.0, 0.3, -0.2, 0.5])
        dt = 0.01

        def state(k: int) -> tuple[np.ndarray, np.ndarray]:
            t = k * dt
            return D0 + v0 * t + 0.5 * a * t * t, v0 + a * t

        forward.prime(t0 - 10_000_000, *state(-1))
        expected = {}
        for k in range(6):
            D, D_dot = state(k)
            when = stamp(t0 + k * 10_000_000)
            cylinders, swing = state_messages(when, D, D_dot)
            forward.swing.publish(swing)
            forward.cylinders.publish(cylinders)
            expected[message_codec.stamp_ns(when)] = (D, D_dot, EXC.state(D, D_dot, a))
        forward.probe.wait_until(
            lambda: (
                all(forward.pose.stamped(s) and forward.joints.stamped(s) for s in expected)
                and all(forward.accel.stamped(s) for s in expected)
            ),
            10.0,
            "outputs for every input stamp",
        )
        checked_accel = 0
        for stamp_ns, (D, D_dot, s) in expected.items():
            (pose,), (twist,), (joints,) = (
                c.stamped(stamp_ns) for c in (forward.pose, forward.twist, forward.joints)
            )
            assert pose.header.frame_id == twist.header.frame_id == "base_link"
            np.testing.assert_allclose(vec(pose.pose.position), s.Q[:3], atol=1e-12)
            o = pose.pose.orientation
            np.testing.assert_allclose([o.x, o.y, o.z, o.w], bucket_quaternion(D[0], s.Q[3]), atol=1e-12)
            np.testing.assert_allclose(vec(twist.twist.linear), s.Q_dot[:3], atol=1e-12)
            np.testing.assert_allclose(
                vec(twist.twist.angular), bucket_angular_velocity(D[0], D_dot[0], s.Q_dot[3]), atol=1e-12
            )
            assert list(joints.name) == list(JOINTS)
            np.testing.assert_allclose(joints.position, s.theta, atol=1e-12)
            np.testing.assert_allclose(joints.velocity, s.theta_dot, atol=1e-12)
            for accel in forward.accel.stamped(stamp_ns):
                np.testing.assert_allclose(vec(accel.accel.linear), s.Q_ddot[:3], atol=1e-9)
                np.testing.assert_allclose(
                    vec(accel.accel.angular),
                    bucket_angular_acceleration(D[0], D_dot[0], 0.0, s.Q_dot[3], s.Q_ddot[3]),
                    atol=1e-9,
                )
                checked_accel += 1
        assert checked_accel == len(expected)

    def test_bucket_orientation_points_along_the_bucket_line(self, forward: Forward) -> None:
        """The pose's x axis is the direction bucket pin -> tip of the pin geometry (REP 103 check)."""
        D = np.array([-0.7, 2.4, 3.5, 2.5])
        when = 1_001 * 1_000_000_000
        forward.prime(when, D, np.zeros(4))
        o = forward.pose.stamped(when)[0].pose.orientation
        x, y, z, w = o.x, o.y, o.z, o.w
        x_axis = np.array([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)])
        pins = EXC.pins(D)
        line = pins["bucket_tip"] - pins["bucket_pin"]
        np.testing.assert_allclose(x_axis, line / np.linalg.norm(line), atol=1e-12)

    @pytest.mark.parametrize(
        ("name", "make", "reason"),
        [
            (
                "nan",
                lambda D: state_messages(stamp(0), np.r_[D[0], np.nan, D[2:]], np.zeros(4)),
                "non-finite position",
            ),
            (
                "stroke",
                lambda D: state_messages(stamp(0), np.r_[D[:3], LIMITS.stroke_max[2] + 0.05], np.zeros(4)),
                "outside the stroke",
            ),
            (
                "names",
                lambda D: (message_codec.joint_state(stamp(0), ["boom_cylinder"], [2.5], [0.0]), None),
                "missing from the message",
            ),
            (
                "no rates",
                lambda D: (message_codec.joint_state(stamp(0), CYLINDERS, D[1:]), None),
                "no velocity values",
            ),
            (
                "stale swing",
                lambda D: (state_messages(stamp(0), D, np.zeros(4))[0], None),
                "from the cylinder stamp",
            ),
            (
                "not cdr",  # published as bytes: the node decodes what it receives itself
                lambda D: (bytes([0, 1, 0, 0]) + b"\xff" * 40, None),
                "not a sensor_msgs/JointState",
            ),
        ],
    )
    def test_forward_rejects_bad_input_and_keeps_serving(
        self, forward: Forward, name: str, make: Callable, reason: str
    ) -> None:
        base = {
            "nan": 1_100,
            "stroke": 1_200,
            "names": 1_300,
            "no rates": 1_400,
            "stale swing": 1_500,
            "not cdr": 1_600,
        }[name]
        primed_ns = base * 1_000_000_000
        # The stale case comes 0.5 s after the swing state (swing_max_age 0.1 s), the others 1 ms.
        bad_ns = primed_ns + (500_000_000 if name == "stale swing" else 1_000_000)
        D = LIMITS.reference.copy()
        forward.prime(primed_ns, D, np.zeros(4))
        bad, _ = make(D)
        if not isinstance(bad, bytes):
            bad.header.stamp = stamp(bad_ns)
        forward.cylinders.publish(bad)
        wait_for_log(forward.probe, forward.process, reason)
        good_ns = primed_ns + 2_000_000
        forward.cylinders.publish(state_messages(stamp(good_ns), D, np.zeros(4))[0])
        forward.probe.wait_until(lambda: forward.pose.stamped(good_ns), 10.0, "output after the rejection")
        assert forward.process.alive()
        assert not any(c.stamped(bad_ns) for c in forward.outputs())
        assert all(finite(m) for c in forward.outputs() for m in c.messages)


# ---------------------------------------------------------------------------------- velocity IK
class VelocityIk:
    """An IK process in ``namespace``; the probe publishes its state D at 50 Hz while D is set.

    While a target is fresh the node recomputes on every cylinder message and stamps the command
    with that message's stamp, so a command tells exactly which published state it was made for.
    """

    def __init__(self, probe: Probe, process: NodeProcess, namespace: str, array: bool = False) -> None:
        self.probe, self.process = probe, process
        n = probe.node
        self.cylinders = n.create_publisher(JointState, f"{namespace}/cylinder_lengths", QOS)
        self.swing = n.create_publisher(JointState, f"{namespace}/joint_states", QOS)
        self.target = n.create_publisher(TwistStamped, f"{namespace}/target_bucket_twist", QOS)
        self.commands = Collector(probe, JointState, f"{namespace}/cylinder_rate_commands")
        self.arrays = Collector(probe, Float64MultiArray, f"{namespace}/velocity_controller/commands")
        self.D: np.ndarray | None = LIMITS.reference.copy()
        self.states: dict[int, np.ndarray] = {}  # stamp ns -> D published with it
        self.previous: np.ndarray | None = None
        n.create_timer(0.02, self.publish_state)
        wait_connected(
            probe, [self.cylinders, self.swing, self.target], [self.commands, self.arrays][: 1 + array]
        )
        self.next_ns = 2_000 * 1_000_000_000
        self.sent_at = 0  # probe clock (ns) when the last target was published

    def publish_state(self) -> None:
        if self.D is None:
            self.previous = None
            return
        now = self.probe.node.get_clock().now().to_msg()
        cylinders, swing = state_messages(now, self.D, np.zeros(4))
        self.swing.publish(swing)
        self.cylinders.publish(cylinders)
        # A state counts once the tick before it had the same D: the swing of either tick is then right.
        if self.previous is not None and np.array_equal(self.previous, self.D):
            self.states[message_codec.stamp_ns(now)] = self.D.copy()
        self.previous = self.D.copy()

    def send(self, linear: np.ndarray, angular: np.ndarray, frame: str = "base_link") -> int:
        """Publish a target twist with a unique stamp; returns the stamp (ns)."""
        self.next_ns += 1_000_000
        self.sent_at = self.probe.node.get_clock().now().nanoseconds  # the node receives it later
        self.target.publish(message_codec.bucket_twist(stamp(self.next_ns), frame, linear, angular))
        return self.next_ns

    def command(self, D: np.ndarray, linear: np.ndarray, angular: np.ndarray) -> np.ndarray:
        """Set the state D, send the target and return the rates commanded at D.

        The target is sent again until such a command comes: a target that arrives before the
        node has a state is rightly rejected (and discovery does not order the topics)."""
        self.D = D.copy()
        after = len(self.commands.messages)

        def found() -> list:
            return [
                m
                for m in self.commands.messages[after:]
                if np.array_equal(self.states.get(message_codec.stamp_ns(m.header.stamp), np.nan), D)
            ]

        deadline = time.monotonic() + 10.0
        while not found():
            self.send(linear, angular)
            try:
                self.probe.wait_until(lambda: bool(found()), 0.3, "rate command for the state")
            except TimeoutError:
                if time.monotonic() > deadline:
                    raise
        msg = found()[0]
        assert list(msg.name) == list(COMMAND_NAMES) and len(msg.position) == 0
        return np.array(msg.velocity)

    def q_dot_command(self, D: np.ndarray, q_dot: np.ndarray) -> np.ndarray:
        """Rates commanded at D for the consistent twist of bucket rates ``q_dot``."""
        return self.command(D, *twist_from_q_dot(D[0], EXC.pose(D)[:3], q_dot))

    def wait_stopped(self) -> None:
        """Until the target has expired (the last command is the zero one)."""
        self.probe.wait_until(
            lambda: self.commands.messages and not np.any(self.commands.messages[-1].velocity),
            5.0,
            "zero command after the timeout",
        )


@pytest.fixture(scope="class")
def ik(probe: Probe) -> Iterator[VelocityIk]:
    process = start("excavator_velocity_ik", "/ik", publish_array=True)
    try:
        yield VelocityIk(probe, process, "/ik", array=True)
    finally:
        print(process.stop())  # shown with a failing test


@pytest.fixture(scope="class")
def ik_damped(probe: Probe) -> Iterator[VelocityIk]:
    """An IK whose damping threshold (2) lies below cond(JC0) at the reference state (4.88)."""
    process = start("excavator_velocity_ik", "/ikd", condition_threshold=2.0)
    try:
        yield VelocityIk(probe, process, "/ikd")
    finally:
        print(process.stop())  # shown with a failing test


def damped(J: np.ndarray, q_dot: np.ndarray, threshold: float) -> np.ndarray:
    """Damped least squares in normal-equations form with the documented damping."""
    sigma = np.linalg.svd(J, compute_uv=False)
    lam = sigma[0] / threshold * (1.0 - threshold / (sigma[0] / sigma[-1]))
    return J.T @ np.linalg.solve(J @ J.T + lam**2 * np.eye(4), q_dot)


def slowed(J: np.ndarray, q_dot: np.ndarray, threshold: float) -> np.ndarray:
    """The exact solution (LU) brought down to the size of the damped one: the direction kept."""
    exact = np.linalg.solve(J, q_dot)
    return exact * np.linalg.norm(damped(J, q_dot, threshold)) / np.linalg.norm(exact)


class TestVelocityIkNode:
    """excavator_velocity_ik: the twist through JC0 and every safety behaviour."""

    def test_unconstrained_command_reproduces_the_twist_through_jc0(self, ik: VelocityIk) -> None:
        D = np.array([0.3, 2.7, 3.2, 2.2])
        q_dot = np.array([0.05, 0.1, -0.04, 0.08])
        linear, angular = twist_from_q_dot(D[0], EXC.pose(D)[:3], q_dot)
        d_dot = ik.command(D, linear, angular)
        achieved = EXC.jc0(D) @ d_dot
        np.testing.assert_allclose(achieved[:3], linear, atol=1e-9)
        np.testing.assert_allclose(bucket_angular_velocity(D[0], d_dot[0], achieved[3]), angular, atol=1e-9)
        ik.probe.wait_until(
            lambda: any(np.array_equal(a.data, d_dot) for a in ik.arrays.messages), 5.0, "array command"
        )
        ik.wait_stopped()

    def test_speed_limits_scale_the_whole_command(self, ik: VelocityIk) -> None:
        D = LIMITS.reference.copy()
        q_dot = np.array([1.5, 0.4, -0.8, 0.6])
        d_dot = ik.q_dot_command(D, q_dot)
        assert np.max(np.abs(d_dot) / LIMITS.max_rates) == pytest.approx(1.0, abs=1e-12)
        achieved = EXC.jc0(D) @ d_dot
        scale = achieved[0] / q_dot[0]
        assert 0.0 < scale < 1.0
        np.testing.assert_allclose(achieved, scale * q_dot, atol=1e-9)  # the bucket keeps its direction
        ik.wait_stopped()

    def test_never_commands_past_a_stroke_end_or_the_swing_limit(self, ik: VelocityIk) -> None:
        """Issue #18 item 4: an end stops (or slows) the whole command, so the bucket keeps its
        direction; before, only the actuator at its end stopped and the bucket turned away."""
        D = LIMITS.reference.copy()
        D[0], D[1] = LIMITS.swing_max, LIMITS.stroke_max[0]  # swing at its limit, boom fully extended
        wanted = np.array([0.1, 0.05, -0.02, 0.03])  # further on both
        assert np.all(ik.q_dot_command(D, EXC.jc0(D) @ wanted) == 0.0)
        D[0], D[1] = 0.0, LIMITS.stroke_max[0] - 0.002  # 2 mm before the end: at most 2 mm / stroke_horizon
        d_dot = ik.q_dot_command(D, EXC.jc0(D) @ wanted)
        assert d_dot[1] == pytest.approx(0.002 / 0.1, rel=1e-9)
        np.testing.assert_allclose(d_dot, wanted * (0.002 / 0.1) / wanted[1], rtol=1e-9, atol=1e-12)
        ik.wait_stopped()

    def test_damped_least_squares_above_the_condition_threshold(self, ik_damped: VelocityIk) -> None:
        D = LIMITS.reference.copy()
        q_dot = np.array([0.05, 0.0, 0.05, 0.05])
        d_dot = ik_damped.q_dot_command(D, q_dot)
        J = EXC.jc0(D)
        # Issue #18 item 4: damped least squares alone bends the direction; its size is used on the
        # exact solution (scale, don't bend).
        np.testing.assert_allclose(d_dot, slowed(J, q_dot, 2.0), rtol=1e-9, atol=1e-12)
        assert np.linalg.norm(J @ d_dot - q_dot) > 1e-3  # the damping is visible
        achieved = J @ d_dot
        np.testing.assert_allclose(achieved, (achieved @ q_dot) / (q_dot @ q_dot) * q_dot, atol=1e-12)
        wait_for_log(ik_damped.probe, ik_damped.process, "damped least squares")
        ik_damped.wait_stopped()

    def test_inconsistent_twist_uses_the_achievable_part_and_warns_throttled(
        self, ik_damped: VelocityIk
    ) -> None:
        """On the damped IK, whose state never changes, so every residual is the target's own."""
        ik = ik_damped
        D = LIMITS.reference.copy()
        q_dot = np.array([0.05, -0.02, 0.03, 0.05])
        linear, angular = twist_from_q_dot(D[0], EXC.pose(D)[:3], q_dot)
        roll = 0.2 * np.array([np.cos(D[0]), np.sin(D[0]), 0.0])  # about the radial axis: impossible
        np.testing.assert_allclose(
            ik.command(D, linear, angular + roll), slowed(EXC.jc0(D), q_dot, 2.0), atol=1e-12
        )
        for _ in range(10):
            ik.send(linear, angular + roll)
        wait_for_log(ik.probe, ik.process, "not achievable")
        assert (
            ik.process.log().count("not achievable") == 1
        )  # many inconsistent targets within 2 s: one warning
        ik.wait_stopped()

    def test_no_fresh_target_publishes_zero_once_and_holds(self, ik: VelocityIk) -> None:
        D = LIMITS.reference.copy()
        ik.q_dot_command(D, np.array([0.05, 0.0, 0.0, 0.0]))
        ik.wait_stopped()
        stopped_at = ik.probe.node.get_clock().now().nanoseconds
        # The last target was received after it was sent, so a stop at its 0.5 s timeout comes at
        # least 0.5 s after the send; the upper slack allows for scheduling delays of a loaded
        # 2-core CI machine (0.9 s was exceeded there) while still catching a late or missing stop.
        waited = (stopped_at - ik.sent_at) * 1e-9
        assert 0.5 <= waited < 0.5 + 2.0, waited
        zeros = len(ik.commands.messages)
        # Holding: the state keeps arriving at 50 Hz, yet nothing is published for another timeout.
        with pytest.raises(TimeoutError):
            ik.probe.wait_until(lambda: len(ik.commands.messages) > zeros, 0.6, "no command while holding")

    @pytest.mark.parametrize(
        ("what", "reason"),
        [
            ("nan", "non-finite twist"),
            ("huge", "implausible"),
            ("frame", "is not the base frame"),
            ("state", "cylinder_lengths is"),
        ],
    )
    def test_bad_target_or_missing_state_stops_with_a_reason_and_keeps_running(
        self, ik: VelocityIk, what: str, reason: str
    ) -> None:
        D = LIMITS.reference.copy()
        ik.q_dot_command(D, np.array([0.05, 0.0, 0.02, 0.0]))  # moving
        count = len(ik.commands.messages)
        good = np.array([0.05, 0.0, 0.02])
        if what == "nan":
            ik.send(np.array([np.nan, 0.0, 0.0]), np.zeros(3))
        elif what == "huge":
            # Finite, would overflow in eq. 9: refused where it enters (beyond 1000 x the fastest motion).
            ik.send(np.full(3, 1.7e308), np.array([0.0, -1.7e308, 0.0]))
        elif what == "frame":
            ik.send(good, np.zeros(3), frame="map")
        else:
            ik.D = None  # the state stops while the targets keep coming
            ik.probe.wait_until(
                lambda: ik.send(good, np.zeros(3)) and reason in ik.process.log(),
                5.0,
                "stale-state rejection",
            )
        wait_for_log(ik.probe, ik.process, reason)
        ik.probe.wait_until(
            lambda: any(not np.any(m.velocity) for m in ik.commands.messages[count:]),
            5.0,
            "zero command on rejection",
        )
        assert np.any(ik.q_dot_command(D, np.array([0.0, 0.0, 0.02, 0.0])))  # still serving
        assert ik.process.alive()
        assert all(np.all(np.isfinite(m.velocity)) for m in ik.commands.messages)
        ik.wait_stopped()


# ----------------------------------------------------------------------------------- closed loop
LINE_START = np.array([6.8, -0.9, 0.0])
LINE_DIRECTION = np.array([-0.8, 0.6, 0.0])
LINE_LENGTH, LINE_SPEED, LINE_ALPHA = 3.0, 0.3, -2.2


def state_at(q: np.ndarray) -> np.ndarray:
    """D with pose(D) = q, by Newton's method on eq. 8 from the reference state."""
    D = LIMITS.reference.copy()
    for _ in range(30):
        D = D + np.linalg.solve(EXC.jc0(D), q - EXC.pose(D))
    np.testing.assert_allclose(EXC.pose(D), q, atol=1e-12)
    return D


@pytest.fixture(scope="class")
def closed_loop(probe: Probe) -> Iterator[list[NodeProcess]]:
    D0 = state_at(np.r_[LINE_START, LINE_ALPHA])
    processes = [
        start(
            "excavator_sim",
            "/loop",
            initial_swing_angle=float(D0[0]),
            initial_cylinder_lengths=[float(v) for v in D0[1:]],
        ),
        start("excavator_forward", "/loop"),
        start("excavator_velocity_ik", "/loop"),
    ]
    try:
        yield processes
    finally:
        for process in processes:
            print(process.stop())


class TestClosedLoop:
    """excavator_sim + excavator_forward + excavator_velocity_ik + a driver."""

    def test_closed_loop_tracks_a_straight_line_along_the_ground(
        self, probe: Probe, closed_loop: list[NodeProcess]
    ) -> None:
        """sim + forward + velocity IK + a driver closing the loop on bucket_pose: a 3 m line on the
        ground at 0.3 m/s (with swing, since the line is oblique) stays within 5 mm of the line."""
        n = probe.node
        target = n.create_publisher(TwistStamped, "/loop/target_bucket_twist", QOS)
        poses: list[PoseStamped] = []
        started: list[int] = []

        def drive(msg: PoseStamped) -> None:
            # The reference is taken at the pose's stamp, so delivery delays do not look like errors.
            measured_ns = message_codec.stamp_ns(msg.header.stamp)
            if not started:
                started.append(measured_ns)
            poses.append(msg)
            travelled = min(LINE_SPEED * (measured_ns - started[0]) * 1e-9, LINE_LENGTH)
            reference = np.r_[LINE_START + travelled * LINE_DIRECTION, LINE_ALPHA]
            rate = np.r_[LINE_SPEED * LINE_DIRECTION * (travelled < LINE_LENGTH), 0.0]
            o = msg.pose.orientation
            theta1, alpha = bucket_angles([o.x, o.y, o.z, o.w])
            tip = vec(msg.pose.position)
            q_dot = follow(reference, rate, np.r_[tip, alpha], gain=4.0)
            target.publish(
                message_codec.bucket_twist(
                    msg.header.stamp, "base_link", *twist_from_q_dot(theta1, tip, q_dot)
                )
            )

        # Depth 1: a controller wants the latest pose, never a backlog.
        n.create_subscription(PoseStamped, "/loop/bucket_pose", drive, 1)
        wait_connected(probe, [target], [])
        probe.wait_until(lambda: bool(started), 20.0, "bucket_pose from the loop")
        duration = LINE_LENGTH / LINE_SPEED
        probe.wait_until(
            lambda: (message_codec.stamp_ns(poses[-1].header.stamp) - started[0]) * 1e-9 > duration + 0.5,
            duration + 10.0,
            "the line to be driven",
        )
        assert all(p.alive() for p in closed_loop)
        tips = np.array([vec(p.pose.position) for p in poses])
        offsets = tips - LINE_START
        along = offsets @ LINE_DIRECTION
        across = np.linalg.norm(offsets - along[:, None] * LINE_DIRECTION, axis=1)
        assert len(tips) > 0.5 * 100 * duration  # the sim publishes at 100 Hz
        assert along.max() > LINE_LENGTH - 0.005, f"the line was driven to {along.max():.4f} m only"
        assert across.max() < 0.005, f"max distance from the line {across.max() * 1000:.2f} mm"


# -------------------------------------------------------------------- the line past the stroke ends
# Legs of constant linear target twists (angular 0: hold the bucket angle) driven one after the other
# from the reference state, each until the machine cannot continue it: the issue's +x 2 m/s (far
# above the speed limits) first, then -z, +z, -x at 1 m/s (each moves the tip 0.6 to 5 m).
LEGS = [(2.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0)]
LINE_TOLERANCE = 0.03  # m: "a few centimetres"; measured 7-12 mm across processes


# bucket_angle_gives_way is driven the same way in one process (test_excavator_rate_command.py); across
# processes it is not asserted here: on a machine at load 12 it left the line by up to 9 cm (the
# bucket turning at full speed while the tip creeps, on commands that arrive late).
@pytest.fixture(scope="class", params=[False], ids=["direction_kept"])
def stroke_line(probe: Probe, request: pytest.FixtureRequest) -> Iterator[tuple[bool, list[NodeProcess]]]:
    """The three nodes from the reference state (the IK's bucket_angle_gives_way as the param)."""
    namespace = "/strokes_angle" if request.param else "/strokes"
    processes = [
        start("excavator_sim", namespace),
        start("excavator_forward", namespace),
        start("excavator_velocity_ik", namespace, bucket_angle_gives_way=request.param),
    ]
    try:
        yield request.param, processes
    finally:
        for process in processes:
            print(process.stop())


class TestLineAtStrokeEnds:
    """excavator_sim -> excavator_velocity_ik -> excavator_forward with a constant target at 50 Hz."""

    def test_the_tip_keeps_the_commanded_line_and_stops_where_it_cannot_go_on(
        self, probe: Probe, stroke_line: tuple[bool, list[NodeProcess]]
    ) -> None:
        """Before the fix the tip left the line by 4.25 m (+x 2 m/s, from z = 1.0 m down to -3.2 m), 1.12,
        1.93 and 2.08 m; now within LINE_TOLERANCE, the status says stopped (which cylinder) at the
        end of every leg, the tip then stays, and the stop is logged once while the target goes on.
        With bucket_angle_gives_way the bucket turns instead of stopping the tip, as the status says,
        and the tip gets further along the first leg (5.3 m instead of 3.3 m in one process)."""
        gives_way, processes = stroke_line
        ns = "/strokes_angle" if gives_way else "/strokes"
        n = probe.node
        target = n.create_publisher(TwistStamped, f"{ns}/target_bucket_twist", QOS)
        poses = Collector(probe, PoseStamped, f"{ns}/bucket_pose")
        statuses = Collector(probe, DiagnosticArray, f"{ns}/velocity_ik_status")
        commands = Collector(probe, JointState, f"{ns}/cylinder_rate_commands")
        linear: list[np.ndarray] = []

        def send() -> None:
            if linear:
                when = n.get_clock().now().to_msg()
                target.publish(message_codec.bucket_twist(when, "base_link", linear[0], np.zeros(3)))

        n.create_timer(0.02, send)
        wait_connected(probe, [target], [poses, statuses])
        probe.wait_until(lambda: len(poses.messages) > 5, 20.0, "bucket_pose from the sim")
        ik = processes[2]
        for number, leg in enumerate(LEGS):
            log_start = len(ik.log())
            start_tip = vec(poses.messages[-1].pose.position)
            first_pose, first_status = len(poses.messages), len(statuses.messages)
            linear[:] = [np.array(leg)]

            def stop(after: int = first_status) -> DiagnosticArray | None:
                """Moving, then stopped at an end: that status (a stale state on a loaded machine also
                stops, with another reason, and the next target moves on)."""
                texts = [m.status[0].message for m in statuses.messages[after:]]
                moving = next((i for i, t in enumerate(texts) if not t.startswith("stopped")), None)
                if moving is None:
                    return None
                return next(
                    (
                        statuses.messages[after + i]
                        for i, t in enumerate(texts)
                        if i > moving and "at its stroke end" in t
                    ),
                    None,
                )

            probe.wait_until(lambda: stop() is not None, 20.0, f"the stopped status of the leg {leg}")
            # By stamps, not by arrival: on a loaded machine the poses reach the probe 0.1 s after the
            # status. The status has the stamp of the state the stop was decided at; the sim (100 Hz)
            # gets the zero rates within 5 of its steps.
            settled = message_codec.stamp_ns(stop().header.stamp) + 50_000_000
            later = settled + 500_000_000
            probe.wait_until(
                lambda t=later: message_codec.stamp_ns(poses.messages[-1].header.stamp) > t,
                5.0,
                "0.5 s more poses",
            )
            tips = np.array([vec(m.pose.position) for m in poses.messages[first_pose:]])
            u = np.array(leg) / np.linalg.norm(leg)
            offsets = tips - start_tip
            along = offsets @ u
            off = np.linalg.norm(offsets - along[:, None] * u, axis=1)
            assert off.max() <= LINE_TOLERANCE, f"leg {leg}: {off.max() * 1000:.1f} mm from the line"
            assert along.max() > (4.0 if gives_way else 3.0) if number == 0 else along.max() > 0.1, (
                f"leg {leg}: only {along.max():.3f} m along the line"
            )
            after = np.array(
                [
                    vec(m.pose.position)
                    for m in poses.messages[first_pose:]
                    if message_codec.stamp_ns(m.header.stamp) >= settled
                ]
            )
            assert len(after) >= 40 and np.abs(after - after[0]).max() <= 1e-3  # stopped for good
            last = statuses.messages[-1].status[0]
            assert last.level == DiagnosticStatus.WARN and "at its stroke end" in last.message, last.message
            # 25 more targets since: said once (or not again, within warning_period of the same words)
            said = ik.log()[log_start:].count(last.message)
            assert said == 1 if number == 0 else said <= 1, ik.log()[log_start:]
        linear.clear()
        probe.wait_until(lambda: statuses.messages[-1].status[0].message.startswith("idle"), 5.0, "idle")
        assert all(np.all(np.isfinite(m.velocity)) for m in commands.messages)
        assert all(
            np.isfinite(float(v.value))
            for m in statuses.messages
            for v in m.status[0].values
            if v.key == "scale"
        )
        assert any("bucket angle gives way" in m.status[0].message for m in statuses.messages) == gives_way
        assert all(p.alive() for p in processes)
