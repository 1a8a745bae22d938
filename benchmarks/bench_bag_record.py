"""Benchmark: message loss of the `mk_record` command at 1 kHz for 60 s.

    python benchmarks/bench_bag_record.py [--rate 1000] [--seconds 60] [--topics 1] [--depth 100]
                                          [--storage mcap sqlite3]

For each storage, starts `mk_record` as its own process, publishes sensor_msgs/JointState at
``--rate`` Hz on each of ``--topics`` topics from this process (reliable, history ``--depth``,
default 100 as the package's nodes have it; a sequence number in position[0]), stops the
recorder with SIGINT, reads the
bag back and counts lost and duplicated messages. Prints a table with the recorder's CPU use and
the latency from header stamp to record time. Exit status 1 if any message was lost.

Runs in ROS_DOMAIN_ID (default 57 here) with discovery limited to this machine.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("ROS_DOMAIN_ID", "57")
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from manipulator_kinematics.bag.reader import BagReader

# History of the publishers, as the package's nodes have it (qos_depth in config/excavator_nodes.yaml).
DEPTH = 100
MATCH_TIMEOUT = 30.0


def run_once(storage: str, rate: float, seconds: float, topics: int, depth: int, directory: Path) -> dict:
    bag = directory / f"bench_record_{storage}"
    names = [f"/bench_record_{i}" for i in range(topics)]
    # The publishers exist before the recorder, which subscribes to a topic once it sees a
    # publisher of it in the graph: its readers then match them as they are created. (A reader
    # created first is matched by the writer before it matches the writer, and what is sent in
    # between is lost: a DDS start-up race, not a recording loss.)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("bench_record_publisher", context=context)
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    publishers = [node.create_publisher(JointState, n, qos) for n in names]
    command = [
        sys.executable,
        "-m",
        "manipulator_kinematics.bag.record",
        "-o",
        str(bag),
        "-s",
        storage,
        "--topics",
        *names,
    ]
    recorder = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + MATCH_TIMEOUT
    while any(p.get_subscription_count() == 0 for p in publishers):
        if time.monotonic() > deadline or recorder.poll() is not None:
            raise RuntimeError(
                f"recorder did not subscribe: {recorder.communicate()[0] if recorder.poll() else ''}"
            )
        time.sleep(0.01)

    count = int(rate * seconds)
    message = JointState(
        name=["boom_cylinder", "arm_cylinder", "bucket_cylinder"],
        position=[0.0, 2.0, 3.0],
        velocity=[0.1, 0.2, 0.3],
    )
    clock = node.get_clock()
    late = 0.0
    start = time.monotonic()
    for k in range(count):
        due = start + k / rate
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        else:
            late = max(late, -wait)
        message.header.stamp = clock.now().to_msg()
        message.position[0] = float(k)
        for publisher in publishers:
            publisher.publish(message)
    elapsed = time.monotonic() - start
    for publisher in publishers:
        publisher.wait_for_all_acked(rclpy.duration.Duration(seconds=10))
    recorder.send_signal(signal.SIGINT)
    _, status, usage = os.wait4(recorder.pid, 0)
    recorder.returncode = os.waitstatus_to_exitcode(status)
    log = recorder.stdout.read()
    node.destroy_node()
    rclpy.shutdown(context=context)
    if recorder.returncode:
        print(f"recorder ({storage}) exited with {recorder.returncode}:\n{log}", file=sys.stderr)

    reader = BagReader(bag)
    lost = duplicated = 0
    latency, missing = [], []
    for arrays in reader.arrays(names).values():
        sequence = arrays["position"][:, 0].astype(np.int64)
        lost += count - len(np.unique(sequence))
        duplicated += len(sequence) - len(np.unique(sequence))
        missing += np.setdiff1d(np.arange(count), sequence).tolist()
        latency.append((arrays.log_time - arrays.stamp_ns()) * 1e-6)
    latency = np.concatenate(latency)
    size = sum(f.stat().st_size for f in bag.iterdir()) / 1e6
    return {
        "storage": storage,
        "topics": topics,
        "rate": rate,
        "published": count * topics,
        "recorded": reader.message_count,
        "lost": lost,
        "duplicated": duplicated,
        "publish_s": elapsed,
        "max_late_ms": late * 1e3,
        "latency_p50_ms": float(np.percentile(latency, 50)),
        "latency_p99_ms": float(np.percentile(latency, 99)),
        "latency_max_ms": float(latency.max()),
        "recorder_cpu": (usage.ru_utime + usage.ru_stime) / elapsed,
        "bag_mb": size,
        "exit": recorder.returncode,
        "lost_numbers": _ranges(sorted(set(missing))),
    }


def _ranges(numbers: list[int]) -> str:
    """[1, 2, 3, 7] -> "1-3,7" (at most 4 ranges)."""
    runs: list[list[int]] = []
    for n in numbers:
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    text = ",".join(f"{a}-{b}" if b > a else str(a) for a, b in runs[:4])
    return (text + ",...") if len(runs) > 4 else text or "-"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--topics", type=int, default=1)
    parser.add_argument("--depth", type=int, default=DEPTH, help="history depth of the publishers")
    parser.add_argument("--storage", nargs="+", default=["mcap", "sqlite3"], choices=["mcap", "sqlite3"])
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for storage in args.storage:
            rows.append(run_once(storage, args.rate, args.seconds, args.topics, args.depth, Path(tmp)))
    columns = [
        ("storage", "{}"),
        ("topics", "{}"),
        ("rate", "{:.0f}"),
        ("published", "{}"),
        ("recorded", "{}"),
        ("lost", "{}"),
        ("duplicated", "{}"),
        ("publish_s", "{:.2f}"),
        ("max_late_ms", "{:.1f}"),
        ("latency_p50_ms", "{:.2f}"),
        ("latency_p99_ms", "{:.2f}"),
        ("latency_max_ms", "{:.1f}"),
        ("recorder_cpu", "{:.0%}"),
        ("bag_mb", "{:.1f}"),
        ("exit", "{}"),
        ("lost_numbers", "{}"),
    ]
    cells = [[name for name, _ in columns]] + [
        [fmt.format(row[name]) for name, fmt in columns] for row in rows
    ]
    widths = [max(len(r[i]) for r in cells) for i in range(len(columns))]
    print(
        f"\nrecord at {args.rate:g} Hz x {args.topics} topic(s) for {args.seconds:g} s, publisher depth "
        f"{args.depth} (load average {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores)\n"
    )
    for i, row in enumerate(cells):
        print("  ".join(c.rjust(w) for c, w in zip(row, widths)))
        if i == 0:
            print("  ".join("-" * w for w in widths))
    return 0 if all(r["lost"] == 0 and r["exit"] == 0 for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
