"""excavator_demo: one scripted digging cycle, closed loop, recorded, summarised and plotted.

    excavator_demo [--output out/demo] [--max-error 0.05] [--timeout 90]

Starts ``excavator_sim``, ``excavator_forward``, ``excavator_velocity_ik`` and the bag recorder
(``record``) as processes with the package's config, then runs a driver node in this process:
on each ``bucket_pose`` it takes the reference of the digging cycle
(:func:`excavator_kinematics.bucket_path.digging_cycle`) at the pose's stamp and publishes
``target_bucket_twist`` = reference rate + gain x (reference - measured) (closed loop on the bucket
position, :func:`excavator_kinematics.bucket_path.follow`), plus the reference itself on
``reference_bucket_pose`` / ``reference_bucket_twist`` so the bag holds what was asked.
Afterwards the bag is read back for the summary and the Fig. 11 / Fig. 12 style plots
(:mod:`excavator_kinematics.cycle_report`), and an animated side view of the whole linkage
(``excavator_digging.gif``). The recorder adds the topics Foxglove's 3-D panel needs
(``record --visuals``: /robot_description, /tf, /tf_static, machine_markers). Exit status 1 if
a process died, the cycle did not run, or the bucket left the reference path by more than
``--max-error`` metres.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import rclpy
import yaml
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from excavator_kinematics import messages
from excavator_kinematics.bucket_path import BucketPath, digging_cycle, follow, natural_coordinates, to_task
from excavator_kinematics.kinematics import Excavator
from excavator_kinematics.twist import bucket_angles, twist_from_q_dot
from manipulator_kinematics import registry
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.params import config_path

FRAME = "base_link"
GAIN = 2.0  # 1/s, bucket position and angle
# Dead time of the loop: the simulator's actuator lag (20 ms) plus pose -> driver -> IK -> next
# simulator step (about 20 ms). The reference rate is fed forward this far ahead of the pose's
# stamp, so the bucket moves at the reference rate when the reference does.
LEAD = 0.04  # s
# Of that, pose stamp -> the IK computing the rates (the IK maps the twist at its own, newer state).
TRANSPORT = 0.02  # s
# A pose older than this is not acted on: feedback on stale measurements makes the loop overshoot;
# without new targets the IK stops the machine after its command timeout instead.
MAX_POSE_AGE = 0.1  # s
# Demo-only settings on top of config/excavator_nodes.yaml: a 50 Hz loop (five Python processes
# and the recorder share two cores), actuators with a 20 ms lag (a real valve-cylinder does not
# jump to speed), lightly filtered accelerations for readable plots, and command timeouts of
# 0.1 s (5 periods): if a process stalls, the machine stops on its path instead of coasting on an
# old command for the default 0.5 s.
OVERRIDES = {
    "/**/excavator_sim": {"ros__parameters": {"rate": 50.0, "time_constant": 0.02, "command_timeout": 0.1}},
    "/**/excavator_forward": {"ros__parameters": {"acceleration_time_constant": 0.03}},
    "/**/excavator_velocity_ik": {"ros__parameters": {"command_timeout": 0.1}},
}
# The recorder's stop includes adding the visual topics (record --visuals).
RECORD_STOP_TIMEOUT = 120.0  # s
ANIMATION = "excavator_digging.gif"
ANIMATION_SPEED = 2.0  # x real time: a 40 s cycle in 20 s (200 frames at 10 fps)
RECORDED = {
    "cylinder_lengths": "sensor_msgs/msg/JointState",
    "joint_states": "sensor_msgs/msg/JointState",
    "open_chain_joint_states": "sensor_msgs/msg/JointState",
    "cylinder_rate_commands": "sensor_msgs/msg/JointState",
    "bucket_pose": "geometry_msgs/msg/PoseStamped",
    "bucket_twist": "geometry_msgs/msg/TwistStamped",
    "bucket_accel": "geometry_msgs/msg/AccelStamped",
    "target_bucket_twist": "geometry_msgs/msg/TwistStamped",
    "reference_bucket_pose": "geometry_msgs/msg/PoseStamped",
    "reference_bucket_twist": "geometry_msgs/msg/TwistStamped",
}


def animation(bag: Path, gif: Path, exc: Excavator, start_ns: int, duration: float) -> Path:
    """Side view (boom plane) of the whole linkage through the recorded cycle, with the reference
    path and the bucket-tip trace, as an animated GIF (:func:`manipulator_kinematics.animation.animate`)."""
    from manipulator_kinematics.animation import View, animate, boom_plane
    from manipulator_kinematics.bag.visual import gather_states

    machine = registry.machine("excavator")
    arrays = BagReader(bag).arrays(["/cylinder_lengths", "/joint_states", "/reference_bucket_pose"])
    _, stamp, D = gather_states({t.strip("/"): a for t, a in arrays.items()}, machine.joint_names(exc))
    cycle = (stamp >= start_ns) & (stamp <= start_ns + int((duration + 1.0) * 1e9))
    reference = arrays["/reference_bucket_pose"]
    points = np.stack([reference[f"pose.position.{c}"] for c in "xyz"], axis=-1)
    return animate(
        machine.scene(exc, D[cycle]), gif, [View(boom_plane(D[cycle, 0]), "r (m)", "z (m)")],
        times=(stamp[cycle] - start_ns) * 1e-9, reference=points, ground=0.0, speed=ANIMATION_SPEED,
        title=f"{exc.name}: digging cycle, side view of the boom plane ({ANIMATION_SPEED:g}x speed)",
    )


class Driver:
    """Publishes the target bucket twist that tracks ``path`` from the first pose it sees."""

    def __init__(self, node: Node, path: BucketPath) -> None:
        self.node, self.path = node, path
        self.start_ns: int | None = None
        self.last_ns: int | None = None
        self.delays: list[float] = []  # s from a pose's stamp to the driver receiving it
        self.skipped = 0  # poses too old to act on
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.target = node.create_publisher(TwistStamped, "target_bucket_twist", qos)
        self.reference_pose = node.create_publisher(PoseStamped, "reference_bucket_pose", qos)
        self.reference_twist = node.create_publisher(TwistStamped, "reference_bucket_twist", qos)
        # Depth 1: a controller wants the latest pose, never a backlog.
        node.create_subscription(PoseStamped, "bucket_pose", self.on_pose, 1)

    def elapsed(self) -> float:
        return 0.0 if self.start_ns is None else (self.last_ns - self.start_ns) * 1e-9

    def on_pose(self, msg: PoseStamped) -> None:
        # The reference is taken at the measurement's stamp, so delivery delays are not errors.
        self.last_ns = messages.stamp_ns(msg.header.stamp)
        self.delays.append((self.node.get_clock().now().nanoseconds - self.last_ns) * 1e-9)
        if self.start_ns is None:
            self.start_ns = self.last_ns
        if self.delays[-1] > MAX_POSE_AGE:
            self.skipped += 1
            return
        c_reference, c_rate = self.path.natural(self.elapsed(), LEAD)
        o = msg.pose.orientation
        theta1, alpha = bucket_angles([o.x, o.y, o.z, o.w])
        p = msg.pose.position
        tip = np.array([p.x, p.y, p.z])
        measured = natural_coordinates(theta1, np.r_[tip, alpha])
        # Track in C = [r, theta1, z, alpha]; turn the rate into a Cartesian twist at the state the
        # IK will see (TRANSPORT later): a twist made for the measured swing angle and resolved
        # after the machine swung on pushes the bucket off the arc (by r theta1_dot^2 x delay).
        c_dot = follow(c_reference, c_rate, measured, GAIN, angles=(1, 3))
        predicted = measured + TRANSPORT * c_dot
        q_predicted, q_dot = to_task(predicted, c_dot)
        twist = twist_from_q_dot(predicted[1], q_predicted[:3], q_dot)
        self.target.publish(messages.bucket_twist(msg.header.stamp, FRAME, *twist))
        reference, rate = self.path.at(self.elapsed())  # what is asked, without the lead
        reference_theta1 = float(c_reference[1])
        self.reference_pose.publish(
            messages.bucket_pose(msg.header.stamp, FRAME, reference_theta1, reference)
        )
        self.reference_twist.publish(
            messages.bucket_twist(
                msg.header.stamp,
                FRAME,
                *twist_from_q_dot(reference_theta1, reference[:3], rate),
            )
        )


def node_command(name: str, overrides: Path) -> list[str]:
    """Command line of an excavator node on the default machine and node settings, then the
    settings in the params file ``overrides`` (a later file wins)."""
    files = (config_path("excavator_cet200.yaml"), config_path("excavator_nodes.yaml"), overrides)
    return [console_script(name), "--ros-args", *(arg for f in files for arg in ("--params-file", str(f)))]


def start_processes(output: Path) -> list[tuple[str, subprocess.Popen]]:
    overrides = output / "demo_params.yaml"
    overrides.write_text(yaml.safe_dump(OVERRIDES), encoding="utf-8")
    commands = {
        name: node_command(name, overrides)
        for name in ("excavator_sim", "excavator_forward", "excavator_velocity_ik")
    }
    commands["record"] = [
        console_script("record"),
        "-o",
        str(output / "bag"),
        "--overwrite",
        "--topics",
        *RECORDED,
        "--type",
        *(f"{topic}:={msgtype}" for topic, msgtype in RECORDED.items()),
        # When the recording ends: /robot_description, /tf, /tf_static, machine_markers (Foxglove).
        "--visuals",
    ]
    processes = []
    for name, command in commands.items():
        log = open(output / f"{name}.log", "w", encoding="utf-8")  # noqa: SIM115 - the child writes it
        processes.append((name, subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)))
    return processes


def stop_processes(processes: list[tuple[str, subprocess.Popen]]) -> None:
    for _, process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
    for name, process in processes:
        try:
            # The recorder adds the visual topics after it stops (a few seconds for the cycle).
            process.wait(RECORD_STOP_TIMEOUT if name == "record" else 10.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def run_cycle(output: Path, path: BucketPath, timeout: float) -> tuple[str | None, Driver | None]:
    """Start everything and drive ``path`` once; (None or what went wrong, the driver)."""
    processes = start_processes(output)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("excavator_demo_driver", context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    driver = None
    try:

        def spin_until(done: Callable[[], bool], limit: float, what: str) -> str | None:
            deadline = time.monotonic() + limit
            while not done():
                dead = [name for name, p in processes if p.poll() is not None]
                if dead:
                    return f"{', '.join(dead)} ended early (see {output}/<name>.log)"
                if time.monotonic() > deadline:
                    return f"timed out after {limit:g} s waiting for {what}"
                executor.spin_once(timeout_sec=0.01)
            return None

        def recorder_ready() -> bool:
            return all(
                any(info.node_name == "bag_recorder" for info in node.get_subscriptions_info_by_topic(t))
                for t in RECORDED
            )

        # Every recorded topic must have the recorder's subscription before the cycle starts.
        failure = spin_until(recorder_ready, 30.0, "the recorder")
        if failure is None:
            driver = Driver(node, path)
            failure = spin_until(lambda: driver.start_ns is not None, 30.0, "bucket_pose")
        if failure is None:
            print(f"excavator_demo: driving a {path.duration:.1f} s digging cycle", flush=True)
            failure = spin_until(
                lambda: driver.elapsed() > path.duration + 1.0, timeout, "the cycle to finish"
            )
        return failure, driver
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
        stop_processes(processes)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="excavator_demo", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--output", type=Path, default=Path("out/demo"), help="output directory (default out/demo)"
    )
    parser.add_argument(
        "--max-error",
        type=float,
        default=0.05,
        help="largest accepted distance of the bucket tip from the reference path, m (default 0.05)",
    )
    parser.add_argument(
        "--timeout", type=float, default=90.0, help="give up after this many seconds of cycle"
    )
    args = parser.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    from excavator_kinematics.cycle_report import report  # matplotlib only once the backend is set

    args.output.mkdir(parents=True, exist_ok=True)
    exc = Excavator.default()
    start_q = exc.pose(exc.limits.reference)  # the simulator starts at the reference lengths
    path = digging_cycle(
        np.r_[np.hypot(start_q[0], start_q[1]), np.arctan2(start_q[1], start_q[0]), start_q[2:]]
    )
    failure, driver = run_cycle(args.output, path, args.timeout)
    if failure is not None:
        print(f"excavator_demo: FAILED: {failure}", file=sys.stderr)
        return 1
    summary = report(args.output / "bag", args.output, exc, path, driver.start_ns)
    print(summary.text)
    gif = animation(args.output / "bag", args.output / ANIMATION, exc, driver.start_ns, path.duration)
    print(f"  animation: {gif} ({gif.stat().st_size / 1e6:.2f} MB); Foxglove: open {args.output / 'bag'} "
          f"(docs/visualisation.md)")
    delay = 1e3 * np.percentile(driver.delays, [50, 99])
    print(
        f"  driver: got bucket_pose {delay[0]:.1f} ms (p50) / {delay[1]:.1f} ms (p99) after its stamp; "
        f"{driver.skipped} of {len(driver.delays)} older than {MAX_POSE_AGE:g} s not acted on"
    )
    if summary.max_path_deviation > args.max_error:
        print(
            f"excavator_demo: FAILED: the bucket left the path by {summary.max_path_deviation:.3f} m "
            f"(> {args.max_error} m)",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
