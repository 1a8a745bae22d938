"""excavator_demo: one scripted digging cycle, closed loop, recorded, summarised and plotted.

    excavator_demo [--output out/demo] [--max-error 0.05] [--timeout 90]

Starts ``excavator_sim``, ``excavator_forward``, ``excavator_velocity_ik``,
``excavator_ik_server`` and the bag recorder (``record``) as processes with the package's config,
then runs a driver node in this process.

Start-up handshake (each step with a timeout and an error naming what is missing): every node's
publishers and subscriptions are in the graph and the driver's own are matched with theirs
(velocity IK, forward node, simulator, recorder on every recorded topic); then a first command
round trip: the driver holds the bucket at the path's start with the reference raised by
``PROBE``, and waits until ``excavator_velocity_ik`` answers with a non-zero
``cylinder_rate_commands`` and the simulator moves on it; then the bucket settles back to the
start and only then does the cycle clock start.

The cycle: on each ``bucket_pose`` the driver takes the reference of the digging cycle
(:func:`excavator_kinematics.demo.bucket_path.digging_cycle`) at the cycle time of the pose's stamp
(:class:`excavator_kinematics.demo.bucket_path.CycleClock`: held over gaps longer than the command
timeouts) and publishes ``target_bucket_twist`` = reference rate + gain x (reference - measured)
(closed loop on the bucket position, :func:`excavator_kinematics.demo.bucket_path.follow`), plus the
reference itself on ``reference_bucket_pose`` / ``reference_bucket_twist`` so the bag holds what
was asked. Every 5 s of cycle it prints a progress line (time, phase, distance from the path).
The cycle here ends over the truck with the bucket turned back to its start angle (``level``,
instead of the scripted ``return``); then the way back is planned: the driver calls the
``excavator_ik_server``'s ``plan_path`` from the measured state to the start (a straight tip
line at the start's bucket angle, timed within every actuator's speed limit) and streams the
trajectory to the simulator as rate commands (:mod:`excavator_kinematics.demo.planned_move`: the
planned velocities plus position feedback, on the stamps of the simulator's states), publishing
the planned D on ``planned_joint_states``; on arrival the measured D must be within
:data:`~excavator_kinematics.demo.planned_move.TOLERANCE` of the start.
Afterwards the bag is read back for the summary and the Fig. 11 / Fig. 12 style plots
(:mod:`excavator_kinematics.demo.cycle_report`), and an animated side view of the whole linkage
(``excavator_digging.gif``). The recorder adds the topics Foxglove's 3-D panel needs
(``record --visuals``: /robot_description, /tf, /tf_static, machine_markers). Last, what the
bucket dug: the per-sample table and as-built surface of :mod:`manipulator_kinematics.bag.asbuilt`
in ``asbuilt/`` (docs/asbuilt.md). Exit status 1 if
a process died, the cycle did not run, or the bucket left the reference path by more than
``--max-error`` metres, or the planned move did not arrive at the start.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import rclpy
import yaml
from geometry_msgs.msg import Point, PoseStamped, TwistStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from excavator_kinematics.core.kinematics import ACTUATORS, CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.twist import bucket_angles, twist_from_q_dot
from excavator_kinematics.demo import planned_move
from excavator_kinematics.demo.bucket_path import (
    BucketPath,
    CycleClock,
    Segment,
    digging_cycle,
    follow,
    natural_coordinates,
    path_deviation,
    to_task,
)
from excavator_kinematics.nodes import message_codec
from manipulator_kinematics import registry, stopping
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.ros_domain import isolated
from manipulator_kinematics_interfaces.srv import PlanPath

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
# Demo-only settings on top of config/excavator_nodes.yaml: a 50 Hz loop (six Python processes
# and the recorder share two cores), actuators with a 20 ms lag (a real valve-cylinder does not
# jump to speed), lightly filtered accelerations for readable plots, and command timeouts of
# 0.1 s (5 periods): if a process stalls, the machine stops on its path instead of coasting on an
# old command for the default 0.5 s.
OVERRIDES = {
    "/**/excavator_sim": {"ros__parameters": {"rate": 50.0, "time_constant": 0.02, "command_timeout": 0.1}},
    "/**/excavator_forward": {"ros__parameters": {"acceleration_time_constant": 0.03}},
    "/**/excavator_velocity_ik": {"ros__parameters": {"command_timeout": 0.1}},
}
# Start-up: how long to wait for every process's endpoints (imports and discovery on a loaded
# machine take seconds), then for the first command round trip and the hold to settle.
CONNECT_TIMEOUT = 60.0  # s
ROUND_TRIP_TIMEOUT = 20.0  # s
# The round trip's probe: the hold reference is raised this much until the simulator moves on the
# IK's command (a zero command would not show that the simulator listens); then back to the start.
PROBE = 0.005  # m
MOVING = 1e-4  # m/s: a cylinder rate in cylinder_lengths that shows the simulator moving
MOVED = 1e-5  # m: or a cylinder this far from where the simulator starts (the probe moves it ~mm)
SETTLED = 1e-3  # m: the cycle starts once the bucket is back within this of the path's start
# The cycle clock advances with the pose stamps but at most this much from one acted-on pose to
# the next: after a longer gap the IK's and the simulator's command timeouts (0.1 s) stopped the
# machine, so the reference waits for it instead of running away.
MAX_CLOCK_STEP = 0.1  # s
PROGRESS_PERIOD = 5.0  # s of cycle between progress lines
RECORDER = "bag_recorder"
# The recorder's stop includes adding the visual topics (record --visuals).
RECORD_STOP_TIMEOUT = 120.0  # s
# The bucket back to its start angle over the truck, before the planned move (the bucket cylinder
# at about 70 % of its speed limit on the reference).
LEVEL_TIME = 5.0  # s
# The planned move's tip speed limit: high enough that an actuator's speed limit (the arm's) sets
# the pace on part of the way, so the plan shows the time scaling at work.
PLAN_TIP_SPEED = 2.0  # m/s
PLAN_TIMEOUT = 30.0  # s for the plan_path answer (imports and a plan on a loaded machine)
PLANNED_MOVE = "excavator_planned_move.png"
ANIMATION = "excavator_digging.gif"
ANIMATION_SPEED = 2.0  # x real time: a 40 s cycle in 20 s (200 frames at 10 fps)
ANIMATION_SIZE = (11.0, 5.0)  # inches at 90 dpi: 990 x 450 px, both views side by side
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
    "planned_joint_states": "sensor_msgs/msg/JointState",
}


def animation(
    bag: Path,
    gif: Path,
    exc: Excavator,
    start_ns: int,
    end_ns: int,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Side view (boom plane) and top view of the whole linkage through the recorded cycle (stamps
    ``start_ns`` to ``end_ns``), with the reference path and the bucket-tip trace, as an animated
    GIF (:func:`manipulator_kinematics.animation.animate`); the top view shows the swing to the
    truck, which the side view of the turning boom plane cannot."""
    from manipulator_kinematics.animation import View, animate, boom_plane, view_xy
    from manipulator_kinematics.bag.visual import gather_states

    machine = registry.machine("excavator")
    arrays = BagReader(bag).arrays(["/cylinder_lengths", "/joint_states", "/reference_bucket_pose"])
    _, stamp, D = gather_states({t.strip("/"): a for t, a in arrays.items()}, machine.joint_names(exc))
    cycle = (stamp >= start_ns) & (stamp <= end_ns)
    reference = arrays["/reference_bucket_pose"]
    points = np.stack([reference[f"pose.position.{c}"] for c in "xyz"], axis=-1)
    return animate(
        machine.scene(exc, D[cycle]),
        gif,
        [
            View(boom_plane(D[cycle, 0]), "r (m)", "z (m)", "side view of the boom plane"),
            View(view_xy, "x (m)", "y (m)", "top view: the swing to the truck"),
        ],
        times=(stamp[cycle] - start_ns) * 1e-9,
        reference=points,
        ground=0.0,
        speed=ANIMATION_SPEED,
        title=f"{exc.name}: digging cycle ({ANIMATION_SPEED:g}x speed)",
        size=ANIMATION_SIZE,
        dpi=90,
        progress=progress,
    )


