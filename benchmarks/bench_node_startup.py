"""Benchmark (not a test): node start-up, from launch to the first output, of the SCARA's nodes.

Each round starts each node as a process and waits, as a client on an isolated ROS domain, for its
first output: ``scara_ik_server`` the first SolveIK answer (the request sent again every 50 ms
until one comes back; the first single IK call also starts loading the compiled kernel),
``scara_forward`` the first tool_pose for a joint_states message published every 10 ms. Times in
milliseconds from the start of the process, the median of the rounds (min and max beside it).

With ``--baseline DIR`` (an unpacked checkout of another commit, e.g. ``git archive main``) the
same nodes from DIR run in turn with this tree's (A B A B ...; the code of each comes first on
PYTHONPATH), so the difference is from one run.

Run: .venv/bin/python benchmarks/bench_node_startup.py [--rounds 10] [--baseline DIR]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
NODES = {"scara_ik_server": "ik_server", "scara_forward": "forward"}


def first_output(probe, repo: Path, node: str) -> float:
    """Seconds from starting ``node`` (code from ``repo``) to its first output."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState

    from manipulator_kinematics.param_files import config_path
    from manipulator_kinematics_interfaces.srv import SolveIK

    code = f"import sys; from scara_kinematics.nodes import {NODES[node]}; sys.exit({NODES[node]}(sys.argv))"
    command = [sys.executable, "-c", code, "--ros-args", "--params-file", str(config_path("scara.yaml"))]
    env = os.environ | {"PYTHONPATH": str(repo)}
    seen: list[float] = []
    if node == "scara_forward":
        subscription = probe.node.create_subscription(
            PoseStamped, "tool_pose", lambda _: seen.append(time.perf_counter()), 10
        )
        publisher = probe.node.create_publisher(JointState, "joint_states", 10)
        message = JointState(name=["rail_joint", "shoulder_joint", "elbow_joint"], position=[0.1, 0.5, 0.6])
        timer = probe.node.create_timer(0.01, lambda: publisher.publish(message))
    else:
        client = probe.node.create_client(SolveIK, "solve_ik")
        request = SolveIK.Request(mode="fixed_phi")
        request.target.pose.position.x, request.target.pose.position.y = 0.5598076211353316, 0.4
        pending: list = []

        def ask() -> None:
            if client.service_is_ready() and not pending:
                future = client.call_async(request)
                future.add_done_callback(lambda _: seen.append(time.perf_counter()))
                pending.append(future)
            elif pending and not pending[0].done():
                pending.clear()  # not answered in 50 ms: ask again

        timer = probe.node.create_timer(0.05, ask)
    start = time.perf_counter()
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        probe.wait_until(lambda: bool(seen) or process.poll() is not None, 60.0, f"first output of {node}")
        if not seen:
            raise RuntimeError(f"{node} ended: {process.stderr.read().decode()[-500:]}")
        return seen[0] - start
    finally:
        process.terminate()
        process.wait(10)
        probe.node.destroy_timer(timer)
        if node == "scara_forward":
            probe.node.destroy_subscription(subscription)
            probe.node.destroy_publisher(publisher)
        else:
            probe.node.destroy_client(client)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--baseline", type=Path, help="another commit's checkout, run in turn with this one")
    args = parser.parse_args()

    import numpy as np

    sys.path.insert(0, str(REPO / "test"))
    import conftest  # noqa: F401 - reserves an unused ROS_DOMAIN_ID and keeps discovery on localhost
    from ros_harness import Probe

    trees = [("this tree", REPO)] + ([("baseline", args.baseline.resolve())] if args.baseline else [])
    probe = Probe("bench_startup_probe")
    times = {(label, node): [] for label, _ in trees for node in NODES}
    try:
        for _ in range(args.rounds):
            for node in NODES:
                for label, repo in trees:
                    times[label, node].append(first_output(probe, repo, node) * 1e3)
    finally:
        probe.close()
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    revision = {
        label: subprocess.run(
            ["git", "-C", str(repo), "log", "-1", "--format=%h"], capture_output=True, text=True
        ).stdout.strip()
        or repo.name
        for label, repo in trees
    }
    print(
        f"\nNode start-up, launch to first output: {os.cpu_count()} cores (load average {load}), "
        f"{args.rounds} rounds, ms (median [min, max]).\n"
    )
    print("| node | " + " | ".join(f"{label} ({revision[label]})" for label, _ in trees) + " |")
    print("|---|" + "---|" * len(trees))
    for node in NODES:
        cells = [
            f"{np.median(t):.0f} [{min(t):.0f}, {max(t):.0f}]"
            for t in (times[label, node] for label, _ in trees)
        ]
        print(f"| {node} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
