"""End-to-end latency, drops and CPU of excavator_forward (and the serial machines' forward nodes)
across processes, beside a bare echo node, on each executor a node can spin
(manipulator_kinematics.executor.EXECUTORS).

    python benchmarks/bench_excavator_latency.py [--duration 30] [--rates 100 1000] [--depth 100]
                                                 [--rounds 3] [--executors events single]
                                                 [--nodes excavator_forward scara_forward ...]
                                                 [--node-depth N]

For each input rate and executor two nodes run in turn, each as its own process started the way
the console scripts run (``node_util.run``, executor chosen with ``MK_EXECUTOR``): the echo node
(JointState in -> TwistStamped out with the input's stamp, no math: the transport floor) and
excavator_forward. A publisher process sends ``cylinder_lengths`` at the rate (and
``joint_states`` at 100 Hz, a typical swing encoder) and this process receives ``bucket_twist``;
latency = receive time - input stamp (one clock), drops = inputs without an output, CPU = the
node process's user + system time while the publisher sends, per input message. The target
compares excavator_forward with the echo on the same executor, so the ratio is the cost of the
kinematics, not of the executor. The measuring process uses EventsExecutor so that it is not the
bottleneck. Every queue is reliable keep-last of ``--depth`` (default 100: 100 ms of 1 kHz input
survives a stall). Each node is stopped with SIGINT after its row; its exit status is in the
table. This machine's speed drifts over minutes, so all of it runs in ``--rounds`` rounds and
each p99 is compared with the echo's of its own round and executor; the result is the median
ratio. Prints a table.

``--nodes`` adds the forward nodes of the serial machines (``scara_forward``, ...; default: only
excavator_forward): each gets ``joint_states`` (its joints at mid-range, with rates) remapped
from ``cylinder_lengths`` and its ``tool_twist`` remapped to ``bucket_twist``, so the publisher
and this process stay the same. Nodes run with their configured ``qos_depth`` unless
``--node-depth`` is given (the table says which).
"""

from __future__ import annotations

import argparse
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
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator
from excavator_kinematics.demo.demo import node_command
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics.executor import ENVIRONMENT, EXECUTORS
from manipulator_kinematics.node_util import console_script, make_node, run

ECHO = "echo"
FORWARD = "excavator_forward"
# The serial machines' forward nodes (manipulator_kinematics.nodes.forward), by machine.
SERIAL = {
    "scara_forward": "scara",
    "tool_changer_forward": "tool_changer",
    "palletizer_forward": "palletizer",
    "pump_boom_forward": "pump_boom",
}


def echo(depth: int) -> int:
    """The transport floor: republish each JointState's stamp as a TwistStamped."""

    def build() -> Node:
        node = make_node("bench_echo")
        qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        pub = node.create_publisher(TwistStamped, "bucket_twist", qos)
        out = TwistStamped()

        def on_message(msg: JointState) -> None:
            out.header.stamp = msg.header.stamp
            pub.publish(out)

        node.create_subscription(JointState, "cylinder_lengths", on_message, qos)
        return node

    return run(build, [sys.argv[0]])


def serial_state(machine_name: str) -> JointState:
    """A joint state of a serial machine: every joint at mid-range, moving."""
    from manipulator_kinematics.registry import machine

    spec = machine(machine_name)
    model = spec.model()
    limits = spec.limits(model)
    middle = (0.5 * (limits.lower + limits.upper)).tolist()
    names = list(spec.joint_names(model))
    return JointState(name=names, position=middle, velocity=[0.01 * (i + 1) for i in range(len(names))])