def missing_endpoints(
    expected: Sequence[tuple[str, str, str]], present: Callable[[str, str], set[str]]
) -> list[str]:
    """What of ``expected`` ((node, "publishes" | "subscribes to", topic)) the graph lacks, as
    phrases; ``present(kind, topic)`` gives the node names with that kind of endpoint on ``topic``."""
    return [f"{name} {kind} /{topic}" for name, kind, topic in expected if name not in present(kind, topic)]


class Driver:
    """Publishes the target bucket twist that tracks ``path``: a hold at the path's start (raised
    by :attr:`probe` m during the start-up round trip) until :meth:`start`, then the cycle."""

    def __init__(self, node: Node, path: BucketPath) -> None:
        self.node, self.path = node, path
        self.probe = PROBE
        self.active = False  # acts on poses only once every endpoint is matched (see run_cycle)
        self.running = False
        self.clock = CycleClock(MAX_CLOCK_STEP)
        self.delays: list[float] = []  # s from a pose's stamp to the driver receiving it (cycle only)
        self.skipped = 0  # poses too old to act on (cycle only)
        self.hold_error = np.inf  # m, tip from the path's start (before the cycle)
        # Cycle samples for the progress lines: time along the path, tip, reference tip.
        self.times: list[float] = []
        self.tips: list[np.ndarray] = []
        self.references: list[np.ndarray] = []
        self.reported = 0  # samples already judged by progress()
        self.max_deviation = 0.0  # m
        self.next_progress = PROGRESS_PERIOD
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.target = node.create_publisher(TwistStamped, "target_bucket_twist", qos)
        self.reference_pose = node.create_publisher(PoseStamped, "reference_bucket_pose", qos)
        self.reference_twist = node.create_publisher(TwistStamped, "reference_bucket_twist", qos)
        # Depth 1: a controller wants the latest pose, never a backlog.
        self.poses = node.create_subscription(PoseStamped, "bucket_pose", self.on_pose, 1)

    def elapsed(self) -> float:
        return self.clock.t

    def start(self) -> None:
        """Start the cycle at the next pose (time 0 of the path)."""
        self.probe = 0.0
        self.running = True

    def on_pose(self, msg: PoseStamped) -> None:
        # The reference is taken at the measurement's stamp, so delivery delays are not errors.
        stamp = message_codec.stamp_ns(msg.header.stamp)
        age = (self.node.get_clock().now().nanoseconds - stamp) * 1e-9
        if self.running:
            self.delays.append(age)
        if age > MAX_POSE_AGE or not self.active:
            self.skipped += self.running
            return
        t = self.clock.tick(stamp) if self.running else 0.0
        c_reference, c_rate = self.path.natural(t, LEAD)
        o = msg.pose.orientation
        theta1, alpha = bucket_angles([o.x, o.y, o.z, o.w])
        p = msg.pose.position
        tip = np.array([p.x, p.y, p.z])
        measured = natural_coordinates(theta1, np.r_[tip, alpha])
        # Track in C = [r, theta1, z, alpha]; turn the rate into a Cartesian twist at the state the
        # IK will see (TRANSPORT later): a twist made for the measured swing angle and resolved
        # after the machine swung on pushes the bucket off the arc (by r theta1_dot^2 x delay).
        raised = c_reference + np.array([0.0, 0.0, self.probe, 0.0])
        c_dot = follow(raised, c_rate, measured, GAIN, angles=(1, 3))
        predicted = measured + TRANSPORT * c_dot
        q_predicted, q_dot = to_task(predicted, c_dot)
        twist = twist_from_q_dot(predicted[1], q_predicted[:3], q_dot)
        self.target.publish(message_codec.bucket_twist(msg.header.stamp, FRAME, *twist))
        reference, rate = self.path.at(t)  # what is asked, without the lead
        if not self.running:
            self.hold_error = float(np.linalg.norm(tip - reference[:3]))
            return
        self.times.append(t)
        self.tips.append(tip)
        self.references.append(reference[:3])
        reference_theta1 = float(c_reference[1])
        self.reference_pose.publish(
            message_codec.bucket_pose(msg.header.stamp, FRAME, reference_theta1, reference)
        )
        self.reference_twist.publish(
            message_codec.bucket_twist(
                msg.header.stamp,
                FRAME,
                *twist_from_q_dot(reference_theta1, reference[:3], rate),
            )
        )

    def progress(self) -> str | None:
        """A line every PROGRESS_PERIOD s of the cycle: phase, time, the bucket's distance from the
        reference path (as the summary measures it), poses not acted on, clock held."""
        if not self.times or self.times[-1] < self.next_progress:
            return None
        self.next_progress += PROGRESS_PERIOD
        times, tips, references = (np.asarray(v) for v in (self.times, self.tips, self.references))
        new = slice(self.reported, len(times))
        self.reported = len(times)
        deviation = path_deviation(tips[new], times[new], references, times)
        self.max_deviation = max(self.max_deviation, float(deviation.max()))
        t = times[-1]
        return (
            f"  {t:5.1f} / {self.path.duration:.1f} s  {self.path.segments[self.path.phase(t)].name:<9} "
            f"off path {1e3 * deviation[-1]:5.1f} mm (max {1e3 * self.max_deviation:5.1f} mm)  "
            f"poses not acted on {self.skipped}, clock held {self.clock.held:.2f} s"
        )


