"""manipulator_kinematics.spin against real rclpy entities over real DDS (isolated domain): every
entity kind our nodes have is served, a backlog arrives whole and in order, shutdown from another
thread ends the spin, and what it cannot serve is refused up front."""
from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest
import rclpy
from rcl_interfaces.srv import GetParameters
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import Probe
from std_msgs.msg import Int64
from std_srvs.srv import Trigger

from manipulator_kinematics.spin import spin

TIMEOUT = 15.0
BACKLOG = 200
QOS = QoSProfile(depth=BACKLOG, reliability=ReliabilityPolicy.RELIABLE)


class Spun:
    """A node spun by ``spin`` in a thread of its own, on a context of its own."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node("spun", context=self.context)
        self.node.declare_parameter("answer", 42)
        self.received: list[int] = []
        self.sequence: list[tuple[str, int]] = []  # (topic, data) in callback order
        self.holding = threading.Event()
        self.ticks = 0
        self.release = threading.Event()
        self.echo = self.node.create_publisher(Int64, "echo", QOS)
        self.node.create_subscription(Int64, "numbers", self.on_number, QOS)
        self.node.create_subscription(Int64, "others", self.on_other, QOS)
        self.node.create_timer(0.01, self.on_timer)
        self.node.create_service(Trigger, "trigger", self.on_trigger)
        self.node.create_service(Trigger, "explode", self.on_explode)
        self.outcome: BaseException | None = None
        self.thread = threading.Thread(target=self.run, daemon=True)

    def on_number(self, msg: Int64) -> None:
        # Holding the first message makes the rest pile up in the queue: a backlog to catch up on.
        self.holding.set()
        self.release.wait(TIMEOUT)
        if msg.data < 0:
            raise RuntimeError("a negative number")
        self.received.append(msg.data)
        self.sequence.append(("numbers", msg.data))
        self.echo.publish(msg)

    def on_other(self, msg: Int64) -> None:
        self.sequence.append(("others", msg.data))

    def on_timer(self) -> None:
        self.ticks += 1

    def on_trigger(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = True, f"{len(self.received)} received"
        return response

    def on_explode(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        raise RuntimeError("a service callback failed")

    def run(self) -> None:
        try:
            spin(self.node)
        except BaseException as error:  # handed to the test thread
            self.outcome = error


@pytest.fixture()
def probe() -> Iterator[Probe]:
    probe = Probe("spin_test_probe")
    yield probe
    probe.close()


@pytest.fixture()
def spun() -> Iterator[Spun]:
    spun = Spun()
    spun.thread.start()
    yield spun
    spun.release.set()
    spun.context.try_shutdown()
    spun.thread.join(TIMEOUT)
    spun.node.destroy_node()


def test_serves_subscriptions_timers_services_and_parameter_services(probe: Probe, spun: Spun) -> None:
    spun.release.set()
    publisher = probe.node.create_publisher(Int64, "numbers", QOS)
    echoed: list[int] = []
    probe.node.create_subscription(Int64, "echo", lambda m: echoed.append(m.data), QOS)

    def matched() -> bool:
        return publisher.get_subscription_count() == 1 and spun.echo.get_subscription_count() == 1

    probe.wait_until(matched, TIMEOUT, "matching")
    publisher.publish(Int64(data=7))
    probe.wait_until(lambda: echoed == [7], TIMEOUT, "the echo of 7")

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


def test_a_backlog_is_delivered_whole_and_in_order(probe: Probe, spun: Spun) -> None:
    publisher = probe.node.create_publisher(Int64, "numbers", QOS)
    probe.wait_until(lambda: publisher.get_subscription_count() == 1, TIMEOUT, "matching")
    for n in range(BACKLOG):
        publisher.publish(Int64(data=n))
    # The spun thread is held in the first callback until every message was published.
    probe.wait_until(lambda: publisher.wait_for_all_acked(Duration(seconds=0.01)),
                     TIMEOUT, "all messages acknowledged by the subscriber")
    spun.release.set()
    probe.wait_until(lambda: len(spun.received) == BACKLOG, TIMEOUT, f"{BACKLOG} messages")
    assert spun.received == list(range(BACKLOG))


def test_a_backlog_on_two_topics_is_delivered_in_the_order_it_was_sent(probe: Probe, spun: Spun) -> None:
    publishers = {topic: probe.node.create_publisher(Int64, topic, QOS) for topic in ("numbers", "others")}
    probe.wait_until(lambda: all(p.get_subscription_count() == 1 for p in publishers.values()), TIMEOUT,
                     "matching")
    sent = [("numbers", 0)] + [("others" if n % 3 else "numbers", n) for n in range(1, 60)]
    publishers["numbers"].publish(Int64(data=0))
    probe.wait_until(spun.holding.is_set, TIMEOUT, "the spun thread held in its first callback")
    for topic, n in sent[1:]:
        publishers[topic].publish(Int64(data=n))
    for publisher in publishers.values():
        probe.wait_until(lambda p=publisher: p.wait_for_all_acked(Duration(seconds=0.01)), TIMEOUT, "acks")
    spun.release.set()
    probe.wait_until(lambda: len(spun.sequence) == len(sent), TIMEOUT, f"{len(sent)} messages")
    assert spun.sequence == sent


def test_shutdown_from_another_thread_ends_the_spin(spun: Spun) -> None:
    spun.release.set()
    spun.context.shutdown()
    spun.thread.join(TIMEOUT)
    assert not spun.thread.is_alive()
    assert isinstance(spun.outcome, ExternalShutdownException)


def test_a_subscription_callback_exception_ends_the_spin_and_is_raised(probe: Probe, spun: Spun) -> None:
    spun.release.set()
    publisher = probe.node.create_publisher(Int64, "numbers", QOS)
    probe.wait_until(lambda: publisher.get_subscription_count() == 1, TIMEOUT, "matching")
    publisher.publish(Int64(data=-1))
    probe.wait_until(lambda: not spun.thread.is_alive(), TIMEOUT, "the end of the spin")
    assert isinstance(spun.outcome, RuntimeError) and str(spun.outcome) == "a negative number"


def test_a_service_callback_exception_ends_the_spin_and_is_raised(probe: Probe, spun: Spun) -> None:
    client = probe.node.create_client(Trigger, "explode")
    probe.wait_until(client.service_is_ready, TIMEOUT, "explode service")
    client.call_async(Trigger.Request())
    probe.wait_until(lambda: not spun.thread.is_alive(), TIMEOUT, "the end of the spin")
    assert isinstance(spun.outcome, RuntimeError) and str(spun.outcome) == "a service callback failed"


def test_a_node_with_a_client_is_refused() -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("with_client", context=context)
    try:
        node.create_client(Trigger, "trigger")
        with pytest.raises(ValueError, match="clients or guard conditions"):
            spin(node)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
