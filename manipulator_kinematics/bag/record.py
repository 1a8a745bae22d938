"""record: topics into a rosbag2 bag (mcap by default), from raw subscriptions, flushed as it goes.

    record [-o BAG] [-s mcap|sqlite3] [--overwrite] [--topics T ...] [--type T:=pkg/msg/Type ...]
           [--discovery-timeout S] [--duration S] [--flush-interval S] [--ros-args ...]

Default topics: every topic of the package's nodes (their config files), resolved in the
recorder's namespace (``--ros-args -r __ns:=/machine1``) and remappings. A topic's type is the
one given with ``--type``, else the one its publishers show in the graph (waiting up to
``--discovery-timeout`` for them), else the package's own type for that topic. Messages are
stored as received (raw CDR) at their DDS reception time. The bag is flushed every
``--flush-interval`` s, so SIGKILL loses at most that much (see docs/bags.md).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import math
import signal
import sys
import threading
import time
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path

import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from manipulator_kinematics.bag.cli import guarded, parse_assignments, split_ros_args
from manipulator_kinematics.bag.io import STORAGES, BagError, BagWriter, TopicQos
from manipulator_kinematics.bag.topics import package_topics

NAME = "record"
# Subscriber queue: 1 s of a 1 kHz topic, so a stall of the recorder's thread loses nothing.
QUEUE_DEPTH = 1000
DISCOVERY_POLL = 0.05
STOP_LATENCY = 0.1


def message_class(msgtype: str) -> type:
    """The rclpy message class of ``pkg/msg/Name``; BagError if it is not installed."""
    package, kind, name = (msgtype.split("/") + ["", "", ""])[:3]
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), name)
    except (ImportError, AttributeError, ValueError):
        raise BagError(
            f"unknown message type {msgtype!r}: no Python module {package}.{kind} with {name!r}"
        ) from None


def subscription_qos(offered: Sequence[TopicQos]) -> QoSProfile:
    """A profile that matches every offered one: best effort if any publisher is, transient local
    only if all are."""
    reliable = all(q.reliable for q in offered)
    transient = bool(offered) and all(q.transient_local for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=QUEUE_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE,
    )


def offered_qos(node: Node, topic: str) -> list[TopicQos]:
    return [
        TopicQos(
            reliable=info.qos_profile.reliability == ReliabilityPolicy.RELIABLE,
            transient_local=info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL,
            depth=info.qos_profile.depth,
        )
        for info in node.get_publishers_info_by_topic(topic)
    ]


def discover_types(
    node: Node, topics: Sequence[str], timeout: float, stop: threading.Event
) -> dict[str, str]:
    """Types of ``topics`` as their publishers show them, waiting up to ``timeout`` s for them."""
    deadline = time.monotonic() + timeout
    found: dict[str, str] = {}
    while True:
        graph = dict(node.get_topic_names_and_types())
        for topic in topics:
            if topic in graph and node.count_publishers(topic) and len(graph[topic]) == 1:
                found[topic] = graph[topic][0]
        if len(found) == len(topics) or time.monotonic() >= deadline or stop.wait(DISCOVERY_POLL):
            return found


class Receiver:
    """Stores whatever arrives on the recorder's subscriptions, until stopped.

    rclpy's executor spends about 0.5 ms of Python per message (one wake-up and callback each),
    which at 1 kHz keeps a core busy and makes the recorder the first to fall behind on a loaded
    machine. This loop waits in rcl on all subscriptions at once (the wait set the executor is
    built on) and then takes every queued message of each ready one, so a recorder that fell
    behind catches up in one pass. Record time is the DDS reception time of each message.
    """

    def __init__(self, node: Node, writer: BagWriter, subscriptions: dict[str, Subscription]) -> None:
        self.node, self.writer, self.subscriptions = node, writer, subscriptions
        self.counts = dict.fromkeys(subscriptions, 0)

    def run(self, duration: float | None, stop: threading.Event) -> None:
        """Record for ``duration`` s (None: until ``stop`` is set)."""
        end = math.inf if duration is None else time.monotonic() + duration
        wait_set = _rclpy.WaitSet(len(self.subscriptions), 0, 0, 0, 0, 0, self.node.context.handle)
        with contextlib.ExitStack() as handles:
            for subscription in self.subscriptions.values():
                handles.enter_context(subscription.handle)
            while not stop.is_set() and (left := end - time.monotonic()) > 0:
                wait_set.clear_entities()
                for subscription in self.subscriptions.values():
                    wait_set.add_subscription(subscription.handle)
                # A signal handler only runs between waits: the timeout bounds how late a stop is seen.
                wait_set.wait(int(min(left, STOP_LATENCY, self.writer.flush_interval) * 1e9))
                ready = set(wait_set.get_ready_entities("subscription"))
                for topic, subscription in self.subscriptions.items():
                    if subscription.handle.pointer in ready:
                        self._take_all(topic, subscription)
                self.writer.flush_if_due()

    def _take_all(self, topic: str, subscription: Subscription) -> None:
        handle, msgtype, clock = subscription.handle, subscription.msg_type, self.node.get_clock()
        while (taken := handle.take_message(msgtype, True)) is not None:
            raw, info = taken
            self.writer.write(topic, info.get("received_timestamp") or clock.now().nanoseconds, raw)
            self.counts[topic] += 1


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=NAME, description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "-o", "--output", type=Path, help="bag directory to create (default: rosbag2_<date>-<time>)"
    )
    parser.add_argument("-s", "--storage", choices=sorted(STORAGES), default="mcap")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing bag at --output")
    parser.add_argument(
        "--topics",
        nargs="+",
        metavar="TOPIC",
        help="topics to record (default: every topic of the package's nodes)",
    )
    parser.add_argument(
        "--type",
        nargs="+",
        default=[],
        metavar="TOPIC:=TYPE",
        dest="types",
        help="type of a topic, e.g. /scan:=sensor_msgs/msg/LaserScan (skips discovery)",
    )
    parser.add_argument(
        "--discovery-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="how long to wait for publishers of topics whose type is not known (s)",
    )
    parser.add_argument("--duration", type=float, metavar="S", help="stop after this many seconds")
    parser.add_argument(
        "--flush-interval", type=float, default=0.5, metavar="S", help="most data a SIGKILL can lose (s)"
    )
    args = parser.parse_args(argv)
    if not args.flush_interval > 0 or (args.duration is not None and not args.duration > 0):
        parser.error("--flush-interval and --duration must be positive")
    return args


def record(argv: Sequence[str]) -> int:
    ours, ros_args = split_ros_args(argv)
    args = parse_args(ours)
    output = args.output or Path(datetime.now().strftime("rosbag2_%Y_%m_%d-%H_%M_%S"))
    if (output.exists() or output.is_symlink()) and not args.overwrite:
        raise BagError(f"{output} exists; not overwriting it (use --overwrite)")
    given = parse_assignments(args.types, "--type")

    # Our own handlers instead of rclpy's: its SIGINT handler also raises KeyboardInterrupt
    # wherever the recorder is, which could cut a bag write in half. SIGTERM (what launch and
    # test harnesses send) stops the recording like Ctrl-C.
    rclpy.init(args=[NAME, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    node = Node("bag_recorder")
    writer: BagWriter | None = None
    try:
        own = package_topics()
        names = args.topics or list(own)
        resolved = {node.resolve_topic_name(name): name for name in names}
        types = {topic: given.get(topic) or given.get(name) for topic, name in resolved.items()}
        types = {topic: t for topic, t in types.items() if t}
        unknown = [topic for topic in resolved if topic not in types]
        discovered = discover_types(node, unknown, args.discovery_timeout, stop) if unknown else {}
        if stop.is_set():
            raise KeyboardInterrupt
        for topic in unknown:
            types[topic] = discovered.get(topic) or own.get(resolved[topic]) or ""
        missing = sorted(topic for topic, t in types.items() if not t)
        if missing:
            raise BagError(
                f"no publisher of {', '.join(missing)} within {args.discovery_timeout:g} s; "
                f"give the type with --type TOPIC:=pkg/msg/Type"
            )
        classes = {topic: message_class(t) for topic, t in types.items()}

        writer = BagWriter(output, args.storage, overwrite=args.overwrite, flush_interval=args.flush_interval)
        subscriptions = {}
        for topic, msgtype in types.items():
            offered = offered_qos(node, topic)
            writer.add_topic(topic, msgtype, offered[0] if offered else None)
            # Never called: the Receiver takes the messages itself.
            subscriptions[topic] = node.create_subscription(
                classes[topic], topic, lambda _: None, subscription_qos(offered), raw=True
            )
        receiver = Receiver(node, writer, subscriptions)
        node.get_logger().info(
            f"recording {len(types)} topics to {output} ({args.storage}): "
            f"{', '.join(f'{t} [{m}]' for t, m in types.items())}"
        )
        receiver.run(args.duration, stop)
        writer.close()
        total = sum(receiver.counts.values())
        print(f"{NAME}: {total} messages on {len(receiver.counts)} topics in {output}", file=sys.stderr)
        return 0
    finally:
        if writer is not None:
            writer.close()
        node.destroy_node()
        rclpy.try_shutdown()


def main(argv: Sequence[str] | None = None) -> int:
    return guarded(NAME, record, argv)


if __name__ == "__main__":
    raise SystemExit(main())
