"""mk_replay: publish a bag's messages again with their recorded timing.

    mk_replay BAG [--rate R] [--loop] [--topics T ...] [--remap FROM:=TO ...] [--start-offset S]
           [--wait-for-subscribers S] [--recover] [--ros-args ...]

Messages go out as recorded (raw CDR, header stamps untouched) on their recorded topic names,
or the names given with ``--remap`` (a relative target is resolved in the replayer's namespace).
Bag topics in ``--topics`` and on the left of ``--remap`` are named with or without the leading
slash (``joint_states`` is the bag's ``/joint_states``).
Message k is published ``(t_k - t_start) / rate`` seconds after the start, t being the record
time and t_start the first message's plus ``--start-offset``. Publishers use the recorded QoS
(reliability, durability) with a deep queue.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from manipulator_kinematics.bag.cli import guarded, parse_assignments, split_ros_args
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.record import QUEUE_DEPTH, message_class
from manipulator_kinematics.bag.types import BagError, TopicQos

NAME = "mk_replay"
# Longest single sleep, so Ctrl-C and shutdown are noticed during long pauses in a bag.
MAX_SLEEP = 0.1
ACK_TIMEOUT = 5.0
MATCH_SETTLE = 0.5


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=NAME, description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", type=Path)
    parser.add_argument("--rate", type=float, default=1.0, help="time factor: 2 plays twice as fast")
    parser.add_argument("--loop", action="store_true", help="start over at the end, until stopped")
    parser.add_argument(
        "--topics",
        nargs="+",
        metavar="TOPIC",
        help="bag topics to play, with or without the leading slash (default: all)",
    )
    parser.add_argument(
        "--remap",
        nargs="+",
        default=[],
        metavar="FROM:=TO",
        help="publish bag topic FROM on topic TO (a relative TO is in the replayer's namespace)",
    )
    parser.add_argument(
        "--start-offset", type=float, default=0.0, metavar="S", help="skip the first S seconds of the bag"
    )
    parser.add_argument(
        "--wait-for-subscribers",
        type=float,
        default=0.0,
        metavar="S",
        help="before playing, wait up to S s until every topic has a subscriber",
    )
    parser.add_argument(
        "--recover",
        action="store_true",
        help="play an mcap bag whose recorder was killed, up to its last flush",
    )
    args = parser.parse_args(argv)
    if not args.rate > 0:
        parser.error(f"--rate must be positive, got {args.rate}")
    if args.start_offset < 0:
        parser.error(f"--start-offset must not be negative, got {args.start_offset}")
    return args


def bag_topic(name: str) -> str:
    """The bag's (absolute) name of a topic given as ``name`` or ``/name``."""
    return name if name.startswith("/") else f"/{name}"


def publisher_qos(qos: TopicQos | None) -> QoSProfile:
    qos = qos or TopicQos()
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=QUEUE_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if qos.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.transient_local else DurabilityPolicy.VOLATILE,
    )


def wait_for_subscribers(node: Node, publishers: dict, timeout: float) -> None:
    """Wait until every publisher has a subscriber, then ``MATCH_SETTLE`` s more.

    A publisher counts a subscriber once it has matched the subscriber's reader; the reader
    matches the publisher separately, usually within milliseconds, and drops what arrives before
    (the recorder benchmark lost the first ~10 messages at 1 kHz that way). The settle time covers
    that second half, which the publishing side cannot observe.
    """
    deadline = time.monotonic() + timeout
    while rclpy.ok():
        alone = [topic for topic, pub in publishers.items() if pub.get_subscription_count() == 0]
        if not alone:
            time.sleep(MATCH_SETTLE)
            return
        if time.monotonic() >= deadline:
            node.get_logger().warning(
                f"no subscriber on {', '.join(alone)} after {timeout:g} s; playing anyway"
            )
            return
        time.sleep(0.01)


@dataclass(frozen=True)
class Playlist:
    """What replay publishes: messages (topic, record time ns, CDR bytes) in record order, from
    ``start`` on, each topic with its message class, recorded QoS and published name."""

    messages: list[tuple[str, int, bytes]]
    start: int
    classes: dict[str, type]
    qos: dict[str, TopicQos | None]
    names: dict[str, str]


def load(args: argparse.Namespace) -> Playlist:
    """Everything replay reads before it starts ROS; BagError for a bag it cannot play as asked."""
    bag = BagReader(args.bag, recover=args.recover)
    if bag.recovered:
        print(f"{NAME}: warning: {bag.recovered}", file=sys.stderr)
    topics = bag.select(None if args.topics is None else [bag_topic(t) for t in args.topics])
    remap = {bag_topic(source): target for source, target in parse_assignments(args.remap, "--remap").items()}
    strangers = sorted(set(remap) - set(bag.topics))
    if strangers:
        raise BagError(f"--remap of {', '.join(strangers)}: not in the bag (it has {', '.join(bag.topics)})")
    messages = list(bag.messages(topics))
    classes = {topic: message_class(bag.topics[topic].msgtype) for topic in topics}
    if not messages:
        raise BagError(f"{args.bag}: no messages to play on {', '.join(topics)}")
    start = messages[0][1] + int(args.start_offset * 1e9)
    if start > messages[-1][1]:
        raise BagError(
            f"--start-offset {args.start_offset:g} s is past the end of the selected messages "
            f"({(messages[-1][1] - messages[0][1]) * 1e-9:.3f} s)"
        )
    return Playlist(
        messages,
        start,
        classes,
        {topic: bag.topics[topic].qos for topic in topics},
        {topic: remap.get(topic, topic) for topic in topics},
    )


def replay(argv: Sequence[str]) -> int:
    ours, ros_args = split_ros_args(argv)
    args = parse_args(ours)
    playlist = load(args)

    rclpy.init(args=[NAME, *ros_args])
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    node = Node("bag_replay")
    try:
        publishers = {
            topic: node.create_publisher(cls, playlist.names[topic], publisher_qos(playlist.qos[topic]))
            for topic, cls in playlist.classes.items()
        }
        if args.wait_for_subscribers > 0:
            wait_for_subscribers(node, publishers, args.wait_for_subscribers)
        played = 0
        while rclpy.ok():
            wall0 = time.monotonic()
            for topic, log_time, raw in playlist.messages:
                if log_time < playlist.start:
                    continue
                due = wall0 + (log_time - playlist.start) * 1e-9 / args.rate
                while rclpy.ok() and (wait := due - time.monotonic()) > 0:
                    time.sleep(min(wait, MAX_SLEEP))
                if not rclpy.ok():
                    break
                publishers[topic].publish(raw)
                played += 1
            if not args.loop:
                break
        for publisher in publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT))
        print(f"{NAME}: published {played} messages on {len(publishers)} topics", file=sys.stderr)
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def main(argv: Sequence[str] | None = None) -> int:
    return guarded(NAME, replay, argv)


if __name__ == "__main__":
    raise SystemExit(main())
