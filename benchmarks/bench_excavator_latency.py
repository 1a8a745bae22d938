"""End-to-end latency and drops of excavator_forward across processes, beside a bare echo node.

    python benchmarks/bench_excavator_latency.py [--duration 30] [--rates 100 1000] [--depth 100] [--rounds 3]

For each input rate three nodes run in turn, each as its own process: the echo node (JointState in
-> TwistStamped out with the input's stamp, no math: the transport floor) spun by rclpy's
SingleThreadedExecutor (``rclpy.spin``, what a plain rclpy node does), the same echo node spun by
:func:`manipulator_kinematics.spin.spin` (what our nodes use), and excavator_forward. A publisher
process sends ``cylinder_lengths`` at the rate (and ``joint_states`` at 100 Hz, a typical swing
encoder) and this process receives ``bucket_twist``; latency = receive time - input stamp (one
clock), drops = inputs without an output. The target compares excavator_forward with the echo on
the same spin, so the ratio is the cost of the kinematics, not of the executor. The measuring
process uses EventsExecutor so that it is not the bottleneck. Every queue is reliable keep-last of
``--depth`` (default 100: 100 ms of 1 kHz input survives a stall). This machine's speed drifts
over minutes, so all of it runs in ``--rounds`` rounds and each p99 is compared with the echo's
of its own round; the result is the median ratio. Prints a table.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rclpy
import yaml
from geometry_msgs.msg import TwistStamped
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from excavator_kinematics import messages
from excavator_kinematics.demo import node_command
from excavator_kinematics.kinematics import CYLINDERS, JOINTS, Excavator
from manipulator_kinematics.spin import spin

# Echo node rows of the table, and the executor each one spins.
ECHOES = {"echo, rclpy.spin": "rclpy", "echo, spin()": "spin"}
FORWARD = "excavator_forward"


def echo(depth: int, executor: str) -> None:
    """The transport floor: republish each JointState's stamp as a TwistStamped."""
    rclpy.init()
    node = Node("bench_echo")
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(TwistStamped, "bucket_twist", qos)
    out = TwistStamped()

    def on_message(msg: JointState) -> None:
        out.header.stamp = msg.header.stamp
        pub.publish(out)

    node.create_subscription(JointState, "cylinder_lengths", on_message, qos)
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        if executor == "rclpy":
            rclpy.spin(node)
        else:
            spin(node)
    rclpy.try_shutdown()


def publish(rate: float, duration: float, depth: int, sent_file: Path, swing_listened: bool) -> None:
    """Publish cylinder_lengths at ``rate`` (joint_states at 100 Hz) for ``duration`` s after a 1 s
    warm-up, paced by the clock; the stamps of the measured messages go to ``sent_file``."""
    rclpy.init()
    node = Node("bench_publisher")
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    cylinders = node.create_publisher(JointState, "cylinder_lengths", qos)
    swing = node.create_publisher(JointState, "joint_states", qos)
    deadline = time.monotonic() + 20.0
    # Both topics matched before the first message (the echo node does not listen to joint_states):
    # excavator_forward rejects cylinder states until it has a swing state.
    while cylinders.get_subscription_count() == 0 or (swing_listened and swing.get_subscription_count() == 0):
        if time.monotonic() > deadline:
            raise RuntimeError("no subscriber for cylinder_lengths (or joint_states)")
        time.sleep(0.01)
    clock = node.get_clock()
    reference = Excavator.default().limits.reference
    cylinder_msg = messages.joint_state(clock.now().to_msg(), CYLINDERS, reference[1:], [0.01, -0.02, 0.015])
    swing_msg = messages.joint_state(clock.now().to_msg(), JOINTS[:1], [0.0], [0.0])
    swing_every = max(1, round(rate / 100.0))
    sent = []
    warm_up = int(rate)
    start = time.monotonic()
    for n in range(warm_up + int(duration * rate)):
        pause = start + n / rate - time.monotonic()
        if pause > 0:
            time.sleep(pause)
        stamp = clock.now().to_msg()
        if n % swing_every == 0:
            swing_msg.header.stamp = stamp
            swing.publish(swing_msg)
        cylinder_msg.header.stamp = stamp
        cylinder_msg.position[0] = reference[1] + 1e-6 * (n % 1000)
        cylinders.publish(cylinder_msg)
        if n >= warm_up:
            sent.append(messages.stamp_ns(stamp))
    np.save(sent_file, np.array(sent, dtype=np.int64))
    # The participant must not go while a stalled subscriber still lacks messages: they would be lost.
    for publisher in (cylinders, swing):
        publisher.wait_for_all_acked(Duration(seconds=10.0))
    node.destroy_node()
    rclpy.shutdown()


def start_node(kind: str, depth: int, work: Path) -> subprocess.Popen:
    if kind in ECHOES:
        command = [sys.executable, __file__, "--echo", ECHOES[kind], "--depth", str(depth)]
    else:
        overrides = work / "bench_params.yaml"
        overrides.write_text(
            yaml.safe_dump({"/**/excavator_forward": {"ros__parameters": {"qos_depth": depth}}})
        )
        command = node_command(FORWARD, overrides)
    log = (work / "node.log").open("w")
    return subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)


