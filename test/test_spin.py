"""manipulator_kinematics.executor (and the parameter and log helpers of node_util) against real
rclpy entities over real DDS (isolated domain), under both executors: every entity kind our nodes
have is served, a failing callback is logged and the node keeps serving, shutdown or ``until``
ends the spin, and what EventsExecutor cannot serve is refused up front."""

from __future__ import annotations

import gc
import sys
import threading
from collections.abc import Iterator
from types import SimpleNamespace

import pytest
import rclpy
from rcl_interfaces.srv import GetParameters
from rclpy.duration import Duration
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerGuardCondition
from ros_harness import Probe
from std_msgs.msg import Int64
from std_srvs.srv import Trigger

from manipulator_kinematics.executor import EXECUTORS, executor_name, new_executor, spin
from manipulator_kinematics.node_util import param, refuse_runtime_changes
from manipulator_kinematics.param_files import ConfigError
from manipulator_kinematics.throttle import ThrottledLog

pytestmark = pytest.mark.ros

TIMEOUT = 15.0
QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
TOPICS = ("numbers", "others")


class Spun:
    """A node spun by ``spin`` in a thread of its own, on a context of its own."""

    def __init__(self, executor: str) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node("spun", context=self.context)
        self.node.declare_parameter("answer", 42)
        self.received: list[int] = []
        self.raw_sizes: list[int] = []
        self.ticks = 0
        self.echo = self.node.create_publisher(Int64, "echo", QOS)
        self.node.create_subscription(Int64, "numbers", self.on_number, QOS)
        self.node.create_subscription(
            Int64, "raw_numbers", lambda raw: self.raw_sizes.append(len(raw)), QOS, raw=True
        )
        self.node.create_timer(0.01, self.on_timer)
        self.node.create_service(Trigger, "trigger", self.on_trigger)
        self.node.create_service(Trigger, "explode", self.on_explode)
        self.executor = executor
        self.until = threading.Event()
        self.outcome: BaseException | None = None
        self.thread = threading.Thread(target=self.run, daemon=True)

    def on_number(self, msg: Int64) -> None:
        if msg.data < 0:
            raise RuntimeError("a negative number")
        self.received.append(msg.data)
        self.echo.publish(msg)

    def on_timer(self) -> None:
        self.ticks += 1
        if self.ticks == 3:
            raise ValueError("the third tick")

    def on_trigger(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = True, f"{len(self.received)} received"
        return response

    def on_explode(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        raise RuntimeError("a service callback failed")

    def run(self) -> None:
        try:
            spin(self.node, self.executor, until=self.until.is_set)
        except BaseException as error:  # handed to the test thread
            self.outcome = error


@pytest.fixture()
def probe() -> Iterator[Probe]:
    probe = Probe("spin_test_probe")
    yield probe
    probe.close()


@pytest.fixture(params=sorted(EXECUTORS))
def spun(request: pytest.FixtureRequest) -> Iterator[Spun]:
    spun = Spun(request.param)
    spun.thread.start()
    yield spun
    spun.context.try_shutdown()
    spun.thread.join(TIMEOUT)
    spun.node.destroy_node()


def matched(probe: Probe, publisher, topic: str) -> None:
    probe.wait_until(lambda: publisher.get_subscription_count() == 1, TIMEOUT, f"a subscriber of {topic}")


def test_serves_subscriptions_raw_subscriptions_timers_services_and_parameter_services(
    probe: Probe, spun: Spun
) -> None:
    numbers = probe.node.create_publisher(Int64, "numbers", QOS)
    raw = probe.node.create_publisher(Int64, "raw_numbers", QOS)
    echoed: list[int] = []
    probe.node.create_subscription(Int64, "echo", lambda m: echoed.append(m.data), QOS)
    matched(probe, numbers, "numbers")
    matched(probe, raw, "raw_numbers")
    probe.wait_until(lambda: spun.echo.get_subscription_count() == 1, TIMEOUT, "a subscriber of echo")
    numbers.publish(Int64(data=7))
    raw.publish(Int64(data=8))
    probe.wait_until(lambda: echoed == [7] and spun.raw_sizes, TIMEOUT, "the echo of 7 and the raw 8")
    assert spun.raw_sizes == [12]  # CDR: 4 bytes of encapsulation header, 8 of int64

    trigger = probe.node.create_client(Trigger, "trigger")
    probe.wait_until(trigger.service_is_ready, TIMEOUT, "trigger service")
    assert probe.call(trigger, Trigger.Request(), TIMEOUT).message == "1 received"

    parameters = probe.node.create_client(GetParameters, "spun/get_parameters")
    probe.wait_until(parameters.service_is_ready, TIMEOUT, "parameter service")
    values = probe.call(parameters, GetParameters.Request(names=["answer"]), TIMEOUT).values
    assert [v.integer_value for v in values] == [42]

    ticks = spun.ticks
    probe.wait_until(lambda: spun.ticks >= ticks + 5, TIMEOUT, "five timer ticks")
    assert spun.thread.is_alive() and spun.outcome is None


def test_a_failing_callback_is_logged_and_the_node_keeps_serving(
    probe: Probe, spun: Spun, capfd: pytest.CaptureFixture[str]
) -> None:
    numbers = probe.node.create_publisher(Int64, "numbers", QOS)
    echoed: list[int] = []
    probe.node.create_subscription(Int64, "echo", lambda m: echoed.append(m.data), QOS)
    matched(probe, numbers, "numbers")
    probe.wait_until(lambda: spun.echo.get_subscription_count() == 1, TIMEOUT, "a subscriber of echo")
    numbers.publish(Int64(data=-1))
    numbers.publish(Int64(data=5))
    probe.wait_until(lambda: echoed == [5], TIMEOUT, "the echo of 5 after a failed callback")

    explode = probe.node.create_client(Trigger, "explode")
    probe.wait_until(explode.service_is_ready, TIMEOUT, "explode service")
    response = probe.call(explode, Trigger.Request(), TIMEOUT)
    assert not response.success
    assert response.message.startswith("internal error: RuntimeError: a service callback failed (at ")

    probe.wait_until(lambda: spun.ticks >= 6, TIMEOUT, "timer ticks after the failed third")
    assert spun.thread.is_alive() and spun.outcome is None
    log = capfd.readouterr().err
    assert (
        "subscription to /numbers failed on std_msgs.msg.Int64(data=-1): RuntimeError: a negative number"
        in log
    )
    assert "timer of 0.01 s failed on its tick: ValueError: the third tick (at " in log
    assert "service /explode failed on std_srvs.srv.Trigger_Request" in log


def test_events_hands_a_backlog_on_two_topics_over_in_the_order_it_was_sent(probe: Probe) -> None:
    """What the forward node relies on after a stall: a cylinder message is not handled before the
    swing message sent ahead of it. (SingleThreadedExecutor takes one message per ready topic in
    turn instead.)"""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("ordered", context=context)
    sequence: list[tuple[str, int]] = []
    holding, release = threading.Event(), threading.Event()

    def on_number(msg: Int64) -> None:
        holding.set()  # the first message holds the executor: the rest piles up
        release.wait(TIMEOUT)
        sequence.append(("numbers", msg.data))

    node.create_subscription(Int64, "numbers", on_number, QOS)
    node.create_subscription(Int64, "others", lambda msg: sequence.append(("others", msg.data)), QOS)
    thread = threading.Thread(target=spin, args=(node, "events"), daemon=True)
    thread.start()
    try:
        publishers = {topic: probe.node.create_publisher(Int64, topic, QOS) for topic in TOPICS}
        for topic, publisher in publishers.items():
            matched(probe, publisher, topic)
        sent = [("numbers", 0)] + [("others" if n % 3 else "numbers", n) for n in range(1, 60)]
        publishers["numbers"].publish(Int64(data=0))
        probe.wait_until(holding.is_set, TIMEOUT, "the executor held in its first callback")
        for topic, n in sent[1:]:
            publishers[topic].publish(Int64(data=n))
        for publisher in publishers.values():
            probe.wait_until(
                lambda p=publisher: p.wait_for_all_acked(Duration(seconds=0.01)), TIMEOUT, "acknowledgements"
            )
        release.set()
        probe.wait_until(lambda: len(sequence) == len(sent), TIMEOUT, f"{len(sent)} messages")
        assert sequence == sent
    finally:
        release.set()
        context.try_shutdown()
        thread.join(TIMEOUT)
        node.destroy_node()


def test_shutdown_of_the_context_ends_the_spin(spun: Spun) -> None:
    spun.context.shutdown()
    spun.thread.join(TIMEOUT)
    assert not spun.thread.is_alive() and spun.outcome is None


@pytest.mark.parametrize("executor", [*sorted(EXECUTORS), "multi", "signal guard"])
def test_a_shutdown_before_the_executor_is_built_ends_the_spin_quietly(
    executor: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """rclpy's executors fail on a shut-down context half-built, and collecting one printed a
    traceback (seen in a node signalled while it started): a shutdown before the build, during it
    (at the executor's guard condition, or at its signal guard condition, built after it), and
    before the spin."""
    unraisable: list[object] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda what: unraisable.append(what.exc_value))
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("built_late", context=context)
    built = {"multi": MultiThreadedExecutor, "signal guard": SignalHandlerGuardCondition}.get(
        executor, EXECUTORS.get(executor)
    )

    def shut_down_then_build(**options: object) -> object:
        context.shutdown()
        return built(**options)

    options = {"num_threads": 2} if executor == "multi" else {}
    built_late = new_executor(shut_down_then_build, context, **options)
    if executor == "events":  # EventsExecutor builds on a shut-down context; its spin ends at once
        built_late.shutdown()
    else:
        assert built_late is None
    if executor == "multi":
        node.THREADS = 2
    spin(node, "single" if executor in ("multi", "signal guard") else executor)  # returns at once
    node.destroy_node()
    gc.collect()
    assert unraisable == []


def test_until_ends_the_spin(spun: Spun) -> None:
    spun.until.set()
    spun.thread.join(TIMEOUT)
    assert not spun.thread.is_alive() and spun.outcome is None
    assert spun.context.ok()


@pytest.mark.parametrize("executor", sorted(EXECUTORS))
def test_message_info_callbacks_are_refused_by_events_and_served_by_single(
    probe: Probe, executor: str
) -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("with_info", context=context)
    infos: list[dict] = []
    node.create_subscription(Int64, "numbers", lambda msg, info: infos.append(info), QOS)
    thread = threading.Thread(target=spin, args=(node, executor), daemon=True)
    try:
        if executor == "events":
            with pytest.raises(ValueError, match="/numbers take \\(msg, info\\)"):
                spin(node, executor)
            return
        thread.start()
        publisher = probe.node.create_publisher(Int64, "numbers", QOS)
        matched(probe, publisher, "numbers")
        publisher.publish(Int64(data=1))
        probe.wait_until(lambda: infos, TIMEOUT, "a message with its info")
        assert infos[0]["received_timestamp"] > 0
    finally:
        context.try_shutdown()
        if thread.is_alive():
            thread.join(TIMEOUT)
        node.destroy_node()


def test_the_executor_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("MK_EXECUTOR", raising=False)
    assert executor_name() == "events"
    monkeypatch.setenv("MK_EXECUTOR", "single")
    assert executor_name() == "single"
    assert executor_name("events") == "events"
    monkeypatch.setenv("MK_EXECUTOR", "multi")
    with pytest.raises(ConfigError, match="MK_EXECUTOR='multi'"):
        executor_name()


def test_runtime_parameter_changes_are_refused_with_a_reason_and_parameters_are_described() -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("params", context=context, parameter_overrides=[Parameter("given", value=2.5)])
    try:
        assert param(node, "rate", 100.0, "loop rate") == 100.0
        assert param(node, "given", 1.0) == 2.5
        described = node.describe_parameter("rate")
        assert described.read_only and described.description == "loop rate"
        assert described.additional_constraints == "parameters are read at start-up"
        assert node.describe_parameter("given").read_only
        node.declare_parameter("free", 1)
        refuse_runtime_changes(node)
        [result] = node.set_parameters([Parameter("free", value=2)])
        assert not result.successful
        assert result.reason == "parameters are read at start-up: restart the node to change free"
        assert node.get_parameter("free").value == 1
        [result] = node.set_parameters([Parameter("rate", value=5.0)])
        assert not result.successful and "read-only" in result.reason
        assert node.declare_parameter("declared_later", 3).value == 3
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


class FakeNode:
    """What ThrottledLog uses of a node: a clock the test sets and a logger that keeps the lines."""

    def __init__(self) -> None:
        self.now_ns = 0
        self.lines: list[tuple[str, str]] = []
        logger = SimpleNamespace(
            **{
                severity: (lambda text, s=severity: self.lines.append((s, text)))
                for severity in ("error", "warning", "info")
            }
        )
        self.get_logger = lambda: logger
        self.get_clock = lambda: SimpleNamespace(now=lambda: SimpleNamespace(nanoseconds=self.now_ns))


def test_throttled_log_keeps_each_kind_to_one_line_per_period() -> None:
    node = FakeNode()
    log = ThrottledLog(node, period=2.0)
    log("error", "rejected: 1.5 m out of range")
    log("error", "rejected: 2.5 m out of range")  # the same kind: numbers do not count
    log("warning", "stale state")
    node.now_ns = 2_000_000_000
    log("error", "rejected: 3.5 m out of range")
    assert node.lines == [
        ("error", "rejected: 1.5 m out of range"),
        ("warning", "stale state (1 more held back since the previous line)"),
        ("error", "rejected: 3.5 m out of range"),
    ]


def letters(n: int) -> str:
    """A name without digits for each n: 0 -> 'a', 12 -> 'bc'."""
    return "".join("abcdefghij"[int(digit)] for digit in str(n))


def test_throttled_log_is_bounded_in_lines_and_memory_whatever_the_inputs_say() -> None:
    node = FakeNode()
    log = ThrottledLog(node, period=2.0, max_lines=3)
    for period in range(3):
        node.now_ns = period * 2_000_000_000
        for n in range(1000):
            log("error", f"unknown joint {letters(n)!r}")  # a new kind every time
            node.now_ns += 1000
    assert len(node.lines) == 9  # 3 per period
    assert node.lines[3] == ("error", "unknown joint 'a' (997 more held back since the previous line)")
    assert len(log._last) <= 3
    # A caller-given kind groups texts that differ in more than numbers.
    node.lines.clear()
    node.now_ns += 10_000_000_000
    log("error", "frame 'a' is not base_link", kind="frame")
    log("error", "frame 'b' is not base_link", kind="frame")
    assert [text for _, text in node.lines] == [
        "frame 'a' is not base_link (997 more held back since the previous line)"
    ]