def publish(rate: float, duration: float, depth: int, sent_file: Path, kind: str) -> None:
    """Publish cylinder_lengths at ``rate`` (joint_states at 100 Hz) for ``duration`` s after a 1 s
    warm-up, paced by the clock; the stamps of the measured messages go to ``sent_file``. For a
    serial forward node (``kind`` in SERIAL) the cylinder_lengths messages are its joint states."""
    swing_listened = kind == FORWARD
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
    if kind in SERIAL:
        cylinder_msg = serial_state(SERIAL[kind])
        first = cylinder_msg.position[0]
    else:
        cylinder_msg = message_codec.joint_state(
            clock.now().to_msg(), CYLINDERS, reference[1:], [0.01, -0.02, 0.015]
        )
        first = reference[1]
    swing_msg = message_codec.joint_state(clock.now().to_msg(), JOINTS[:1], [0.0], [0.0])
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
        cylinder_msg.position[0] = first + 1e-6 * (n % 1000)
        cylinders.publish(cylinder_msg)
        if n >= warm_up:
            sent.append(message_codec.stamp_ns(stamp))
    np.save(sent_file, np.array(sent, dtype=np.int64))
    # The participant must not go while a stalled subscriber still lacks messages: they would be lost.
    for publisher in (cylinders, swing):
        publisher.wait_for_all_acked(Duration(seconds=10.0))
    node.destroy_node()
    rclpy.shutdown()


