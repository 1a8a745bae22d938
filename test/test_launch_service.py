"""launch/*.launch.xml run for real: ROS 2 launch's LaunchService (jazzy) starts each file, as
``ros2 launch`` does, and its nodes must talk to each other and to this test (issue 28 items 1
and 8). Skipped where ``launch_ros`` is not installed (README, "Launch files": it is pure Python,
scripts/install_launch.sh puts it into the venv).

The package is found as after a colcon build: a prefix with its ament index entry,
``share/manipulator_kinematics/{launch,config,urdf}`` and the console scripts in
``lib/manipulator_kinematics``. robot_state_publisher (C++, not in the venv) is either absent
(a headless box: the launch must fail before it starts anything, or run with
``robot_state_publisher:=false``) or a stand-in that does what the launch files rely on: it
publishes its ``robot_description`` parameter on ``robot_description`` (transient local), so
the test sees which URDF the launch file gave it.
"""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_harness import REPO, Probe
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.registry import machines
from manipulator_kinematics_interfaces.srv import SolveFK

pytestmark = [
    pytest.mark.skipif(
        importlib.util.find_spec("launch_ros") is None or importlib.util.find_spec("launch_xml") is None,
        reason="launch and launch_ros (jazzy) are not installed: bash scripts/install_launch.sh (README)",
    ),
    pytest.mark.ros,
    pytest.mark.slow,
]

TIMEOUT = 60.0  # a launch starts 3-5 Python processes: several seconds each on a loaded machine
QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
PKG = "manipulator_kinematics"

# What ``ros2 launch FILE ARG:=VALUE ...`` does, without the ros2 CLI (not on PyPI either).
# launch_ros imports composition_interfaces for composable nodes, which these files do not use;
# the PyPI ROS wheels do not have it, so where it is missing an empty stand-in takes its place.
RUN_LAUNCH = """
import importlib.util, sys, types
if importlib.util.find_spec("composition_interfaces") is None:
    stand_in = sys.modules["composition_interfaces"] = types.ModuleType("composition_interfaces")
    stand_in.srv = sys.modules["composition_interfaces.srv"] = types.ModuleType("composition_interfaces.srv")
    stand_in.srv.__getattr__ = lambda name: types.SimpleNamespace(Request=object, Response=object)
from launch import LaunchService
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import AnyLaunchDescriptionSource
path, *pairs = sys.argv[1:]
service = LaunchService()
service.include_launch_description(IncludeLaunchDescription(
    AnyLaunchDescriptionSource(path), launch_arguments=[pair.split(":=", 1) for pair in pairs]))
sys.exit(service.run())
"""

# The stand-in robot_state_publisher: its robot_description parameter on robot_description.
RSP_STAND_IN = f"""#!{sys.executable}
import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String
from manipulator_kinematics.node_util import run

def build():
    node = Node("robot_state_publisher", automatically_declare_parameters_from_overrides=True)
    qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    publisher = node.create_publisher(String, "robot_description", qos)
    publisher.publish(String(data=node.get_parameter("robot_description").value))
    node.keep = publisher
    return node

raise SystemExit(run(build))
"""


def _prefix(root: Path, package: str) -> Path:
    (root / "share/ament_index/resource_index/packages").mkdir(parents=True, exist_ok=True)
    (root / "share/ament_index/resource_index/packages" / package).touch()
    (root / "lib" / package).mkdir(parents=True, exist_ok=True)
    (root / "share" / package).mkdir(parents=True, exist_ok=True)
    return root