def measure(node: Node, kind: str, rate: float, duration: float, depth: int, work: Path) -> dict[str, float]:
    """Start the node under test and a publisher process; receive bucket_twist here."""
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    received: dict[int, int] = {}
    clock = node.get_clock()
    sub = node.create_subscription(
        TwistStamped,
        "bucket_twist",
        lambda m: received.setdefault(messages.stamp_ns(m.header.stamp), clock.now().nanoseconds),
        qos,
    )
    # The measuring end must not be the bottleneck: rclpy's SingleThreadedExecutor costs a few
    # hundred microseconds per message here, EventsExecutor (spun in this, the main thread) far less.
    executor = EventsExecutor()
    executor.add_node(node)
    under_test = start_node(kind, depth, work)
    sent_file = work / "bench_sent.npy"
    try:
        deadline = time.monotonic() + 20.0
        while node.count_publishers("bucket_twist") == 0:
            if time.monotonic() > deadline:
                raise RuntimeError(f"{kind} did not show up")
            executor.spin_once(timeout_sec=0.05)
        publisher = subprocess.Popen(
            [
                sys.executable,
                __file__,
                "--publish",
                str(rate),
                str(duration),
                str(sent_file),
                "--depth",
                str(depth),
                *(["--swing-listened"] if kind == FORWARD else []),
            ]
        )
        while publisher.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        if publisher.returncode != 0:
            raise RuntimeError(f"publisher failed ({publisher.returncode})")
        sent = np.load(sent_file)
        drain = time.monotonic() + 2.0
        while time.monotonic() < drain and not all(int(s) in received for s in sent[-5:]):
            executor.spin_once(timeout_sec=0.01)
    finally:
        under_test.send_signal(signal.SIGINT)
        under_test.wait(10)
        executor.remove_node(node)
        node.destroy_subscription(sub)
    latencies = np.array([received[s] - s for s in sent.tolist() if s in received]) * 1e-6
    return {
        "sent": len(sent),
        "dropped": len(sent) - len(latencies),
        "p50": float(np.percentile(latencies, 50)),
        "p99": float(np.percentile(latencies, 99)),
        "max": float(latencies.max()),
        # A rejected input is a drop too; the node's log says why (throttled: one line per kind per 2 s).
        "complaints": [line for line in (work / "node.log").read_text().splitlines() if "[INFO]" not in line],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=30.0, help="seconds per measurement")
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 1000.0])
    parser.add_argument("--depth", type=int, default=100, help="reliable keep-last queue depth")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of all nodes and rates")
    parser.add_argument("--echo", choices=sorted(ECHOES.values()), help=argparse.SUPPRESS)
    parser.add_argument("--publish", nargs=3, metavar=("RATE", "DURATION", "FILE"), help=argparse.SUPPRESS)
    parser.add_argument("--swing-listened", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        echo(args.depth, args.echo)
        return 0
    if args.publish:
        rate, duration, sent_file = args.publish
        publish(float(rate), float(duration), args.depth, Path(sent_file), args.swing_listened)
        return 0
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    work = Path(tempfile.mkdtemp(prefix="bench_excavator_"))
    rclpy.init()
    node = Node("bench_excavator_latency")
    rows = []
    try:
        # Rounds of every node in turn: this machine's speed drifts over minutes, so a p99 is
        # compared with the echo's of the same round and the rounds' median ratio is the result.
        for round_ in range(args.rounds):
            for rate in args.rates:
                for kind in (*ECHOES, FORWARD):
                    result = measure(node, kind, rate, args.duration, args.depth, work)
                    rows.append((round_, kind, rate, result))
                    print(f"round {round_ + 1}: {kind:<17} {rate:6.0f} Hz  done", file=sys.stderr, flush=True)
    finally:
        node.destroy_node()
        rclpy.shutdown()
    print(
        f"\nend-to-end latency, input stamp -> bucket_twist received, {args.duration:g} s per row, "
        f"reliable depth {args.depth}, {args.rounds} round(s)"
    )
    print(
        f"{'round':<6} {'node':<17} {'rate':>7} {'sent':>7} {'dropped':>8} {'p50 ms':>8} {'p99 ms':>8} "
        f"{'max ms':>8}"
    )
    for round_, kind, rate, r in rows:
        print(
            f"{round_ + 1:<6} {kind:<17} {rate:5.0f}Hz {r['sent']:7d} {r['dropped']:8d} {r['p50']:8.3f} "
            f"{r['p99']:8.3f} {r['max']:8.2f}"
        )
        for line in r["complaints"][:3]:
            print(f"       {kind} said: {line}")
    p99 = {(round_, kind, rate): r["p99"] for round_, kind, rate, r in rows}
    print()
    for rate in args.rates:
        drops = sum(r["dropped"] for _, kind, q, r in rows if kind == FORWARD and q == rate)
        for kind in ECHOES:
            ratios = [p99[i, FORWARD, rate] / p99[i, kind, rate] for i in range(args.rounds)]
            print(
                f"{rate:5.0f} Hz: forward p99 / {kind} p99 = {statistics.median(ratios):.2f} median of "
                f"[{', '.join(f'{x:.2f}' for x in ratios)}]"
            )
        print(f"{rate:5.0f} Hz: forward drops {drops} in {args.rounds} x {args.duration:g} s")
    print("targets: forward p99 <= 1.5 x echo, spin() p99; 0 drops at 1 kHz")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
