"""mk_record: topics into a rosbag2 bag (mcap by default), from raw subscriptions, flushed as it goes.

    mk_record [-o BAG] [-s mcap|sqlite3] [--overwrite] [--topics T ...] [--type T:=pkg/msg/Type ...]
              [--duration S] [--flush-interval S] [--visuals [PARAMS ...]] [--frame-prefix NS:=PREFIX ...]
              [--root-frame FRAME] [--ros-args ...]

Default topics: every topic of the registered machines' nodes (``Machine.topics``). Topic names,
relative or absolute, are resolved in the recorder's namespace (``--ros-args -r __ns:=/machine1``)
and remappings. The bag is open from the start; the graph is looked at every
``DISCOVERY_PERIOD`` s and a topic is subscribed to as soon as a publisher of it appears, with one
line saying its name, type and QoS. Its type is the one given with ``--type``, else the one its
publishers show, else the package's own type for that topic. Messages are stored as received (raw
CDR) at the time the recorder takes them. The bag is flushed every ``--flush-interval`` s, so
SIGKILL loses at most that much (see docs/bags.md). Spun by
:func:`manipulator_kinematics.executor.spin` (``MK_EXECUTOR``); on SIGINT/SIGTERM it stores what
is still queued and then ends.
"""

from __future__ import annotations

import argparse
import importlib
import math
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

import rclpy
from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from manipulator_kinematics import stopping
from manipulator_kinematics.bag.cli import guarded, parse_assignments, split_ros_args
from manipulator_kinematics.bag.topics import SETTINGS_KEY, encode_recorded_settings, package_topics
from manipulator_kinematics.bag.types import BagError, TopicQos
from manipulator_kinematics.bag.writer import STORAGES, BagWriter
from manipulator_kinematics.executor import ERROR_LOG_PERIOD, executor_name, spin
from manipulator_kinematics.executor import guarded as guarded_callback
from manipulator_kinematics.param_files import ConfigError, unflatten
from manipulator_kinematics.throttle import ThrottledLog

NAME = "mk_record"
# Subscriber queue: 1 s of a 1 kHz topic, so a stall of the recorder's thread loses nothing.
QUEUE_DEPTH = 1000
# How often the graph is looked at for publishers of topics not yet recorded (s).
DISCOVERY_PERIOD = 0.2
STOP_LATENCY = 0.1
DRAIN_LIMIT = 1.0
# How long the recorder waits for a publishing node's parameter services (s): a node that offers
# none (not an rclpy/rclcpp node, or started with parameter services off) is not waited for.
SETTINGS_TIMEOUT = 10.0
# rmw's node name of an endpoint whose participant's node list has not been discovered yet.
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


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


def describe_qos(qos: QoSProfile) -> str:
    reliability = "reliable" if qos.reliability == ReliabilityPolicy.RELIABLE else "best effort"
    durability = "transient local" if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL else "volatile"
    return f"{reliability}, {durability}, depth {qos.depth}"


def resolve(node: Node, name: str) -> str:
    """``name`` (relative, absolute or ``~/``) as the absolute topic name it means for ``node``;
    BagError for a name that is not a topic name."""
    try:
        return node.resolve_topic_name(name)
    except RuntimeError as error:  # rclpy's RCLError: "failed to resolve name: <why>, at <file>"
        why = str(error).removeprefix("failed to resolve name: ").split(", at ")[0]
        raise BagError(f"{name!r} is not a topic name: {why}") from None


def say(text: str) -> None:
    print(f"{NAME}: {text}", file=sys.stderr, flush=True)