class Mover:
    """Runs the planned move: asks ``plan_path`` for the way from the measured D to ``start`` and
    streams the trajectory as rate commands on the simulator's states (planned_move)."""

    def __init__(self, node: Node, exc: Excavator, start: np.ndarray) -> None:
        self.node, self.exc, self.start = node, exc, start
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.commands = node.create_publisher(JointState, "cylinder_rate_commands", qos)
        self.planned = node.create_publisher(JointState, "planned_joint_states", qos)
        self.client = node.create_client(PlanPath, "plan_path")
        self.swing: float | None = None
        self.d: np.ndarray | None = None  # the latest measured D
        self.watching = False  # for the velocity IK's stop (zero rates once) after the cycle
        self.ik_stopped = False
        self.trajectory: planned_move.Trajectory | None = None
        self.clock = CycleClock(MAX_CLOCK_STEP)
        self.max_error = np.zeros(4)  # |planned - measured| D during the move
        self.arrived: planned_move.Arrival | None = None
        node.create_subscription(JointState, "joint_states", self.on_swing, 1)
        node.create_subscription(JointState, "cylinder_lengths", self.on_cylinders, 1)
        node.create_subscription(JointState, "cylinder_rate_commands", self.on_command, 10)

    def on_swing(self, msg: JointState) -> None:
        if list(msg.name) == list(JOINTS[:1]) and len(msg.position) == 1:
            self.swing = float(msg.position[0])

    def on_command(self, msg: JointState) -> None:
        # Before the move only the velocity IK publishes here; its stop is an all-zero command.
        if self.watching and self.trajectory is None and len(msg.velocity) and not any(msg.velocity):
            self.ik_stopped = True

    def request(self) -> PlanPath.Request:
        """From the measured D's tip to the start's, seeded with the measured D (its bucket angle)."""
        request = PlanPath.Request()
        request.waypoints = [
            Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))
            for p in (self.exc.pose(self.d)[:3], self.exc.pose(self.start)[:3])
        ]
        request.seed = message_codec.joint_state(self.node.get_clock().now().to_msg(), ACTUATORS, self.d)
        request.tip_speed = PLAN_TIP_SPEED
        return request

    def on_cylinders(self, msg: JointState) -> None:
        if self.swing is None or list(msg.name) != list(CYLINDERS) or len(msg.position) != 3:
            return
        self.d = np.r_[self.swing, msg.position]
        if self.trajectory is None or self.arrived is not None:
            return
        t = self.clock.tick(message_codec.stamp_ns(msg.header.stamp))
        if t > self.trajectory.duration + planned_move.SETTLE:
            self.commands.publish(
                message_codec.joint_state(msg.header.stamp, ACTUATORS, velocities=np.zeros(4))
            )
            self.arrived = planned_move.arrival(self.exc, self.d, self.start)
            return
        rates, q = self.trajectory.command(t, self.d)
        self.max_error = np.maximum(self.max_error, np.abs(q - self.d))
        self.commands.publish(message_codec.joint_state(msg.header.stamp, ACTUATORS, velocities=rates))
        self.planned.publish(
            message_codec.joint_state(msg.header.stamp, ACTUATORS, q, self.trajectory.at(t)[1])
        )