def start_node(kind: str, executor: str, depth: int, node_depth: int | None, work: Path) -> subprocess.Popen:
    """The node under test; a forward node keeps its configured qos_depth when ``node_depth`` is None."""
    overrides = work / "bench_params.yaml"
    # reliable like the echo's queue (the nodes' default input_reliability is best_effort)
    settings = {"input_reliability": "reliable", **({} if node_depth is None else {"qos_depth": node_depth})}
    overrides.write_text(yaml.safe_dump({f"/**/{kind}": {"ros__parameters": settings}}))
    if kind == ECHO:
        command = [sys.executable, __file__, "--echo", "--depth", str(depth)]
    elif kind in SERIAL:
        command = [
            console_script(kind),
            "--ros-args",
            "-r",
            "joint_states:=cylinder_lengths",
            "-r",
            "tool_twist:=bucket_twist",
            "--params-file",
            str(overrides),
        ]
    else:
        command = node_command(FORWARD, overrides)
    log = (work / "node.log").open("w")
    return subprocess.Popen(
        command, stdout=log, stderr=subprocess.STDOUT, env={**os.environ, ENVIRONMENT: executor}
    )


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a running process so far (Linux)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(
    node: Node,
    kind: str,
    executor_name: str,
    rate: float,
    duration: float,
    depth: int,
    node_depth: int | None,
    work: Path,
) -> dict[str, float]:
    """Start the node under test and a publisher process; receive bucket_twist here."""
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    received: dict[int, int] = {}
    clock = node.get_clock()
    sub = node.create_subscription(
        TwistStamped,
        "bucket_twist",
        lambda m: received.setdefault(message_codec.stamp_ns(m.header.stamp), clock.now().nanoseconds),
        qos,
    )
    # The measuring end must not be the bottleneck: rclpy's SingleThreadedExecutor costs a few
    # hundred microseconds per message here, EventsExecutor (spun in this, the main thread) far less.
    executor = EventsExecutor()
    executor.add_node(node)
    under_test = start_node(kind, executor_name, depth, node_depth, work)
    sent_file = work / "bench_sent.npy"
    try:
        deadline = time.monotonic() + 20.0
        while node.count_publishers("bucket_twist") == 0:
            if time.monotonic() > deadline:
                raise RuntimeError(f"{kind} did not show up")
            executor.spin_once(timeout_sec=0.05)
        cpu_before = cpu_seconds(under_test.pid)
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
                "--kind",
                kind,
            ]
        )
        while publisher.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        cpu = cpu_seconds(under_test.pid) - cpu_before
        if publisher.returncode != 0:
            raise RuntimeError(f"publisher failed ({publisher.returncode})")
        sent = np.load(sent_file)
        drain = time.monotonic() + 2.0
        while time.monotonic() < drain and not all(int(s) in received for s in sent[-5:]):
            executor.spin_once(timeout_sec=0.01)
    finally:
        under_test.send_signal(signal.SIGINT)
        exit_status = under_test.wait(10)
        executor.remove_node(node)
        node.destroy_subscription(sub)
    latencies = np.array([received[s] - s for s in sent.tolist() if s in received]) * 1e-6
    return {
        "sent": len(sent),
        "dropped": len(sent) - len(latencies),
        "p50": float(np.percentile(latencies, 50)),
        "p99": float(np.percentile(latencies, 99)),
        "max": float(latencies.max()),
        "cpu_ms": cpu / (duration * rate + rate) * 1e3,  # the warm-up second's messages count too
        "exit": exit_status,
        # A rejected input is a drop too; the node's log says why (throttled: one line per kind per 2 s).
        "complaints": [line for line in (work / "node.log").read_text().splitlines() if "[INFO]" not in line],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=30.0, help="seconds per measurement")
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 1000.0])
    parser.add_argument("--depth", type=int, default=100, help="reliable keep-last queue depth")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of all nodes and rates")
    parser.add_argument("--executors", nargs="+", choices=sorted(EXECUTORS), default=list(EXECUTORS))
    parser.add_argument("--echo", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--publish", nargs=3, metavar=("RATE", "DURATION", "FILE"), help=argparse.SUPPRESS)
    parser.add_argument(
        "--nodes",
        nargs="+",
        choices=[FORWARD, *SERIAL],
        default=[FORWARD],
        help="forward nodes to measure, each beside the echo",
    )
    parser.add_argument("--node-depth", type=int, help="qos_depth of the nodes (default: as configured)")
    parser.add_argument("--kind", default=FORWARD, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        return echo(args.depth)
    if args.publish:
        rate, duration, sent_file = args.publish
        publish(float(rate), float(duration), args.depth, Path(sent_file), args.kind)
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
                for name in args.executors:
                    for kind in (ECHO, *args.nodes):
                        result = measure(
                            node, kind, name, rate, args.duration, args.depth, args.node_depth, work
                        )
                        rows.append((round_, kind, name, rate, result))
                        done = f"round {round_ + 1}: {kind:<20} {name:<6} {rate:6.0f} Hz  done"
                        print(done, file=sys.stderr, flush=True)
    finally:
        node.destroy_node()
        rclpy.shutdown()
    depths = "as configured" if args.node_depth is None else str(args.node_depth)
    print(
        f"\nend-to-end latency, input stamp -> bucket_twist (tool_twist) received, {args.duration:g} s "
        f"per row, reliable depth {args.depth} (nodes: {depths}), {args.rounds} round(s); CPU of the node "
        "per input message"
    )
    print(
        f"{'round':<6} {'node':<20} {'executor':<9} {'rate':>7} {'sent':>7} {'dropped':>8} {'p50 ms':>8} "
        f"{'p99 ms':>8} {'max ms':>8} {'CPU ms':>7} {'exit':>5}"
    )
    for round_, kind, name, rate, r in rows:
        print(
            f"{round_ + 1:<6} {kind:<20} {name:<9} {rate:5.0f}Hz {r['sent']:7d} {r['dropped']:8d} "
            f"{r['p50']:8.3f} {r['p99']:8.3f} {r['max']:8.2f} {r['cpu_ms']:7.3f} {r['exit']:5d}"
        )
        for line in r["complaints"][:3]:
            print(f"       {kind} said: {line}")
    results = {(round_, kind, name, rate): r for round_, kind, name, rate, r in rows}
    print()
    for rate in args.rates:
        for name in args.executors:
            echoes = [results[i, ECHO, name, rate] for i in range(args.rounds)]
            for kind in args.nodes:
                forward = [results[i, kind, name, rate] for i in range(args.rounds)]
                ratios = [f["p99"] / e["p99"] for f, e in zip(forward, echoes)]
                drops = [f["dropped"] for f in forward]
                print(
                    f"{rate:5.0f} Hz {name:<6} {kind:<20}: p99 / echo p99 = {statistics.median(ratios):.2f} "
                    f"median of [{', '.join(f'{x:.2f}' for x in ratios)}]; drops "
                    f"{statistics.median(drops):g} median of {drops}; CPU ms/msg "
                    f"{statistics.median(f['cpu_ms'] for f in forward):.3f}, "
                    f"echo {statistics.median(e['cpu_ms'] for e in echoes):.3f}"
                )
    print("targets: forward p99 <= 1.5 x echo p99 on the same executor; 0 drops at 1 kHz (median of rounds)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
