"""record: topics into a rosbag2 bag (mcap by default), from raw subscriptions, flushed as it goes.

    record [-o BAG] [-s mcap|sqlite3] [--overwrite] [--topics T ...] [--type T:=pkg/msg/Type ...]
           [--discovery-timeout S] [--duration S] [--flush-interval S] [--visuals [PARAMS ...]]
           [--ros-args ...]

Default topics: every topic of the registered machines' nodes (``Machine.topics``), resolved in the
recorder's namespace (``--ros-args -r __ns:=/machine1``) and remappings. A topic's type is the
one given with ``--type``, else the one its publishers show in the graph (waiting up to
``--discovery-timeout`` for them), else the package's own type for that topic. Messages are
stored as received (raw CDR) at the time the recorder takes them. The bag is flushed every
``--flush-interval`` s, so SIGKILL loses at most that much (see docs/bags.md). Spun by
:func:`manipulator_kinematics.executor.spin` (``MK_EXECUTOR``); on SIGINT/SIGTERM it stores
what is still queued and then ends.
"""

from __future__ import annotations

import argparse
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
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from manipulator_kinematics.bag.cli import guarded, parse_assignments, split_ros_args
from manipulator_kinematics.bag.topics import package_topics
from manipulator_kinematics.bag.types import BagError, TopicQos
from manipulator_kinematics.bag.writer import STORAGES, BagWriter
from manipulator_kinematics.executor import executor_name, spin
from manipulator_kinematics.params import ConfigError

NAME = "record"
# Subscriber queue: 1 s of a 1 kHz topic, so a stall of the recorder's thread loses nothing.
QUEUE_DEPTH = 1000
DISCOVERY_POLL = 0.05
STOP_LATENCY = 0.1
DRAIN_LIMIT = 1.0


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
    """Stores whatever arrives on the recorder's subscriptions (raw CDR), until stopped.

    Record time is the time the message is handed to its callback: the DDS reception time is
    only in the message info, which EventsExecutor cannot pass (see manipulator_kinematics.executor).
    """

    def __init__(self, node: Node, writer: BagWriter) -> None:
        self.node, self.writer = node, writer
        self.counts: dict[str, int] = {}
        self._counted = -1
        self._stopped_at: float | None = None

    def subscribe(self, topic: str, msg_class: type, qos: QoSProfile) -> None:
        self.counts[topic] = 0
        clock, write, counts = self.node.get_clock(), self.writer.write, self.counts

        def store(raw: bytes) -> None:
            write(topic, clock.now().nanoseconds, raw)
            counts[topic] += 1

        self.node.create_subscription(msg_class, topic, store, qos, raw=True)

    def run(self, duration: float | None, stop: threading.Event, executor: str) -> None:
        """Record for ``duration`` s (None: until ``stop`` is set), then take what is still queued
        (at most ``DRAIN_LIMIT`` s more)."""
        end = math.inf if duration is None else time.monotonic() + duration
        self.node.create_timer(self.writer.flush_interval, self.writer.flush_if_due)

        def done() -> bool:
            now = time.monotonic()
            if not stop.is_set() and now < end:
                return False
            # Once a whole poll went by without a message, every one that arrived before the stop
            # (all acknowledged ones of a publisher that waited for its acks) is stored; a
            # publisher that keeps sending does not keep the recorder alive.
            self._stopped_at = self._stopped_at or now
            total = sum(self.counts.values())
            quiet, self._counted = total == self._counted, total
            return quiet or now - self._stopped_at >= DRAIN_LIMIT

        # A signal handler only runs between polls: the poll bounds how late a stop is seen.
        spin(self.node, executor, until=done, poll=min(STOP_LATENCY, self.writer.flush_interval))


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
        "--visuals",
        nargs="*",
        type=Path,
        metavar="PARAMS",
        help="when the recording ends, add /robot_description, /tf, /tf_static and machine_markers for "
        "Foxglove (manipulator_kinematics.bag.visual); optional params files with the machines "
        "(default: the shipped ones)",
    )
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
    try:
        executor = executor_name()
    except ConfigError as error:
        raise BagError(str(error)) from None

    # Our own handlers instead of rclpy's: those shut the context down at once, losing what is
    # still queued, and their SIGINT also raises KeyboardInterrupt wherever the recorder is, which
    # could cut a bag write in half. SIGTERM (what launch and test harnesses send) stops the
    # recording like Ctrl-C.
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
        receiver = Receiver(node, writer)
        for topic, msgtype in types.items():
            offered = offered_qos(node, topic)
            writer.add_topic(topic, msgtype, offered[0] if offered else None)
            receiver.subscribe(topic, classes[topic], subscription_qos(offered))
        node.get_logger().info(
            f"recording {len(types)} topics to {output} ({args.storage}): "
            f"{', '.join(f'{t} [{m}]' for t, m in types.items())}"
        )
        receiver.run(args.duration, stop, executor)
        writer.close()
        total = sum(receiver.counts.values())
        print(f"{NAME}: {total} messages on {len(receiver.counts)} topics in {output}", file=sys.stderr)
        if args.visuals is not None:
            add_visuals_to_recording(output, args.visuals)
        return 0
    finally:
        if writer is not None:
            writer.close()
        node.destroy_node()
        rclpy.try_shutdown()


def add_visuals_to_recording(output: Path, params: Sequence[Path]) -> None:
    """``--visuals``: the recorded bag rewritten with its visual topics (the recording stays as it
    is when that fails)."""
    from manipulator_kinematics.bag.visual import add_visuals  # URDF and scene code: only when asked

    try:
        added = add_visuals(output, output, params=params)
    except BagError as error:
        raise BagError(f"{output} is recorded, but no visual topics were added: {error}") from None
    for item in added:
        print(f"{NAME}: added {', '.join(item.topics)} for {item.machine} ({item.states} states) in "
              f"{item.namespace}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    return guarded(NAME, record, argv)


if __name__ == "__main__":
    raise SystemExit(main())