@pytest.fixture(scope="module")
def prefixes(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """AMENT_PREFIX_PATH without and with the stand-in robot_state_publisher."""
    ours = _prefix(tmp_path_factory.mktemp("install"), PKG)
    for folder in ("launch", "config", "urdf"):
        (ours / "share" / PKG / folder).symlink_to(REPO / folder)
    (ours / "share" / PKG / "package.xml").symlink_to(REPO / "package.xml")
    from importlib.metadata import distribution

    for entry in distribution(PKG).entry_points:
        if entry.group == "console_scripts":
            (ours / "lib" / PKG / entry.name).symlink_to(console_script(entry.name))
    rsp = _prefix(tmp_path_factory.mktemp("rsp"), "robot_state_publisher")
    script = rsp / "lib/robot_state_publisher/robot_state_publisher"
    script.write_text(RSP_STAND_IN)
    script.chmod(0o755)
    base = os.environ.get("AMENT_PREFIX_PATH", sys.prefix)
    return {"missing": f"{ours}:{base}", "stand-in": f"{rsp}:{ours}:{base}"}


def processes_of(namespace: str) -> list[str]:
    """Command lines of the running processes remapped into ``namespace`` (launch_ros gives every
    node ``-r __ns:=NAMESPACE``)."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            args = cmdline.read_bytes().split(b"\0")
            state = (cmdline.parent / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if f"__ns:={namespace}".encode() in args and state != "Z":
            found.append(b" ".join(args).decode(errors="replace"))
    return found


class Launch:
    """``ros2 launch manipulator_kinematics FILE ARGS`` as a process (LaunchService), its output in
    a file."""

    def __init__(self, file: str, namespace: str, env_path: str, log: Path, *args: str) -> None:
        self.namespace = namespace
        self.log_path = log
        env = {**os.environ, "AMENT_PREFIX_PATH": env_path}
        with log.open("w") as out:
            self.process = subprocess.Popen(
                [
                    sys.executable,
                    "-c",
                    RUN_LAUNCH,
                    str(REPO / "launch" / file),
                    f"namespace:={namespace}",
                    *args,
                ],
                stdout=out,
                stderr=subprocess.STDOUT,
                env=env,
                start_new_session=True,
            )

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self, probe: Probe) -> int:
        """SIGINT to the launch and its nodes, as Ctrl-C in a terminal (its process group: launch
        then sends none itself); the exit code once launch and every node ended. (Whether a node
        needed launch's SIGTERM, 5 s after SIGINT, is not checked: at a load average of 20-24 on
        2 cores the excavator chain's nodes did; the 2 s bound is test_node_shutdown's.)"""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
        probe.wait_until(
            lambda: self.process.poll() is not None and not processes_of(self.namespace),
            TIMEOUT,
            f"the end of the launch in {self.namespace}",
        )
        return self.process.returncode


@pytest.fixture
def launched(probe: Probe, tmp_path: Path) -> Iterator[Callable[..., Launch]]:
    started: list[Launch] = []

    def start(file: str, namespace: str, env_path: str, *args: str) -> Launch:
        launch = Launch(file, namespace, env_path, tmp_path / f"{namespace.strip('/')}.log", *args)
        started.append(launch)
        return launch

    yield start
    for launch in started:
        try:
            launch.stop(probe)
        finally:
            if launch.process.poll() is None:
                launch.process.kill()
                launch.process.wait()


def mk_urdf(machine: str, params: Path) -> str:
    return subprocess.run(
        [console_script("mk_urdf"), machine, "--params-file", str(params)],
        capture_output=True,
        text=True,
        check=True,
        timeout=TIMEOUT,
    ).stdout


def described(probe: Probe, namespace: str) -> list[str]:
    """The robot_description messages of ``namespace`` (filled as they arrive)."""
    got: list[str] = []
    probe.node.create_subscription(
        String, f"{namespace}/robot_description", lambda m: got.append(m.data), LATCHED
    )
    return got


def fk_answers(probe: Probe, namespace: str, machine: str) -> Callable[[], int]:
    """Sends solve_fk requests (at the middle of the joint limits) while called; answers so far."""
    entry = machines()[machine]
    model = entry.model()
    limits = entry.limits(model)
    middle = 0.5 * (np.asarray(limits.lower) + np.asarray(limits.upper))
    request = SolveFK.Request(joint_state=JointState(name=list(limits.names), position=middle.tolist()))
    client = probe.node.create_client(SolveFK, f"{namespace}/solve_fk")
    answers: list[bool] = []

    def answered() -> int:
        if client.service_is_ready() and len(answers) < 1:
            client.call_async(request).add_done_callback(lambda f: answers.append(f.result().success))
        return sum(answers)

    return answered


def joint_traffic(probe: Probe, namespace: str, machine: str) -> Callable[[], int]:
    """Sends joint_states (the middle of the limits) while called; tool_pose messages so far."""
    entry = machines()[machine]
    limits = entry.limits(entry.model())
    middle = 0.5 * (np.asarray(limits.lower) + np.asarray(limits.upper))
    states = probe.node.create_publisher(JointState, f"{namespace}/joint_states", QOS)
    poses: list[PoseStamped] = []
    probe.node.create_subscription(PoseStamped, f"{namespace}/tool_pose", poses.append, QOS)

    def send() -> int:
        msg = JointState(name=list(limits.names), position=middle.tolist(), velocity=[0.0] * len(middle))
        msg.header.stamp = probe.node.get_clock().now().to_msg()
        states.publish(msg)
        return len(poses)

    return send


def excavator_chain_traffic(probe: Probe, namespace: str) -> Callable[[], int]:
    """The simulator's state reaches the forward node (bucket_pose), a bucket target the velocity
    IK (cylinder_rate_commands) and its commands the simulator: bucket poses that move."""
    target = probe.node.create_publisher(TwistStamped, f"{namespace}/target_bucket_twist", QOS)
    poses: list[PoseStamped] = []
    probe.node.create_subscription(PoseStamped, f"{namespace}/bucket_pose", poses.append, QOS)

    def send() -> int:
        twist = TwistStamped()
        twist.header.stamp = probe.node.get_clock().now().to_msg()
        twist.header.frame_id = "base_link"
        twist.twist.linear.z = -0.3
        target.publish(twist)
        if len(poses) < 2:
            return 0
        moved = poses[-1].pose.position.z - poses[0].pose.position.z
        return 1 if moved < -0.05 else 0  # the bucket went down by 5 cm: the chain is closed

    return send


def excavator_traffic(probe: Probe, namespace: str) -> Callable[[], int]:
    """Cylinder lengths and swing in, bucket_pose out (the machine's own sensors' role)."""
    from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator
    from excavator_kinematics.nodes import message_codec

    cylinders = probe.node.create_publisher(JointState, f"{namespace}/cylinder_lengths", QOS)
    swing = probe.node.create_publisher(JointState, f"{namespace}/joint_states", QOS)
    poses: list[PoseStamped] = []
    probe.node.create_subscription(PoseStamped, f"{namespace}/bucket_pose", poses.append, QOS)
    D = Excavator.default().limits.reference

    def send() -> int:
        stamp = probe.node.get_clock().now().to_msg()
        swing.publish(message_codec.joint_state(stamp, JOINTS[:1], D[:1], [0.0]))
        cylinders.publish(message_codec.joint_state(stamp, CYLINDERS, D[1:], [0.0, 0.0, 0.0]))
        return len(poses)

    return send


# launch file -> (machine, params file, the traffic that shows its nodes talk)
FILES = {
    "scara.launch.xml": ("scara", "scara.yaml"),
    "pump_boom.launch.xml": ("pump_boom", "pump_boom.yaml"),
    "tool_changer.launch.xml": ("tool_changer", "tool_changer.yaml"),
    "palletizer.launch.xml": ("palletizer", "irb460.yaml"),
    "excavator.launch.xml": ("excavator", "excavator_cet200.yaml"),
    "excavator_chain.launch.xml": ("excavator", "excavator_cet200.yaml"),
    "wheel_loader.launch.xml": ("wheel_loader", "wheel_loader_wl20.yaml"),
    "knuckle_crane.launch.xml": ("knuckle_crane", "knuckle_crane_kc100.yaml"),
}


def test_every_launch_file_is_run_here() -> None:
    assert set(FILES) == {path.name for path in (REPO / "launch").glob("*.launch.xml")}


@pytest.mark.parametrize("file", sorted(FILES))
def test_a_launch_file_starts_nodes_that_talk_and_gives_the_machines_urdf(
    probe: Probe, launched: Callable[..., Launch], prefixes: dict[str, str], file: str
) -> None:
    machine, params = FILES[file]
    namespace = f"/launch_{file.split('.')[0]}"
    urdf = described(probe, namespace)
    if file == "excavator_chain.launch.xml":
        traffic = excavator_chain_traffic(probe, namespace)
    elif file == "excavator.launch.xml":
        traffic = excavator_traffic(probe, namespace)
    else:
        traffic = joint_traffic(probe, namespace, machine)
    answers = fk_answers(probe, namespace, machine) if file != "excavator_chain.launch.xml" else lambda: 1
    launch = launched(file, namespace, prefixes["stand-in"], "markers:=true")
    probe.wait_until(
        lambda: (traffic() > 0 and answers() > 0 and urdf) or launch.process.poll() is not None,
        TIMEOUT,
        f"the nodes of {file}",
    )
    assert launch.process.poll() is None, launch.log()
    assert urdf == [mk_urdf(machine, config_path(params))]
    assert launch.stop(probe) == 0, launch.log()


def test_the_urdf_is_that_of_the_machine_given(
    probe: Probe, launched: Callable[..., Launch], prefixes: dict[str, str], tmp_path: Path
) -> None:
    """params_file:=another SCARA: robot_state_publisher gets its URDF (it got the shipped one)."""
    document = yaml.safe_load(config_path("scara.yaml").read_text())
    document["/**"]["ros__parameters"]["scara"]["l2"] = 0.24  # m, was 0.30
    params = tmp_path / "small_scara.yaml"
    params.write_text(yaml.safe_dump(document))
    namespace = "/launch_scara_given"
    urdf = described(probe, namespace)
    launch = launched("scara.launch.xml", namespace, prefixes["stand-in"], f"params_file:={params}")
    probe.wait_until(lambda: urdf or launch.process.poll() is not None, TIMEOUT, "robot_description")
    assert urdf == [mk_urdf("scara", params)], launch.log()
    assert urdf != [mk_urdf("scara", config_path("scara.yaml"))]
    assert launch.stop(probe) == 0, launch.log()
    namespace = "/launch_scara_text"
    urdf = described(probe, namespace)
    launch = launched(
        "scara.launch.xml", namespace, prefixes["stand-in"], "robot_description:=<robot name='given'/>"
    )
    probe.wait_until(lambda: urdf or launch.process.poll() is not None, TIMEOUT, "robot_description")
    assert urdf == ["<robot name='given'/>"], launch.log()
    assert launch.stop(probe) == 0, launch.log()


def test_without_robot_state_publisher_a_launch_fails_leaving_nothing_or_runs_without_it(
    probe: Probe, launched: Callable[..., Launch], prefixes: dict[str, str]
) -> None:
    """A headless box: robot_state_publisher not installed. By default the launch fails and has
    started nothing (it left sim, forward, velocity IK and IK server running with parent PID 1);
    with robot_state_publisher:=false the chain runs."""
    namespace = "/launch_no_rsp"
    launch = launched("excavator_chain.launch.xml", namespace, prefixes["missing"])
    probe.wait_until(lambda: launch.process.poll() is not None, TIMEOUT, "the failed launch to end")
    assert launch.process.returncode != 0, launch.log()
    assert "robot_state_publisher" in launch.log(), launch.log()
    assert not processes_of(namespace), launch.log()

    traffic = excavator_chain_traffic(probe, "/launch_rsp_off")
    launch = launched(
        "excavator_chain.launch.xml", "/launch_rsp_off", prefixes["missing"], "robot_state_publisher:=false"
    )
    probe.wait_until(lambda: traffic() > 0 or launch.process.poll() is not None, TIMEOUT, "the chain")
    assert launch.process.poll() is None, launch.log()
    assert launch.stop(probe) == 0, launch.log()