class Recorder:
    """Subscribes to each wanted topic once a publisher of it is in the graph and stores whatever
    arrives (raw CDR), until stopped.

    Subscribing only to a topic that already has a publisher in the graph also means the reader
    matches that publisher when it is created, before the publisher can see the reader: a
    publisher that waits for a subscriber before sending loses nothing (the start-up note in
    docs/bags.md). Record time is the time the message is handed to its callback: the DDS
    reception time is only in the message info, which EventsExecutor cannot pass (see
    manipulator_kinematics.executor).
    """

    def __init__(
        self, node: Node, writer: BagWriter, wanted: Mapping[str, str | None], fallback: Mapping[str, str]
    ) -> None:
        """``wanted``: resolved topic -> the type given for it or None; ``fallback``: the package's
        type of a topic, used when its publishers disagree."""
        self.node, self.writer = node, writer
        self.wanted, self.fallback = dict(wanted), dict(fallback)
        self.counts: dict[str, int] = {}
        self.refused: set[str] = set()
        # Per recorded topic: its subscription, the profile it was made with, its message class.
        self._subscriptions: dict[str, tuple[Any, QoSProfile, type]] = {}
        self._log = ThrottledLog(node, ERROR_LOG_PERIOD)
        self._counted = -1
        self._stopped_at: float | None = None
        #: Full node name -> its parameters (nested), of every node that publishes a recorded topic.
        self.settings: dict[str, dict] = {}
        # Nodes whose parameters are still to be asked for: full name -> when first seen.
        self._asking: dict[str, float | None] = {}
        self._clients: dict[str, Any] = {}
        # Done callbacks of service calls run in the executor, outside executor.spin's guard.
        self._on_listed = guarded_callback(self._listed, self._log, "a node's parameter names")
        self._on_got = guarded_callback(self._got, self._log, "a node's parameters")

    def pending(self) -> list[str]:
        return [t for t in self.wanted if t not in self.counts and t not in self.refused]

    def discover(self) -> None:
        """Subscribe to every pending topic that has a publisher now, and widen a subscription a
        new publisher cannot serve (the discovery timer)."""
        self.widen()
        pending = self.pending()
        if not pending:
            return
        graph = dict(self.node.get_topic_names_and_types())
        for topic in pending:
            if topic not in graph or not self.node.count_publishers(topic):
                continue
            shown = graph[topic]
            msgtype = self.wanted[topic] or (shown[0] if len(shown) == 1 else None)
            if msgtype is None and self.fallback.get(topic) in shown:
                msgtype = self.fallback[topic]
            if msgtype is None:
                self.refused.add(topic)
                say(
                    f"not recording {topic}: it has the types {', '.join(shown)}; give one with "
                    f"--type {topic}:=pkg/msg/Type"
                )
                continue
            try:
                self.subscribe(topic, msgtype, offered_qos(self.node, topic))
            except BagError as error:
                self.refused.add(topic)
                say(f"not recording {topic}: {' '.join(str(error).split())}")

    def ask_settings(self) -> None:
        """Ask every node that publishes a recorded topic for its parameters, once; store them in
        the bag's metadata (``custom_data[SETTINGS_KEY]``) when they come (the discovery timer).

        Asked of the nodes, not read from params files: their launch may have used any files and
        ``-p`` overrides. In ``custom_data``, which rosbag2 (``StorageOptions.custom_data``) and
        rosbags keep: a topic would be published again by every replay."""
        for topic in self.counts:
            for info in self.node.get_publishers_info_by_topic(topic):
                if info.node_name == UNKNOWN_NODE:
                    continue  # its participant's node names are not discovered yet: next time
                name = f"{info.node_namespace.rstrip('/')}/{info.node_name}"
                if name not in self.settings and name not in self._asking:
                    self._asking[name] = time.monotonic()
        for name, since in list(self._asking.items()):
            if since is None:
                continue  # answer pending
            lister = self._client(ListParameters, f"{name}/list_parameters")
            # Both services matched first: a request to an unmatched server can be lost.
            getter = self._client(GetParameters, f"{name}/get_parameters")
            if not (lister.service_is_ready() and getter.service_is_ready()):
                if time.monotonic() - since > SETTINGS_TIMEOUT:
                    del self._asking[name]
                    say(f"{name} offers no parameter services: its settings are not in the bag")
                continue
            self._asking[name] = None
            lister.call_async(ListParameters.Request()).add_done_callback(
                lambda future, name=name: self._on_listed(name, future.result())
            )

    def _client(self, kind: type, service: str) -> Any:
        if service not in self._clients:
            self._clients[service] = self.node.create_client(kind, service)
        return self._clients[service]

    def _listed(self, name: str, response: Any) -> None:
        names = list(response.result.names) if response is not None else []
        getter = self._client(GetParameters, f"{name}/get_parameters")
        future = getter.call_async(GetParameters.Request(names=names))
        future.add_done_callback(lambda done: self._on_got(name, names, done.result()))

    def _got(self, name: str, names: list[str], response: Any) -> None:
        values = [] if response is None else [parameter_value_to_python(v) for v in response.values]
        # Array parameters come as array.array or lists: JSON takes lists.
        flat = {
            key: v if isinstance(v, (str, bool, int, float)) or v is None else list(v)
            for key, v in zip(names, values)
        }
        self.settings[name] = unflatten(flat)
        self._asking.pop(name, None)
        self.writer.set_custom_data(SETTINGS_KEY, encode_recorded_settings(self.settings))
        say(f"stored the {len(flat)} parameters of {name} in the bag's metadata")

    def subscribe(self, topic: str, msgtype: str, offered: Sequence[TopicQos]) -> None:
        msg_class = message_class(msgtype)
        self.writer.add_topic(topic, msgtype, offered[0] if offered else None)
        self.counts[topic] = 0
        qos = subscription_qos(offered)
        self._create(topic, msg_class, qos)
        say(f"recording {topic} [{msgtype}] ({describe_qos(qos)}; {len(offered)} publishers)")

    def _create(self, topic: str, msg_class: type, qos: QoSProfile) -> None:
        clock, write, counts = self.node.get_clock(), self.writer.write, self.counts

        def store(raw: bytes) -> None:
            write(topic, clock.now().nanoseconds, raw)
            counts[topic] += 1

        # Created while spinning: executor.spin's guard does not reach it, so it is guarded here.
        callback = guarded_callback(store, self._log, f"subscription to {topic}")
        subscription = self.node.create_subscription(msg_class, topic, callback, qos, raw=True)
        self._subscriptions[topic] = (subscription, qos, msg_class)

    def widen(self) -> None:
        """A reliable reader matches no best-effort writer, a transient-local reader no volatile
        one: a topic subscribed while only reliable or transient-local publishers were in the
        graph (a latched one, or one left over from a run that just ended) would record nothing of
        a publisher that appears later and offers less. Such a subscription is made again with a
        profile every publisher now matches."""
        for topic, (subscription, qos, msg_class) in list(self._subscriptions.items()):
            offered = offered_qos(self.node, topic)
            wider = subscription_qos(offered)
            unmatched = (
                qos.reliability == ReliabilityPolicy.RELIABLE and wider.reliability != qos.reliability
            ) or (qos.durability == DurabilityPolicy.TRANSIENT_LOCAL and wider.durability != qos.durability)
            if not offered or not unmatched:
                continue
            self.node.destroy_subscription(subscription)
            self._create(topic, msg_class, wider)
            say(
                f"recording {topic} now {describe_qos(wider)}: a publisher offers less than "
                f"{describe_qos(qos)}"
            )

    def run(self, duration: float | None, stop: threading.Event, executor: str) -> None:
        """Record for ``duration`` s (None: until ``stop`` is set), then take what is still queued
        (at most ``DRAIN_LIMIT`` s more)."""
        end = math.inf if duration is None else time.monotonic() + duration
        self.node.create_timer(self.writer.flush_interval, self.writer.flush_if_due)
        self.discover()
        self.node.create_timer(DISCOVERY_PERIOD, self.discover)
        self.node.create_timer(DISCOVERY_PERIOD, self.ask_settings)

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
        help="type of a topic, e.g. /scan:=sensor_msgs/msg/LaserScan (default: what its publishers show)",
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
        "--frame-prefix",
        nargs="+",
        default=[],
        metavar="NS:=PREFIX",
        help="with --visuals: the frame prefix of the machine in namespace NS, e.g. /m1:=m1/ (as its "
        "nodes' frame_prefix; default: none for one machine, <ns>_<machine>/ for several)",
    )
    parser.add_argument(
        "--root-frame",
        default="",
        metavar="FRAME",
        help="with --visuals: a static identity transform FRAME -> each machine's base "
        "frame (several machines in one TF tree)",
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
    prefixes = parse_assignments(args.frame_prefix, "--frame-prefix")  # refused before recording
    try:
        executor = executor_name()
    except ConfigError as error:
        raise BagError(str(error)) from None

    # No handlers from rclpy: those shut the context down at once, losing what is still queued.
    # A signal (SIGTERM too: what launch and test harnesses send) only sets ``stop``, whatever the
    # recorder is doing (manipulator_kinematics.stopping), and the recording then ends itself.
    stopping.hold()
    rclpy.init(args=[NAME, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    stopping.on_request(stop.set)
    node = Node("bag_recorder")
    writer: BagWriter | None = None
    try:
        own = package_topics()
        # Relative and absolute names alike: "joint_states", "/joint_states" and, in namespace /m1,
        # "/m1/joint_states" are one topic.
        wanted = {resolve(node, name): None for name in args.topics or own}
        for name, msgtype in given.items():
            topic = resolve(node, name)
            if topic not in wanted:
                raise BagError(f"--type {name}:={msgtype}: {topic} is not a recorded topic")
            message_class(msgtype)  # an unknown type is an error now, not when its topic appears
            wanted[topic] = msgtype
        fallback = {resolve(node, name): msgtype for name, msgtype in own.items()}
        writer = BagWriter(output, args.storage, overwrite=args.overwrite, flush_interval=args.flush_interval)
        recorder = Recorder(node, writer, wanted, fallback)
        say(
            f"writing {output} ({args.storage}); each of {len(wanted)} topics is recorded from when a "
            f"publisher of it appears: {', '.join(wanted)}"
        )
        recorder.run(args.duration, stop, executor)
        writer.close()
        absent = recorder.pending()
        if absent:
            say(f"no publisher of {', '.join(absent)} appeared: not in the bag")
        total = sum(recorder.counts.values())
        say(f"{total} messages on {len(recorder.counts)} topics in {output}")
        if args.visuals is not None:
            add_visuals_to_recording(output, args.visuals, prefixes, args.root_frame)
        return 0
    finally:
        if writer is not None:
            writer.close()
        node.destroy_node()
        rclpy.try_shutdown()


def add_visuals_to_recording(
    output: Path, params: Sequence[Path], frame_prefix: dict[str, str] | None = None, root_frame: str = ""
) -> None:
    """``--visuals``: the recorded bag rewritten with its visual topics (the recording stays as it
    is when that fails)."""
    from manipulator_kinematics.bag.visual import add_visuals  # URDF and scene code: only when asked

    try:
        added = add_visuals(output, output, params=params, frame_prefix=frame_prefix, root_frame=root_frame)
    except BagError as error:
        raise BagError(f"{output} is recorded, but no visual topics were added: {error}") from None
    for item in added:
        say(f"added {', '.join(item.topics)} for {item.machine} ({item.states} states) in {item.namespace}")


def main(argv: Sequence[str] | None = None) -> int:
    return guarded(NAME, record, argv)


if __name__ == "__main__":
    raise SystemExit(main())
