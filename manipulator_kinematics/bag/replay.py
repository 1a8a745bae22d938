"""mk_replay: publish a bag's messages again with their recorded timing.

    mk_replay BAG [--rate R] [--loop] [--topics T ...] [--remap FROM:=TO ...] [--start-offset S]
           [--wait-for-subscribers S] [--recover] [--max-gap S] [--skip-gaps] [--ros-args ...]

Messages go out as recorded (raw CDR, header stamps untouched) on their recorded topic names,
or the names given with ``--remap`` (a relative target is resolved in the replayer's namespace).
Bag topics in ``--topics`` and on the left of ``--remap`` are named with or without the leading
slash (``joint_states`` is the bag's ``/joint_states``).
Message k is published ``(t_k - t_start) / rate`` seconds after the start, t being the record
time and t_start the first message's plus ``--start-offset``. Publishers use the recorded QoS
(reliability, durability) with a deep queue.

Record times are not trusted: a gap longer than ``--max-gap`` (default 10 s of record time)
between two played messages, one flipped byte of a time stamp for instance, refuses the bag
before anything is published (exit 1, one line); with ``--skip-gaps`` each such gap is cut out
(the next message goes out at once) and named in one line. SIGINT and SIGTERM end the replay
after the message being published, at any moment, with exit 0
(:mod:`manipulator_kinematics.stopping`).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from manipulator_kinematics import stopping
from manipulator_kinematics.bag.cli import guarded, parse_assignments, split_ros_args
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.record import QUEUE_DEPTH, message_class
from manipulator_kinematics.bag.types import BagError, TopicQos

NAME = "mk_replay"
# Longest single sleep, so Ctrl-C and shutdown are noticed during long pauses in a bag.
MAX_SLEEP = 0.1
ACK_TIMEOUT = 5.0
MATCH_SETTLE = 0.5
#: Longest gap between two played messages (record time, s) that is played as recorded.
MAX_GAP = 10.0


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
    parser.add_argument(
        "--max-gap",
        type=float,
        default=MAX_GAP,
        metavar="S",
        help=f"refuse a bag with more than S s between two messages (default {MAX_GAP:g}): a damaged stamp",
    )
    parser.add_argument(
        "--skip-gaps", action="store_true", help="play on across such a gap: the next message at once"
    )
    args = parser.parse_args(argv)
    if not args.max_gap > 0:
        parser.error(f"--max-gap must be positive, got {args.max_gap}")
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
    while not stopping.requested():
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
    t_start on, each topic with its message class, recorded QoS and published name; ``due``:
    when each message goes out, ns of record time after t_start (skipped gaps taken out)."""

    messages: list[tuple[str, int, bytes]]
    due: list[int]
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
    classes, unknown = {}, {}
    for topic in topics:
        try:
            classes[topic] = message_class(bag.topics[topic].msgtype)
        except BagError:
            unknown[topic] = bag.topics[topic].msgtype
    if unknown and args.topics is not None:
        raise BagError(f"cannot publish {_listed(unknown)}: no Python message module for its type here")
    if unknown:
        # The package's own bags carry /tf and /tf_static (tf2_msgs) for Foxglove, and rclpy can
        # publish only types whose generated Python module is installed: the rest still plays.
        print(
            f"{NAME}: skipping {_listed(unknown)}: no Python message module for its type here",
            file=sys.stderr,
        )
        topics = [topic for topic in topics if topic in classes]
        if not topics:
            raise BagError(f"{args.bag}: no topic of the bag has a type this ROS installation can publish")
    messages = list(bag.messages(topics))
    if not messages:
        raise BagError(f"{args.bag}: no messages to play on {', '.join(topics)}")
    start = messages[0][1] + int(args.start_offset * 1e9)
    if start > messages[-1][1]:
        raise BagError(
            f"--start-offset {args.start_offset:g} s is past the end of the selected messages "
            f"({(messages[-1][1] - messages[0][1]) * 1e-9:.3f} s)"
        )
    messages = [m for m in messages if m[1] >= start]
    return Playlist(
        messages,
        schedule(messages, start, args),
        classes,
        {topic: bag.topics[topic].qos for topic in topics},
        {topic: remap.get(topic, topic) for topic in topics},
    )


def _listed(topics: dict[str, str]) -> str:
    return ", ".join(f"{topic} [{msgtype}]" for topic, msgtype in topics.items())


def schedule(messages: Sequence[tuple[str, int, bytes]], start: int, args: argparse.Namespace) -> list[int]:
    """When each message goes out (ns of record time after ``start``): its record time, less every
    gap longer than ``--max-gap`` before it when ``--skip-gaps`` is given; BagError for such a gap
    without it."""
    limit, skipped, due = int(args.max_gap * 1e9), 0, []
    previous = start
    for index, (topic, log_time, _) in enumerate(messages):
        gap = log_time - previous
        if gap > limit:
            where = (
                f"{gap * 1e-9:.1f} s of record time without a message before message {index} "
                f"({topic}, record time {log_time} ns)"
            )
            if not args.skip_gaps:
                raise BagError(
                    f"{args.bag}: {where}, more than --max-gap {args.max_gap:g} s (a damaged "
                    "stamp?); --skip-gaps plays on across it"
                )
            print(f"{NAME}: skipping {where}", file=sys.stderr)
            skipped += gap
        due.append(log_time - start - skipped)
        previous = log_time
    return due


def replay(argv: Sequence[str]) -> int:
    ours, ros_args = split_ros_args(argv)
    args = parse_args(ours)
    playlist = load(args)

    # rclpy's handlers would shut the context down from their own thread, under a publish() in
    # progress (an RCLError): a signal is only recorded, and the loop ends after the message it
    # is publishing.
    stopping.hold()
    rclpy.init(args=[NAME, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = Node("bag_replay")
    try:
        publishers = {
            topic: node.create_publisher(cls, playlist.names[topic], publisher_qos(playlist.qos[topic]))
            for topic, cls in playlist.classes.items()
        }
        if args.wait_for_subscribers > 0:
            wait_for_subscribers(node, publishers, args.wait_for_subscribers)
        played = 0
        while not stopping.requested():
            wall0 = time.monotonic()
            for (topic, _, raw), due_ns in zip(playlist.messages, playlist.due):
                due = wall0 + due_ns * 1e-9 / args.rate
                while not stopping.requested() and (wait := due - time.monotonic()) > 0:
                    time.sleep(min(wait, MAX_SLEEP))
                if stopping.requested():
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
