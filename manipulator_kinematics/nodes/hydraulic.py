"""The nodes of the hydraulic family: any machine file runs them (``hydraulic_*`` executables).

Each runs the machine of the ``hydraulic_machine`` section of its ``--params-file`` (e.g.
``hydraulic_forward --ros-args --params-file config/wheel_loader_wl20.yaml``); with none it
refuses to start and names the shipped machine files. The registry record (wheel_loader,
knuckle_crane, or for a user's own file the family's first) lends its name; the node settings'
defaults are config/hydraulic_nodes.yaml. The actuators are joints named as in the machine file
(``swing_joint`` in rad, each cylinder's length in m), all in one JointState (``joint_states``).

* ``hydraulic_forward``: joint_states -> tool_pose, tool_twist (the generic forward node on
  :class:`~manipulator_kinematics.hydraulic.machine.FamilyArm`) and, at
  ``urdf_joint_states_rate``, ``urdf_joint_states``: every joint of the machine's URDF (the loops'
  passive joints computed), for robot_state_publisher (the URDF cannot close a loop:
  :mod:`manipulator_kinematics.hydraulic.drawing`). With ``design_surface.file`` (a LandXML TIN
  in the site frame, the machine placed by ``design_surface.site_*``) the grade outputs of the
  excavator's forward node: ``grade/tip``, ``grade/left``, ``grade/right`` (PointStamped: easting,
  northing, height of the tool point and of the ends of its edge, tool point +- width/2 across the
  boom plane, above the surface; + = cut) and ``grade/status``
  (:mod:`manipulator_kinematics.nodes.surface_grade`).
* ``hydraulic_velocity_ik``: target_twist (TwistStamped, base frame) + joint_states ->
  rate_commands (JointState velocities of the actuators) by
  :func:`manipulator_kinematics.hydraulic.control.rate_command` on the task rows the machine file
  commands (``tool.velocity_rows``: the loader z and alpha, so the reach follows; the crane x, y,
  z); a status (DiagnosticArray: tracking, slowed, stopped and why); a constant target's drift
  off its line corrected at ``line_gain`` (a stop there holds until the target changes). No
  accepted target for ``command_timeout`` s, or a state that cannot be used: zero rates once,
  then nothing. With ``zones_file`` (docs/zones.md) each command is scaled once more by the
  avoidance zones' factor for the machine's monitored points
  (:meth:`~manipulator_kinematics.hydraulic.model.HydraulicModel.monitored`), as the excavator's
  velocity IK does (:class:`~manipulator_kinematics.nodes.zone_output.ZoneOutput`): it slows
  approaching a zone and stops at it in its own direction, the status names zone and point, and
  ``zone_clearance`` carries each zone's smallest clearance.
* ``hydraulic_sim``: rate_commands -> joint_states at ``rate`` Hz
  (:class:`manipulator_kinematics.hydraulic.control.Plant`).
* ``hydraulic_ik_server``: solve_ik, solve_fk (the generic server; one branch, ``nearest``) and
  ``plan_path`` (manipulator_kinematics_interfaces/srv/PlanPath, as the excavator's): straight
  tool-point lines through the waypoints from the seed (else the reference state), holding what
  the point does not fix (the tool angle of a three-joint arm, the crane's extension), timed
  within every actuator's max speed, ``path.tip_speed`` and ``path.acceleration``
  (:mod:`manipulator_kinematics.hydraulic.path`); the trajectory in sensor readings as on
  joint_states. A path leaving the stroke box ends at the farthest reachable point: success false
  (NO_IK_SOLUTION), the reason (the actuator at its stroke end), ``last_reachable_waypoint`` and
  the trajectory up to there; with ``zones_file`` it ends before a monitored point enters an
  avoidance zone (base-frame zones). Requests beyond the bounds of every plan are refused as the
  excavator's are (:class:`~manipulator_kinematics.nodes.ik_server.PlanPathServer`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TwistStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from manipulator_kinematics.hydraulic.control import (
    SLOWED,
    STOPPED,
    TRACKING,
    Plant,
    describe,
    rate_command,
    task_rates,
    toward_line,
)
from manipulator_kinematics.hydraulic.description import SECTION
from manipulator_kinematics.hydraulic.drawing import urdf_joint_values
from manipulator_kinematics.hydraulic.model import HydraulicModel, StrokeError
from manipulator_kinematics.hydraulic.path import plan_clear
from manipulator_kinematics.joint_state import (
    PLAUSIBILITY_FACTOR,
    InputError,
    decode_joint_state,
    joint_values,
)
from manipulator_kinematics.landxml import read_landxml
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes import run_node
from manipulator_kinematics.nodes.base import FRAME_PREFIX, MachineNode, input_qos, input_reliability
from manipulator_kinematics.nodes.forward import SETTINGS as FORWARD_SETTINGS
from manipulator_kinematics.nodes.forward import ForwardNode
from manipulator_kinematics.nodes.help import help_text, wants_help
from manipulator_kinematics.nodes.ik_server import PATH_SETTINGS, PlanPathServer
from manipulator_kinematics.nodes.ik_server import SETTINGS as IK_SETTINGS
from manipulator_kinematics.nodes.surface_grade import DESIGN_SURFACE, GRADE_TOPICS, SurfaceGrade
from manipulator_kinematics.nodes.zone_output import ZoneOutput
from manipulator_kinematics.param_files import ConfigError, given_parameters
from manipulator_kinematics.registry import Machine, by_section, machines
from manipulator_kinematics.schema import Number, Numbers, Text
from manipulator_kinematics.tool_path import ToolPlan
from manipulator_kinematics.zone_guard import ZoneGuard
from manipulator_kinematics_interfaces.srv import PlanPath

DEFAULTS_FILE = "hydraulic_nodes.yaml"
LEVELS = {TRACKING: DiagnosticStatus.OK, SLOWED: DiagnosticStatus.WARN, STOPPED: DiagnosticStatus.WARN}

_COMMON = {
    "qos_depth": Number(min=1, max=100_000, integer=True, doc="keep-last depth of the publishers"),
    "warning_period": Number(
        min=0.0, max=3600.0, unit="s", doc="the same kind of rejection is logged at most this often"
    ),
}


def family() -> list[Machine]:
    """The registered machines of the family, by name."""
    return [m for m in machines().values() if m.section == SECTION]


def family_machine_of(argv: Sequence[str]) -> Machine:
    """The family machine whose file the ``--params-file`` files of ``argv`` hold."""
    given = given_parameters(argv)
    if SECTION in given:
        found = by_section(SECTION, given[SECTION])
        if found is not None:
            return found
    files = ", ".join(f"config/{m.config_file} ({m.name})" for m in family())
    raise ConfigError(f"no {SECTION} section in the params files; give a machine file of the family: {files}")


def family_main(node_class: type[MachineNode], node_name: str, args: Sequence[str] | None) -> int:
    """Run ``node_class`` for the family machine of the params files (module docstring)."""
    argv = list(sys.argv if args is None else args)
    if wants_help(argv):
        print(help_text(node_class, family()[0], node_name, DEFAULTS_FILE))
        return 0
    try:
        machine = family_machine_of(argv)
    except ConfigError as error:
        print(f"configuration error: {error}", file=sys.stderr)
        return 2
    return run_node(node_class, machine.name, node_name, argv)


# ------------------------------------------------------------------------------------------ forward
FORWARD = {
    **FORWARD_SETTINGS,
    "urdf_joint_states_rate": Number(
        min=0.0, max=10_000.0, unit="Hz", doc="of urdf_joint_states by input stamps; 0 = every input"
    ),
    "design_surface": DESIGN_SURFACE,
    "topics": {
        **FORWARD_SETTINGS["topics"],
        "urdf_joint_states": Text(empty=False, doc="output: every URDF joint, for robot_state_publisher"),
        **GRADE_TOPICS,
    },
}


class HydraulicForward(ForwardNode):
    """The generic forward node plus ``urdf_joint_states`` (module docstring)."""

    SETTINGS = FORWARD
    DEFAULTS_FILE = DEFAULTS_FILE

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        s = self.settings
        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        self.urdf_pub = self.create_publisher(JointState, s["topics"]["urdf_joint_states"], qos)
        rate = s["urdf_joint_states_rate"]
        self.urdf_period_ns = 0 if rate == 0.0 else int(1e9 / rate)
        self.urdf_sent_ns: int | None = None
        surface = s["design_surface"]
        self.grade = (
            SurfaceGrade(self, surface, s["topics"], self.model.hydraulic.description.width, qos, self.log)
            if surface["file"]
            else None
        )

    def on_joint_state(self, raw: bytes) -> None:
        super().on_joint_state(raw)
        try:
            decoded = decode_joint_state(raw)
            q, _ = joint_values(decoded, self.joint_names, require_position=True)
        except InputError:
            return  # logged by the forward node
        stamp_ns = decoded.sec * 1_000_000_000 + decoded.nanosec
        if self.grade is not None:
            self.publish_grade(decoded, stamp_ns, q)
        if self.urdf_sent_ns is not None and 0 <= stamp_ns - self.urdf_sent_ns < self.urdf_period_ns:
            return
        with np.errstate(all="ignore"):
            values = urdf_joint_values(self.model, self.model.true_state(q))
        if not all(np.isfinite(v) for v in values.values()):
            return  # the linkage does not close there: the forward node said so
        self.urdf_sent_ns = stamp_ns
        header = Header()
        header.stamp.sec, header.stamp.nanosec = decoded.sec, decoded.nanosec
        self.urdf_pub.publish(
            JointState(header=header, name=list(values), position=[float(v) for v in values.values()])
        )

    def publish_grade(self, decoded: Any, stamp_ns: int, q: np.ndarray) -> None:
        """The tool point and the ends of its edge above the design surface (module docstring)."""
        with np.errstate(all="ignore"):
            tip = self.model.fkine(q)[:3, 3]
        D = self.model.true_state(q)
        theta1 = float(D[0]) if self.model.hydraulic.swing else 0.0
        if not (np.all(np.isfinite(tip)) and np.isfinite(theta1)):
            return  # the forward node said why
        values = self.grade.values(stamp_ns, theta1, tip.tolist())
        if all(v is None or all(map(np.isfinite, v)) for v in values):
            self.grade.publish((decoded.sec, decoded.nanosec), values)


# ------------------------------------------------------------------------------------- velocity IK
VELOCITY_IK = {
    **_COMMON,
    "base_frame": Text(empty=False, doc="frame_id of target_twist (an empty frame_id means it)"),
    "frame_prefix": FRAME_PREFIX,
    "command_timeout": Number(0.0, 60.0, "s", exclusive_min=True, doc="no target for this long: stop"),
    "state_timeout": Number(0.0, 60.0, "s", exclusive_min=True, doc="a state older than this is not used"),
    "condition_threshold": Number(1.0, 1e12, doc="cond(JC0 S) above which the command slows (damped size)"),
    "stroke_horizon": Number(0.0, 60.0, "s", exclusive_min=True, doc="no actuator reaches an end sooner"),
    "line_gain": Number(
        0.0, 100.0, "1/s", doc="drift off a constant target's line is corrected at this rate; 0 = off"
    ),
    "status_period": Number(0.0, 3600.0, "s", exclusive_min=True, doc="an unchanged status is resent after"),
    "input_queue_depth": Number(1, 1000, integer=True, doc="subscriptions: act on the latest input"),
    "input_reliability": input_reliability("target_twist and joint_states"),
    "zones_file": Text(doc="avoidance zone file (YAML, docs/zones.md) read at start; empty: no zones"),
    "zones_period": Number(
        0.0,
        60.0,
        "s",
        exclusive_min=True,
        doc="longest a command acts before the next one can slow it (state period plus latency)",
    ),
    "zones_stop_time": Number(
        0.0,
        60.0,
        "s",
        exclusive_min=True,
        doc="the actuators stop from full speed within this (deceleration limits: max speed / this)",
    ),
    "zones_lag": Number(
        0.0, 60.0, "s", doc="the actuators' first-order time constant (0: they follow at once)"
    ),
    "topics": {
        "target_twist": Text(empty=False, doc="input: geometry_msgs/TwistStamped of the tool"),
        "joint_states": Text(empty=False, doc="input: sensor_msgs/JointState of the actuators"),
        "rate_commands": Text(empty=False, doc="output: sensor_msgs/JointState velocities"),
        "status": Text(empty=False, doc="output: diagnostic_msgs/DiagnosticArray"),
        "zone_clearance": Text(
            empty=False, doc="output: diagnostic_msgs/DiagnosticArray, per zone its smallest clearance"
        ),
    },
}


def monitored(h: HydraulicModel, D: np.ndarray, D_dot: np.ndarray) -> tuple[np.ndarray, ...]:
    """Positions, velocities and accelerations of the monitored points at a measured state D; a state a
    round-off beyond a stroke end (reading + zero_offset of a state at the end) is taken at the
    end, one farther out is refused (StrokeError)."""
    try:
        return h.monitored_motion(D, D_dot)[1:]
    except StrokeError:  # clipped only then: the clip costs as much as the compiled points
        at_end = np.clip(D, h.lower, h.upper)
        if not np.all(np.abs(at_end - D) <= 1e-9):
            raise
        return h.monitored_motion(at_end, D_dot)[1:]


class HydraulicVelocityIK(MachineNode):
    """target_twist + joint_states -> rate_commands, direction kept (module docstring)."""

    SETTINGS = VELOCITY_IK
    DEFAULTS_FILE = DEFAULTS_FILE

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        s = self.settings
        self.h = self.model.hydraulic
        self.names = self.h.actuator_names
        self.rows = list(self.h.description.velocity_rows)
        self.frame = s["frame_prefix"] + s["base_frame"]
        self.log = ThrottledLog(self, s["warning_period"])
        self.command_timeout_ns = int(s["command_timeout"] * 1e9)
        self.state_timeout_ns = int(s["state_timeout"] * 1e9)
        self.status_period_ns = int(s["status_period"] * 1e9)
        # The fastest tool motion the actuators give at the reference state, each at its limit:
        # a target beyond PLAUSIBILITY_FACTOR x that is refused.
        fastest = np.abs(self.h.jc0(self.h.reference)) @ self.h.max_speed
        self.max_speed = PLAUSIBILITY_FACTOR * float(np.max(fastest) + np.max(self.h.max_speed))
        # The commanded line: (target twist, Q where it began, its Q_dot); another target begins a
        # new one, so does a tool farther than LINE_RESTART from it. A stop on the line holds until
        # the target changes (the correction must not creep the machine on and off at an end).
        self.line: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.stopped_on_line: str | None = None
        self.state: tuple[int, np.ndarray, int] | None = None  # (receipt ns, D, stamp ns)
        self.target: tuple[int, np.ndarray] | None = None  # (receipt ns, [linear, angular])
        self.moving = False
        self.status_sent: tuple[int, str] | None = None
        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        latest = input_qos(s["input_queue_depth"], s["input_reliability"])
        topics = s["topics"]
        self.command_pub = self.create_publisher(JointState, topics["rate_commands"], qos)
        latched = QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        self.status_pub = self.create_publisher(DiagnosticArray, topics["status"], latched)
        self.create_subscription(TwistStamped, topics["target_twist"], self.on_target, latest)
        self.create_subscription(JointState, topics["joint_states"], self.on_state, latest)
        self.create_timer(s["command_timeout"] / 5.0, self.on_timer)
        # Avoidance zones (docs/zones.md): every command scaled so no monitored point enters one.
        self.zones = ZoneOutput.of(
            self,
            s["zones_file"],
            self.h.monitored(self.h.reference, np.zeros(self.h.m))[0],
            self.h.max_speed / s["zones_stop_time"],
            s["zones_period"],
            topics["zone_clearance"],
            s["qos_depth"],
            self.h.description.name,
            read_landxml,
            lag=s["zones_lag"],
        )
        commanded = [self.h.task_names[r] for r in self.rows]
        self.get_logger().info(
            f"{machine.name}: {topics['target_twist']} (rows {commanded} of {list(self.h.task_names)}) "
            f"-> {topics['rate_commands']} {list(self.names)}"
        )

    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def on_state(self, msg: JointState) -> None:
        try:
            readings, _ = joint_values(msg, self.names, require_position=True)
        except InputError as error:
            self.log("error", f"rejected joint_states: {error}")
            return
        stamp = msg.header.stamp
        self.state = (
            self.now_ns(),
            self.model.true_state(readings),
            stamp.sec * 1_000_000_000 + stamp.nanosec,
        )
        if self.target is not None:
            self.command(stamp)
        elif self.zones is not None:  # standing: the clearances still go out
            with contextlib.suppress(ValueError):
                self.zones.watch(stamp, monitored(self.h, self.state[1], np.zeros(self.h.m))[0])

    def on_target(self, msg: TwistStamped) -> None:
        t = msg.twist
        twist = np.array([t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z])
        if msg.header.frame_id not in ("", self.frame):
            self.stop(f"rejected target_twist: frame_id {msg.header.frame_id!r} is not {self.frame!r}")
            return
        with np.errstate(over="ignore", invalid="ignore"):
            size = float(np.linalg.norm(twist))
        if not size <= self.max_speed:  # NaN and inf fail too
            self.stop(
                f"rejected target_twist: {twist.tolist()} not finite or beyond "
                f"{self.max_speed:.6g}: implausible"
            )
            return
        self.target = (self.now_ns(), twist)
        self.command(msg.header.stamp)

    def on_timer(self) -> None:
        if self.target is not None and self.now_ns() - self.target[0] > self.command_timeout_ns:
            self.stop(f"no target_twist for {self.command_timeout_ns * 1e-9:g} s", "info", idle=True)

    def command(self, stamp: Any) -> None:
        """Publish the rates for the current target at the current state (or stop, saying why)."""
        try:
            if self.state is None or self.now_ns() - self.state[0] > self.state_timeout_ns:
                raise InputError("no fresh joint_states" if self.state else "no joint_states received yet")
            D = self.state[1]
            measured = self.h.measured(D)
            jc0, Q = measured.jc0, measured.Q
            if not (np.all(np.isfinite(jc0)) and np.all(np.isfinite(Q))):
                raise InputError(f"the linkage does not close at D = {D.tolist()}")
            twist = self.target[1]
            q_dot = task_rates(D, twist, self.h.swing, self.h.description.has_angle)
            if self.line is None or not np.array_equal(self.line[0], twist):
                self.line, self.stopped_on_line = (twist, Q, q_dot), None
            gain = self.settings["line_gain"]
            correction = toward_line(self.line[1], self.line[2], Q, self.rows, gain)
            if correction is None:  # moved, not drifted: a new line from here
                self.line, self.stopped_on_line = (twist, Q, q_dot), None
                correction = np.zeros_like(Q)
            if self.stopped_on_line is not None:
                self.publish(stamp, np.zeros(len(self.names)))
                self.report(stamp, LEVELS[STOPPED], self.stopped_on_line)
                return
            rates = rate_command(
                jc0[self.rows],
                D,
                (q_dot + correction)[self.rows],
                self.h.lower,
                self.h.upper,
                self.h.max_speed,
                self.settings["condition_threshold"],
                self.settings["stroke_horizon"],
            )
            zone = (
                None
                if self.zones is None
                else self.zones(stamp, *monitored(self.h, D, rates.d_dot), rates.d_dot, self.state[2])
            )
        except ValueError as error:  # InputError, StrokeError, an overflowing target
            self.stop(f"cannot command: {error}", "warning")
            return
        self.publish(stamp, rates.d_dot if zone is None else zone.scale * rates.d_dot)
        self.moving = True
        state, message = describe(rates, self.names)
        if state == STOPPED:
            self.stopped_on_line = message
        elif zone is not None and zone.scale < 1.0:  # the zones slow it further (a zone stop is not held)
            state, message = zone.state, zone.message
        scale = rates.scale * (1.0 if zone is None else zone.scale)
        self.report(stamp, LEVELS[state], message, scale, rates.condition)

    def report(
        self, stamp: Any, level: bytes, message: str, scale: float = 0.0, condition: float = np.nan
    ) -> None:
        now = self.now_ns()
        changed = self.status_sent is None or self.status_sent[1] != message
        if not changed and now - self.status_sent[0] < self.status_period_ns:
            return
        if changed and level != DiagnosticStatus.OK:
            self.log("info", message)
        self.status_sent = (now, message)
        values = {
            "scale": f"{scale:.6g}",
            "condition": f"{condition:.6g}" if np.isfinite(condition) else "n/a",
        }
        status = DiagnosticStatus(
            level=level,
            name=self.get_fully_qualified_name(),
            message=message,
            hardware_id=self.h.description.name,
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )
        self.status_pub.publish(DiagnosticArray(header=Header(stamp=stamp), status=[status]))

    def stop(self, reason: str, severity: str = "error", idle: bool = False) -> None:
        """Log ``reason``; drop the target; zero rates once if a motion may be in force."""
        self.log(severity, reason)
        self.target = None
        now = self.get_clock().now().to_msg()
        if self.moving:
            self.publish(now, np.zeros(len(self.names)))
            self.moving = False
        level = DiagnosticStatus.OK if idle else DiagnosticStatus.WARN
        self.report(now, level, f"idle: {reason}" if idle else f"{STOPPED}: {reason}")

    def publish(self, stamp: Any, d_dot: np.ndarray) -> None:
        # rate_command promises both; a command moves the machine, so it is checked here again.
        if not (np.all(np.isfinite(d_dot)) and np.all(np.abs(d_dot) <= self.h.max_speed)):
            self.log("error", f"command {d_dot.tolist()} not finite or beyond the speed limits: zero sent")
            d_dot = np.zeros(len(self.names))
        self.command_pub.publish(
            JointState(header=Header(stamp=stamp), name=list(self.names), velocity=[float(v) for v in d_dot])
        )


# -------------------------------------------------------------------------------------- simulator
SIM = {
    **_COMMON,
    "rate": Number(0.0, 10_000.0, "Hz", exclusive_min=True, doc="of joint_states"),
    "time_constant": Number(0.0, 60.0, "s", doc="first-order lag of the actuators; 0 = ideal"),
    "command_timeout": Number(0.0, 60.0, "s", exclusive_min=True, doc="no command for this long: stop"),
    "initial_state": Numbers(
        default=None, doc="start D [swing rad, cylinder lengths m] (default: the machine's reference)"
    ),
    "input_queue_depth": Number(1, 1000, integer=True, doc="rate commands: the latest only"),
    "input_reliability": input_reliability("rate_commands"),
    "topics": {
        "rate_commands": Text(empty=False, doc="input: sensor_msgs/JointState velocities"),
        "joint_states": Text(empty=False, doc="output: sensor_msgs/JointState of the actuators"),
    },
}


class HydraulicSim(MachineNode):
    """rate_commands -> joint_states of simulated actuators (module docstring)."""

    SETTINGS = SIM
    DEFAULTS_FILE = DEFAULTS_FILE

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        s = self.settings
        h = self.model.hydraulic
        self.names = h.actuator_names
        start = h.reference if s["initial_state"] is None else np.asarray(s["initial_state"], dtype=float)
        self.plant = Plant(h.lower, h.upper, h.max_speed, start, s["time_constant"])
        self.max_command = PLAUSIBILITY_FACTOR * h.max_speed
        self.command = np.zeros(len(self.names))
        self.command_ns: int | None = None
        self.command_timeout_ns = int(s["command_timeout"] * 1e9)
        self.log = ThrottledLog(self, s["warning_period"])
        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        self.state_pub = self.create_publisher(JointState, s["topics"]["joint_states"], qos)
        latest = input_qos(s["input_queue_depth"], s["input_reliability"])
        self.create_subscription(JointState, s["topics"]["rate_commands"], self.on_command, latest)
        self.last_ns = self.now_ns()
        self.create_timer(1.0 / s["rate"], self.on_timer)
        self.get_logger().info(
            f"{machine.name} simulated at {s['rate']:g} Hz from D = {start.round(6).tolist()}"
        )

    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def on_command(self, msg: JointState) -> None:
        try:
            _, rates = joint_values(msg, self.names, require_velocity=True)
            if np.any(np.abs(rates) > self.max_command):
                raise InputError(f"rates {rates.tolist()} beyond {PLAUSIBILITY_FACTOR:g} x the speed limits")
        except InputError as error:
            self.log("error", f"rejected rate command: {error}")
            return
        self.command, self.command_ns = rates, self.now_ns()

    def on_timer(self) -> None:
        now = self.now_ns()
        fresh = self.command_ns is not None and now - self.command_ns <= self.command_timeout_ns
        self.plant.step(self.command if fresh else np.zeros(len(self.names)), (now - self.last_ns) * 1e-9)
        self.last_ns = now
        d, d_dot = self.plant.d, self.plant.d_dot
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(d_dot))):
            self.log("error", f"simulated D = {d.tolist()} not finite: not sent")
            return
        self.state_pub.publish(
            JointState(
                header=Header(stamp=Time(nanoseconds=now).to_msg()),
                name=list(self.names),
                position=[float(v) for v in d - self.model.hydraulic.zero_offset],  # what sensors read
                velocity=[float(v) for v in d_dot],
            )
        )


IK_SERVER = {
    **IK_SETTINGS,
    "path": PATH_SETTINGS,
    "zones_file": Text(doc="avoidance zone file (docs/zones.md): plan_path ends before a zone; empty: none"),
}


class HydraulicIKServer(PlanPathServer):
    """solve_ik, solve_fk and plan_path of a family machine (module docstring)."""

    SETTINGS = IK_SERVER
    DEFAULTS_FILE = DEFAULTS_FILE

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        self.h = self.model.hydraulic
        self.path = self.settings["path"]
        file = self.settings["zones_file"]
        names = self.h.monitored(self.h.reference, np.zeros(self.h.m))[0]
        self.zones = (
            ZoneGuard.from_file(file, names, self.h.max_speed, 1.0, read_landxml).zones if file else []
        )
        self.get_logger().info(
            f"serving plan_path (defaults: step {self.path['step']:g} m, tip speed "
            f"{self.path['tip_speed']:g} m/s, acceleration {self.path['acceleration']:g} m/s^2"
            f"{f', {len(self.zones)} zone(s)' if self.zones else ''})"
        )

    def plan(self, request: PlanPath.Request, waypoints: np.ndarray, seed: np.ndarray | None) -> ToolPlan:
        # 0 = the default; anything else (negative, NaN, tiny, huge) the shared bounds check.
        plan = plan_clear(
            self.h,
            self.zones,
            waypoints,
            request.step or self.path["step"],
            request.tip_speed or self.path["tip_speed"],
            self.path["acceleration"],
            None if seed is None else self.model.true_state(seed),
        )
        if plan.timing is None:
            return plan
        # Joint values on the wire are sensor readings (D - zero_offset), as on joint_states.
        readings = dataclasses.replace(plan.timing, q=plan.timing.q - self.h.zero_offset)
        return dataclasses.replace(plan, timing=readings)


def forward(args: Sequence[str] | None = None) -> int:
    return family_main(HydraulicForward, "hydraulic_forward", args)


def velocity_ik(args: Sequence[str] | None = None) -> int:
    return family_main(HydraulicVelocityIK, "hydraulic_velocity_ik", args)


def sim(args: Sequence[str] | None = None) -> int:
    return family_main(HydraulicSim, "hydraulic_sim", args)


def ik_server(args: Sequence[str] | None = None) -> int:
    return family_main(HydraulicIKServer, "hydraulic_ik_server", args)
