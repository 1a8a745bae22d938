"""How far the bucket tip leaves the commanded line for a constant target twist (issue #18 item 4).

    python benchmarks/excavator_line_deviation.py [--where both|plant|nodes] [--duration 14]

From the reference state, a constant linear target twist (angular 0: hold the bucket angle) is
followed until the run ends, past the stroke ends. The line is the tip position when the target
began plus its direction; the table gives the travel along it and the largest distance from it.

* ``plant``: in one process, the numpy pieces the nodes wire: each 10 ms step re-solves
  ``rate_command`` at the plant's state (as the IK does on each 100 Hz ``cylinder_lengths``),
  with the IK's correction toward the line (``toward_line``, gain ``--line-gain``), and the plant
  integrates it.
* ``nodes``: the shipped nodes as processes over DDS with the package's config (excavator_sim ->
  excavator_velocity_ik -> excavator_forward), the target published at 50 Hz, the tip read from
  ``bucket_pose``. Its own ROS_DOMAIN_ID, reserved as the test suite does.

Not part of the test suite (about 20 s a direction across processes).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
import time

import numpy as np
import yaml

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.core.rate_command import rate_command, toward_line
from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.param_files import config_path

# The table: (label, linear target m/s).
TARGETS = (
    ("+x 2 m/s", (2.0, 0.0, 0.0)),
    ("-z 1 m/s", (0.0, 0.0, -1.0)),
    ("+z 1 m/s", (0.0, 0.0, 1.0)),
    ("-x 1 m/s", (-1.0, 0.0, 0.0)),
)
NODES = ("excavator_sim", "excavator_forward", "excavator_velocity_ik")


def line_deviation(tips: np.ndarray, start: np.ndarray, direction: np.ndarray) -> tuple[float, float]:
    """(largest travel along the line, largest distance from it) of tip positions (N, 3)."""
    u = direction / np.linalg.norm(direction)
    offsets = tips - start
    along = offsets @ u
    return float(along.max()), float(np.linalg.norm(offsets - along[:, None] * u, axis=1).max())


def in_plant(
    linear: np.ndarray, duration: float, gain: float, gives_way: bool, dt: float = 0.01
) -> tuple[float, float]:
    exc = Excavator.default()
    plant = Plant(exc.limits, exc.limits.reference)
    q_dot = np.r_[linear, 0.0]
    began = exc.pose(plant.d)
    start = began[:3]
    tips = [start]
    for _ in range(round(duration / dt)):
        # The drift stays far below LINE_RESTART here (no state jumps): never None.
        target = q_dot + toward_line(began, q_dot, exc.pose(plant.d), gain, not gives_way)
        command = rate_command(exc.jc0(plant.d), plant.d, target, exc.limits, 50.0, 0.1, gives_way)
        plant.step(command.d_dot, dt)
        tips.append(exc.pose(plant.d)[:3])
    return line_deviation(np.array(tips), start, linear)


def across_processes(linear: np.ndarray, duration: float, gives_way: bool) -> tuple[float, float]:
    import rclpy
    from geometry_msgs.msg import PoseStamped, TwistStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from excavator_kinematics.nodes import message_codec

    files = [
        arg
        for name in ("excavator_cet200.yaml", "excavator_nodes.yaml")
        for arg in ("--params-file", str(config_path(name)))
    ]
    settings = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)  # noqa: SIM115 - deleted below
    yaml.safe_dump(
        {"/**/excavator_velocity_ik": {"ros__parameters": {"bucket_angle_gives_way": gives_way}}}, settings
    )
    settings.close()
    files += ["--params-file", settings.name]
    logs = [open(os.devnull, "w") for _ in NODES]  # noqa: SIM115 - closed below
    processes = [
        subprocess.Popen([console_script(n), "--ros-args", *files], stdout=log, stderr=log)
        for n, log in zip(NODES, logs, strict=True)
    ]
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node("line_deviation_driver", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        target = node.create_publisher(TwistStamped, "target_bucket_twist", qos)
        poses: list[tuple[int, np.ndarray]] = []
        node.create_subscription(
            PoseStamped,
            "bucket_pose",
            lambda m: poses.append(
                (
                    message_codec.stamp_ns(m.header.stamp),
                    np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z]),
                )
            ),
            qos,
        )

        def spin_until(condition, timeout: float) -> None:
            deadline = time.monotonic() + timeout
            while not condition():
                if time.monotonic() > deadline:
                    raise TimeoutError("nodes did not come up")
                executor.spin_once(timeout_sec=0.01)

        spin_until(lambda: len(poses) > 10 and target.get_subscription_count() > 0, 30.0)
        start_ns = node.get_clock().now().nanoseconds
        start = poses[-1][1]

        def send() -> None:
            target.publish(
                message_codec.bucket_twist(node.get_clock().now().to_msg(), "base_link", linear, np.zeros(3))
            )

        node.create_timer(0.02, send)
        deadline = start_ns + int(duration * 1e9)
        spin_until(lambda: node.get_clock().now().nanoseconds > deadline, duration + 5.0)
        tips = np.array([tip for stamp, tip in poses if stamp >= start_ns])
        return line_deviation(np.vstack((start, tips)), start, linear)
    finally:
        rclpy.shutdown(context=context)
        for process in processes:
            process.terminate()
        for process, log in zip(processes, logs, strict=True):
            process.wait(10.0)
            log.close()
        os.unlink(settings.name)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--where", choices=("both", "plant", "nodes"), default="both")
    parser.add_argument("--duration", type=float, default=14.0, help="seconds per direction")
    parser.add_argument(
        "--line-gain",
        type=float,
        default=2.0,
        help="plant: the IK's line_gain (1/s, config default 2); the nodes use their config",
    )
    parser.add_argument("--bucket-angle-gives-way", action="store_true", help="the IK's secondary task")
    parser.add_argument("--only", help="one target of the table, e.g. '+x 2 m/s'")
    args = parser.parse_args()
    places = ("plant", "nodes") if args.where == "both" else (args.where,)
    rows, gives_way = [], args.bucket_angle_gives_way
    for label, linear in TARGETS:
        if args.only and label != args.only:
            continue
        for where in places:
            if where == "plant":
                travel, off = in_plant(np.array(linear), args.duration, args.line_gain, gives_way)
            else:
                from demo_stress import reserved_domain  # benchmarks/: the test suite's domain locks

                with reserved_domain() as domain:
                    os.environ["ROS_DOMAIN_ID"] = str(domain)
                    travel, off = across_processes(np.array(linear), args.duration, gives_way)
            rows.append((label, where, travel, off))
            print(
                f"{label:10} {where:6} travel {travel:6.3f} m  max distance from the line {off:6.4f} m",
                flush=True,
            )
    print(
        f"\n| target ({args.duration:g} s) | where | tip travel along it (m) | "
        "largest distance from the line (m) |"
    )
    print("| --- | --- | --- | --- |")
    for label, where, travel, off in rows:
        print(f"| {label} | {where} | {travel:.3f} | {off:.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
