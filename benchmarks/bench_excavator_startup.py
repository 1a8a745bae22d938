"""Start-up of excavator_forward: seconds from launching the process to its first bucket_pose,
with numba's cache warm (the state kernel loads from disk) and cold (an empty NUMBA_CACHE_DIR:
the kernel compiles), and what the background load costs the outputs of the first seconds.

    python benchmarks/bench_excavator_startup.py [--rounds 3] [--after 5] [--rate 200]

This process publishes ``cylinder_lengths`` and ``joint_states`` at ``--rate`` from before the
launch and receives ``bucket_pose``; per round and cache it prints the time to the first output
and, over the ``--after`` seconds that follow, the outputs received per input sent and the longest
gap between outputs (the kernel loads in a background thread while numpy answers). Runs in a ROS
domain of its own (the lock files of the test suite). Prints a table.
"""

from __future__ import annotations

import argparse
import itertools
import os
import signal
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import rclpy
import yaml
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator
from excavator_kinematics.demo.demo import node_command
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics.ros_domain import reserved_domain


def one_start(
    node: Node, executor: SingleThreadedExecutor, rate: float, after: float, cache: Path | None, work: Path
) -> dict[str, float]:
    """Launch the node (``cache``: its NUMBA_CACHE_DIR, None = the default, warm) and watch."""
    received: list[float] = []
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    sub = node.create_subscription(
        PoseStamped, "bucket_pose", lambda _: received.append(time.monotonic()), qos
    )
    overrides = work / "startup_params.yaml"
    overrides.write_text(
        yaml.safe_dump({"/**/excavator_forward": {"ros__parameters": {"input_reliability": "reliable"}}})
    )
    env = dict(os.environ, **({} if cache is None else {"NUMBA_CACHE_DIR": str(cache)}))
    start = time.monotonic()
    process = subprocess.Popen(
        node_command("excavator_forward", overrides),
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
    )
    try:
        while not received and time.monotonic() < start + 60.0:
            executor.spin_once(timeout_sec=0.001)
        first = received[0] if received else float("nan")
        end = first + after
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.001)
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(10)
        node.destroy_subscription(sub)
    gaps = [b - a for a, b in itertools.pairwise(received) if b <= end]
    return {
        "first": first - start,
        "outputs": sum(t <= end for t in received) / (after * rate),
        "gap": max(gaps, default=float("nan")),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--after", type=float, default=5.0, help="seconds watched after the first output")
    parser.add_argument("--rate", type=float, default=200.0, help="input messages per second")
    args = parser.parse_args()
    with reserved_domain() as domain, tempfile.TemporaryDirectory() as tmp:
        os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        rclpy.init()
        node = Node("bench_startup")
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        cylinders = node.create_publisher(JointState, "cylinder_lengths", qos)
        swing = node.create_publisher(JointState, "joint_states", qos)
        reference = Excavator.default().limits.reference
        clock = node.get_clock()

        def send() -> None:
            stamp = clock.now().to_msg()
            swing.publish(message_codec.joint_state(stamp, JOINTS[:1], [0.0], [0.0]))
            cylinders.publish(
                message_codec.joint_state(stamp, CYLINDERS, reference[1:], [0.01, -0.02, 0.015])
            )

        node.create_timer(1.0 / args.rate, send)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        rows: dict[str, list[dict[str, float]]] = {"warm": [], "cold": []}
        # The first launch of a run is slower whatever the node does (discovery of this process's
        # participant): not counted.
        one_start(node, executor, args.rate, 0.5, None, Path(tmp))
        for i in range(args.rounds):
            rows["warm"].append(one_start(node, executor, args.rate, args.after, None, Path(tmp)))
            cold = Path(tmp) / f"numba_cache_{i}"
            cold.mkdir()
            rows["cold"].append(one_start(node, executor, args.rate, args.after, cold, Path(tmp)))
        node.destroy_node()
        rclpy.shutdown()
    print(
        f"excavator_forward start-up, {args.rounds} rounds, inputs at {args.rate:g}/s, load {os.getloadavg()}"
    )
    print(
        f"{'numba cache':<12}{'first output s: median':>24}{'min':>7}{'max':>7}"
        f"{f'outputs/input in {args.after:g} s':>26}{'longest gap ms':>16}"
    )
    for cache, results in rows.items():
        firsts = [r["first"] for r in results]
        print(
            f"{cache:<12}{statistics.median(firsts):>24.3f}{min(firsts):>7.3f}{max(firsts):>7.3f}"
            f"{statistics.median(r['outputs'] for r in results):>26.3f}"
            f"{max(r['gap'] for r in results) * 1e3:>16.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