def demo_cycle(start: np.ndarray) -> BucketPath:
    """The digging cycle from ``start`` (C) up to the dump, then the bucket back to its start
    angle over the truck (``level``): the way back to the start is the planned move."""
    cycle = digging_cycle(start)
    dump = cycle.segments[-2].end
    level = Segment("level", np.r_[dump[:3], start[3]], LEVEL_TIME)
    return BucketPath(cycle.start, [*cycle.segments[:-1], level])


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
        for name in ("excavator_sim", "excavator_forward", "excavator_velocity_ik", "excavator_ik_server")
    }
    commands["record"] = [
        console_script("mk_record"),
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
        with stopping.starting():  # a signal to the demo ends them too, even one during Popen
            process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
            processes.append((name, stopping.adopt(process)))
    return processes


def stop_processes(processes: list[tuple[str, subprocess.Popen]]) -> None:
    for _, process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
    for name, process in processes:
        # The recorder adds the visual topics after it stops (a few seconds for the cycle, more on
        # a busy machine): a line every PROGRESS_PERIOD s while it works.
        deadline = time.monotonic() + (RECORD_STOP_TIMEOUT if name == "record" else 10.0)
        while process.poll() is None and time.monotonic() < deadline:
            try:
                process.wait(min(PROGRESS_PERIOD, max(deadline - time.monotonic(), 0.0)))
            except subprocess.TimeoutExpired:
                print(f"    waiting for {name} to finish", flush=True)
        if process.poll() is None:
            process.kill()
            process.wait()


def expected_graph() -> list[tuple[str, str, str]]:
    """Every endpoint the cycle needs, as (node, "publishes" | "subscribes to", topic)."""
    pub, sub = "publishes", "subscribes to"
    return [
        ("excavator_sim", sub, "cylinder_rate_commands"),
        ("excavator_sim", pub, "cylinder_lengths"),
        ("excavator_sim", pub, "joint_states"),
        ("excavator_forward", sub, "cylinder_lengths"),
        ("excavator_forward", sub, "joint_states"),
        *(("excavator_forward", pub, t) for t in ("bucket_pose", "bucket_twist", "bucket_accel")),
        ("excavator_forward", pub, "open_chain_joint_states"),
        ("excavator_velocity_ik", sub, "target_bucket_twist"),
        ("excavator_velocity_ik", sub, "cylinder_lengths"),
        ("excavator_velocity_ik", sub, "joint_states"),
        ("excavator_velocity_ik", pub, "cylinder_rate_commands"),
        *((RECORDER, sub, t) for t in RECORDED),
    ]


def run_cycle(
    output: Path, path: BucketPath, timeout: float, at_rest: np.ndarray, exc: Excavator
) -> tuple[str | None, Driver | None, Mover | None]:
    """Start everything, wait until the chain answers, drive ``path`` once, then the planned move
    back to the start; (None or what went wrong, the driver, the mover). ``at_rest``: the
    cylinder lengths the simulator starts at (m)."""
    started = time.monotonic()
    processes = start_processes(output)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("excavator_demo_driver", context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    driver = mover = None

    def say(line: str) -> None:
        print(f"excavator_demo: {line} ({time.monotonic() - started:.1f} s)", flush=True)

    def spin_until(
        done: Callable[[], bool],
        limit: float,
        what: Callable[[], str],
        tick: Callable[[], None] | None = None,
    ) -> str | None:
        deadline = time.monotonic() + limit
        while not done():
            dead = [f"{name} (exit {p.returncode})" for name, p in processes if p.poll() is not None]
            if dead:
                return f"{', '.join(dead)} ended early (see {output}/<name>.log)"
            if time.monotonic() > deadline:
                return f"timed out after {limit:g} s waiting for {what()} (see {output}/<name>.log)"
            executor.spin_once(timeout_sec=0.01)
            if tick is not None:
                tick()
        return None

    try:
        driver = Driver(node, path)
        mover = Mover(node, exc, exc.limits.reference)
        seen = {"command": False, "motion": False}

        def answered(msg: JointState) -> None:
            seen["command"] |= any(v != 0.0 for v in msg.velocity)

        def moved(msg: JointState) -> None:
            # Displacement, not only speed: on a slow machine the probe's motion may be over before
            # this callback first runs. Only a command moves the simulator off its start.
            seen["motion"] |= any(abs(v) > MOVING for v in msg.velocity) or (
                len(msg.position) == len(at_rest) and bool(np.max(np.abs(msg.position - at_rest)) > MOVED)
            )

        # The start-up round trip watches the chain's outputs; these go again before the cycle.
        commands = node.create_subscription(JointState, "cylinder_rate_commands", answered, 1)
        states = node.create_subscription(JointState, "cylinder_lengths", moved, 1)
        expected = expected_graph()
        # Our own endpoints matched with theirs (the DDS match, not only the graph entry):
        # (who, topic, matched count, how many).
        matches = [
            ("the IK and the recorder", "target_bucket_twist", driver.target.get_subscription_count, 2),
            ("the recorder", "reference_bucket_pose", driver.reference_pose.get_subscription_count, 1),
            ("the recorder", "reference_bucket_twist", driver.reference_twist.get_subscription_count, 1),
            ("excavator_forward", "bucket_pose", driver.poses.get_publisher_count, 1),
            ("excavator_velocity_ik", "cylinder_rate_commands", commands.get_publisher_count, 1),
            ("excavator_sim", "cylinder_lengths", states.get_publisher_count, 1),
            (
                "the simulator and the recorder",
                "cylinder_rate_commands",
                mover.commands.get_subscription_count,
                2,
            ),
            ("the recorder", "planned_joint_states", mover.planned.get_subscription_count, 1),
        ]

        def graph_missing() -> list[str]:
            def present(kind: str, topic: str) -> set[str]:
                infos = (
                    node.get_publishers_info_by_topic(topic)
                    if kind == "publishes"
                    else node.get_subscriptions_info_by_topic(topic)
                )
                return {info.node_name for info in infos}

            return (
                missing_endpoints(expected, present)
                + [
                    f"{who} matching the driver on /{topic}"
                    for who, topic, count, least in matches
                    if count() < least
                ]
                + ([] if mover.client.service_is_ready() else ["excavator_ik_server serving /plan_path"])
            )

        failure = spin_until(lambda: not graph_missing(), CONNECT_TIMEOUT, lambda: "; ".join(graph_missing()))
        if failure is None:
            say(f"connected: {len(processes)} processes, {len(expected) + len(matches)} endpoints matched")
            driver.active = True
            # The round trip: a hold target raised by PROBE -> velocity IK (on the simulator's state)
            # -> cylinder_rate_commands -> the simulator moves -> excavator_forward -> bucket_pose.
            failure = spin_until(
                lambda: seen["command"] and seen["motion"],
                ROUND_TRIP_TIMEOUT,
                lambda: (
                    "the simulator to move on the velocity IK's command (excavator_sim, cylinder_lengths)"
                    if seen["command"]
                    else "a cylinder_rate_commands answer from excavator_velocity_ik to target_bucket_twist"
                    if driver.hold_error < np.inf
                    else "the first bucket_pose from excavator_forward"
                ),
            )
        if failure is None:
            driver.probe = 0.0
            node.destroy_subscription(commands)
            node.destroy_subscription(states)
            failure = spin_until(
                lambda: driver.hold_error < SETTLED,
                ROUND_TRIP_TIMEOUT,
                lambda: f"the bucket to settle at the path's start (off by {1e3 * driver.hold_error:.1f} mm)",
            )
        if failure is None:
            say("first command round trip: target -> velocity IK -> simulator -> forward -> driver")
            print(f"excavator_demo: driving a {path.duration:.1f} s digging cycle", flush=True)
            driver.start()

            def show() -> None:
                line = driver.progress()
                if line is not None:
                    print(line, flush=True)

            failure = spin_until(
                lambda: driver.elapsed() > path.duration + 1.0,
                timeout,
                lambda: f"the cycle to finish (at {driver.elapsed():.1f} of {path.duration:.1f} s)",
                show,
            )
        if failure is None:
            # No more targets: the velocity IK stops the machine (zero rates once) after its timeout
            # and then stays silent, leaving cylinder_rate_commands to the planned move.
            driver.active = driver.running = False
            mover.watching = True
            failure = spin_until(
                lambda: mover.ik_stopped,
                ROUND_TRIP_TIMEOUT,
                lambda: "excavator_velocity_ik to stop after the last target",
            )
        if failure is None:
            future = mover.client.call_async(mover.request())
            failure = spin_until(
                future.done, PLAN_TIMEOUT, lambda: "the plan_path answer of excavator_ik_server"
            )
        if failure is None:
            answer = future.result()
            if not answer.success:
                failure = f"plan_path refused the way back: {answer.message}"
            else:
                points = answer.trajectory.points
                mover.trajectory = planned_move.Trajectory.from_points(
                    list(answer.trajectory.joint_names),
                    [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in points],
                    [list(p.positions) for p in points],
                    [list(p.velocities) for p in points],
                )
                say(f"plan_path back to the start: {answer.message}")
                shown = [0.0]

                def show_move() -> None:
                    if mover.clock.t >= shown[0] + PROGRESS_PERIOD:
                        shown[0] += PROGRESS_PERIOD
                        say(f"planned move at {mover.clock.t:.1f} of {mover.trajectory.duration:.1f} s")

                failure = spin_until(
                    lambda: mover.arrived is not None,
                    timeout,
                    lambda: (
                        f"the planned move to finish (at {mover.clock.t:.1f} of "
                        f"{mover.trajectory.duration:.1f} s)"
                    ),
                    show_move,
                )
        return failure, driver, mover
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
        say("stopping the nodes (the recorder then adds the visual topics to the bag)")
        stop_processes(processes)
        say("nodes stopped")


def move_report(output: Path, exc: Excavator, mover: Mover) -> str:
    """The planned move from the bag (the simulator's states while it ran, the plan): its plot
    (PLANNED_MOVE), peak speeds against the limits, tracking and arrival errors, as lines."""
    arrays = BagReader(output / "bag").arrays(["/cylinder_lengths", "/joint_states"])
    cylinders, swing = arrays["/cylinder_lengths"], arrays["/joint_states"]
    start_ns, end_ns = mover.clock.start_ns, mover.clock.last_ns
    stamps = cylinders.stamp_ns()
    stamps = stamps[(stamps >= start_ns) & (stamps <= end_ns)]
    stamps = np.intersect1d(stamps, swing.stamp_ns())  # the simulator stamps both alike
    ic = np.searchsorted(cylinders.stamp_ns(), stamps)
    js = np.searchsorted(swing.stamp_ns(), stamps)
    d = np.column_stack(
        (swing.by_name("position", JOINTS[:1])[js], cylinders.by_name("position", CYLINDERS)[ic])
    )
    d_dot = np.column_stack(
        (swing.by_name("velocity", JOINTS[:1])[js], cylinders.by_name("velocity", CYLINDERS)[ic])
    )
    plan, arrived, lim = mover.trajectory, mover.arrived, exc.limits
    png = planned_move.plot(output / PLANNED_MOVE, exc, (stamps - start_ns) * 1e-9, d, d_dot, plan)
    units = ["rad/s", "m/s", "m/s", "m/s"]
    lines = [
        f"planned move back to the start (plan_path, {len(plan.t)} points, {plan.duration:.2f} s; "
        f"executed in {(end_ns - start_ns) * 1e-9:.2f} s of simulator time incl. "
        f"{planned_move.SETTLE:g} s to settle):",
        "  actuator         planned peak / limit    simulated peak   max |planned - simulated|",
    ]
    for i, name in enumerate(ACTUATORS):
        lines.append(
            f"  {name:<15}  {np.max(np.abs(plan.qd[:, i])):.3f} / {lim.max_rates[i]:.2f} "
            f"{units[i]:<6}  {np.max(np.abs(d_dot[:, i])):.3f} {units[i]:<6}  "
            f"{mover.max_error[i]:.2e}"
        )
    lines.append(f"  plot: {png}")
    tolerance = planned_move.TOLERANCE
    errors = ", ".join(f"{e:.1e}" for e in arrived.error)
    verdict = "reached" if arrived.ok else "NOT reached"
    lines.append(
        f"  arrival: |D - start| = {errors} (swing rad, cylinders m; tolerance "
        f"{tolerance[0]:g} rad, {tolerance[1]:g} m), tip {1e3 * arrived.tip_error:.2f} mm "
        f"(tolerance {1e3 * planned_move.TIP_TOLERANCE:g} mm): {verdict}"
    )
    return "\n".join(lines)


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
    began = time.monotonic()

    @contextmanager
    def step(what: str) -> Iterator[None]:
        # Every step that takes more than a few seconds says so when it starts and ends, so the
        # demo is never silent for long (the cycle and the planned move print every 5 s).
        print(f"excavator_demo: {what} ...", flush=True)
        yield
        print(f"excavator_demo: {what}: done ({time.monotonic() - began:.1f} s)", flush=True)

    os.environ.setdefault("MPLBACKEND", "Agg")
    from excavator_kinematics.demo.cycle_report import report  # matplotlib only once the backend is set
    from manipulator_kinematics.bag.asbuilt import process_bag

    args.output.mkdir(parents=True, exist_ok=True)
    exc = Excavator.default()
    start_q = exc.pose(exc.limits.reference)  # the simulator starts at the reference lengths
    path = demo_cycle(
        np.r_[np.hypot(start_q[0], start_q[1]), np.arctan2(start_q[1], start_q[0]), start_q[2:]]
    )
    with isolated() as network:  # never join a ROS graph around (manipulator_kinematics.ros_domain)
        print(f"excavator_demo: {network}", flush=True)
        failure, driver, mover = run_cycle(args.output, path, args.timeout, exc.limits.reference[1:], exc)
    if failure is not None:
        print(f"excavator_demo: FAILED: {failure}", file=sys.stderr)
        return 1
    start_ns, end_ns = driver.clock.start_ns, driver.clock.last_ns
    with step("reading the bag, plotting figs. 11 and 12"):
        summary = report(args.output / "bag", args.output, exc, path, start_ns, end_ns)
    print(summary.text)
    said = [time.monotonic()]

    def frames(frame: int, total: int) -> None:
        if time.monotonic() - said[0] >= PROGRESS_PERIOD:
            said[0] = time.monotonic()
            print(f"    frame {frame + 1} / {total} ({said[0] - began:.1f} s)", flush=True)

    with step("drawing the animation"):
        gif = animation(args.output / "bag", args.output / ANIMATION, exc, start_ns, end_ns, frames)
    print(
        f"  animation: {gif} ({gif.stat().st_size / 1e6:.2f} MB); Foxglove: open {args.output / 'bag'} "
        f"(docs/visualisation.md)"
    )
    delay = 1e3 * np.percentile(driver.delays, [50, 99])
    print(
        f"  driver: got bucket_pose {delay[0]:.1f} ms (p50) / {delay[1]:.1f} ms (p99) after its stamp; "
        f"{driver.skipped} of {len(driver.delays)} older than {MAX_POSE_AGE:g} s not acted on; "
        f"cycle clock held {driver.clock.held:.2f} s over gaps longer than {MAX_CLOCK_STEP:g} s"
    )
    with step("plotting the planned move"):
        moved = move_report(args.output, exc, mover)
    print(moved)
    with step("mapping what the bucket dug (mk_asbuilt)"):
        dug = process_bag(args.output / "bag", args.output / "asbuilt", [], cell=0.1)
    for table in dug.tables:
        print(f"  as-built: {table['rows']} samples in {table['file']}; surface, CSV and map beside it")
    if dug.error:
        print(f"  as-built: not made: {dug.error}")
    print(f"excavator_demo: finished in {time.monotonic() - began:.1f} s", flush=True)
    if not mover.arrived.ok:
        print(
            f"excavator_demo: FAILED: the planned move did not arrive at the start "
            f"({moved.splitlines()[-1].strip()})",
            file=sys.stderr,
        )
        return 1
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
