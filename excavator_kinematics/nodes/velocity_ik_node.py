"""excavator_velocity_ik: swing and cylinder rate commands for a target bucket twist (paper eq. 9).

Wiring only; the decisions are in numpy modules:
:func:`excavator_kinematics.core.twist.split_twist` (6-D twist -> achievable Q_dot + residual) and
:func:`excavator_kinematics.core.rate_command.rate_command` (damped inverse, stroke ends, speed limits).

A command is computed when a target arrives and again on each ``cylinder_lengths`` message while
the target is fresh and no newer target came since the previous one, so JC0 follows the moving
machine also when targets come slower than states. Rates go out as JointState (names
swing_joint, boom_cylinder, arm_cylinder, bucket_cylinder; velocity only) and, if
``publish_array``, as Float64MultiArray in that fixed order.

Direction kept (docs/excavator_nodes.md, "The direction rule at stroke ends"): the rates are the
ideal ones times one factor in [0, 1], so a target the machine cannot follow is slowed or stopped
in its own direction, never bent into another one. ``status`` (diagnostic_msgs/DiagnosticArray,
one DiagnosticStatus) says which: tracking, slowed (by what) or stopped (why), on every change and
at least every ``status_period`` s while commanding; each change to slowed or stopped is logged
once (throttled). A constant target's drift from its line is corrected (``line_gain``,
:func:`excavator_kinematics.core.rate_command.toward_line`), and a stop at a stroke end holds until
the target changes.

Stopping: no accepted target for ``command_timeout`` s, or a target/state that cannot be used
while moving, publishes zero rates once and holds (publishes nothing) until the next good target.

Avoidance zones (``zones_file``, docs/zones.md): the command is scaled once more, by
:class:`manipulator_kinematics.zone_guard.ZoneGuard`'s factor for the monitored points
(:class:`excavator_kinematics.core.monitored.MonitoredPoints`), so it slows approaching a zone and stops
at it in its own direction; the status names the zone and the point, and ``zone_clearance``
carries each zone's smallest clearance. Site-frame zones are placed by the machine's pose in the
site frame, read as the forward node's grade outputs read it (settings ``site``, topics
``site_pose`` and ``machine_tilt``): :class:`manipulator_kinematics.nodes.site_pose.SitePoseInput`
(fixed, or the latest PoseStamped within ``site_pose_max_age`` of the cylinder stamp), with
``site.tilt`` its roll and pitch from the cab IMU's tilt
(:class:`excavator_kinematics.sensing.machine_tilt.TiltInput`, the nearest within
``tilt_max_age``; :meth:`SitePose.levelled`). Without a fresh pose the command is stopped with the
reason (the zones cannot be checked), and the clearances of site-frame zones are reported STALE.

Inputs are checked where they enter, finite values included: a swing rate beyond 1000 x its speed
limit (:class:`excavator_kinematics.nodes.state_input.Plausible`) and a target twist beyond 1000 x the
fastest bucket motion the actuators give at the reference state are refused with a reason. Every
command is finite and within the speed limits exactly (checked again before it is published).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TwistStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header

from excavator_kinematics.core.kinematics import ACTUATORS, CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.core.rate_command import (
    SLOWED,
    STOPPED,
    TRACKING,
    describe,
    rate_command,
    toward_line,
)
from excavator_kinematics.core.twist import split_twist
from excavator_kinematics.grade.design_surface import read_landxml
from excavator_kinematics.nodes import family, message_codec
from excavator_kinematics.nodes.node_schemas import NODES_CONFIG, VELOCITY_IK
from excavator_kinematics.nodes.state_input import (
    PLAUSIBILITY_FACTOR,
    InputError,
    Plausible,
    StaleInput,
    SwingHold,
)
from excavator_kinematics.sensing.imu import base_up
from excavator_kinematics.sensing.machine_tilt import TiltInput
from manipulator_kinematics.joint_state import joint_values
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes import MachineNode
from manipulator_kinematics.nodes.base import input_qos
from manipulator_kinematics.nodes.site_pose import SitePoseInput
from manipulator_kinematics.nodes.zone_output import ZoneOutput
from manipulator_kinematics.registry import Machine

NODE = "excavator_velocity_ik"
# Status levels: tracking is OK; slowed or stopped is a warning (the machine does what it can, in
# the commanded direction); a target or state that cannot be used is an error.
LEVELS = {TRACKING: DiagnosticStatus.OK, SLOWED: DiagnosticStatus.WARN, STOPPED: DiagnosticStatus.WARN}
# Status of a stop per log severity: an input that needs a person (ERROR) or a late one (WARN).
STOP_LEVELS = {"error": DiagnosticStatus.ERROR, "warning": DiagnosticStatus.WARN}


class VelocityIk(MachineNode):
    """The node's state and callbacks."""

    SETTINGS = VELOCITY_IK
    DEFAULTS_FILE = NODES_CONFIG

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        s = self.settings
        self.exc: Excavator = self.model
        self.frame = s["frame_prefix"] + s["base_frame"]
        self.command_timeout_ns = int(s["command_timeout"] * 1e9)
        self.state_timeout_ns = int(s["state_timeout"] * 1e9)
        self.condition_threshold = float(s["condition_threshold"])
        self.stroke_horizon = float(s["stroke_horizon"])
        self.residual_tolerance = float(s["twist_residual_tolerance"])
        self.bucket_angle_gives_way = bool(s["bucket_angle_gives_way"])
        self.status_period_ns = int(s["status_period"] * 1e9)
        self.line_gain = float(s["line_gain"])
        # The commanded line: (target linear, angular, Q where it began, its Q_dot); a target with
        # other numbers begins a new one, so does a bucket farther than LINE_RESTART from it.
        self.line: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        # Why the machine stopped on this line: it stays stopped until the target changes (also
        # across a timeout or a stale state: the same target again is still the same line), so it
        # does not creep on and off at the end (the correction toward the line, or the secondary
        # task's minimum speed, can tip a command just past the stop).
        self.stopped_on_line: str | None = None
        self.status_sent: tuple[int, str] | None = None  # (node clock ns, message) of the last status
        self.log = ThrottledLog(self, s["warning_period"])
        self.swing = SwingHold(s["swing_max_age"])
        limits = self.exc.limits
        self.max_rates = limits.max_rates
        self.plausible = Plausible(ACTUATORS, self.max_rates.tolist())
        # Bucket rates [x_dot, y_dot, z_dot, alpha_dot] of every actuator at its limit, each adding up
        # (eq. 8 at the reference state): the plausible target speeds are PLAUSIBILITY_FACTOR times that.
        fastest = np.abs(self.exc.jc0(limits.reference)) @ self.max_rates
        self.max_linear = PLAUSIBILITY_FACTOR * float(np.linalg.norm(fastest[:3]))
        self.max_angular = PLAUSIBILITY_FACTOR * float(limits.max_swing_speed + fastest[3])
        self.cylinders: tuple[int, int, np.ndarray] | None = None  # (stamp ns, receipt ns, lengths)
        self.target: tuple[int, np.ndarray, np.ndarray] | None = None  # (receipt ns, linear, angular)
        self.moving = False  # a non-zero command may be in force
        self.target_since_state = False

        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        # A controller acts on the latest target and state: a short input queue drops what a busy
        # moment left behind instead of working through it late (a backlog is a delay in the loop).
        latest = input_qos(s["input_queue_depth"], s["input_reliability"])
        self.command_pub = self.create_publisher(JointState, s["topics"]["rate_commands"], qos)
        self.array_pub = (
            self.create_publisher(Float64MultiArray, s["topics"]["rate_command_array"], qos)
            if s["publish_array"]
            else None
        )
        # Transient local: a monitor that starts later still gets the current status.
        latched = QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        self.status_pub = self.create_publisher(DiagnosticArray, s["topics"]["status"], latched)
        self.create_subscription(TwistStamped, s["topics"]["target_bucket_twist"], self.on_target, latest)
        self.create_subscription(JointState, s["topics"]["joint_states"], self.on_swing, latest)
        self.create_subscription(JointState, s["topics"]["cylinder_lengths"], self.on_cylinders, latest)
        self.create_timer(s["command_timeout"] / 5.0, self.on_timer)
        # Avoidance zones (docs/zones.md): every command scaled so no monitored point enters one.
        self.points = MonitoredPoints(self.exc)
        self.zones = ZoneOutput.of(
            self,
            s["zones_file"],
            self.points.names,
            self.max_rates / s["zones_stop_time"],
            s["zones_period"],
            s["topics"]["zone_clearance"],
            s["qos_depth"],
            self.exc.name,
            read_landxml,
            site_pose=True,
            lag=s["zones_lag"],
        )
        # The machine's pose in the site frame, read only when a site-frame zone needs it.
        site = s["site"]
        self.site: SitePoseInput | None = None
        self.tilt: TiltInput | None = None
        if self.zones is not None and any(z.frame == "site" for z in self.zones.guard.zones):
            self.site = SitePoseInput(self, site, s["topics"]["site_pose"], latest, self.log)
            if site["tilt"]:
                self.tilt = TiltInput(
                    self, s["topics"]["machine_tilt"], site["tilt_max_age"], latest, self.log
                )
            self.get_logger().info(
                f"site-frame zones: site pose {self.site.describe()}"
                + (f", roll and pitch from {s['topics']['machine_tilt']}" if self.tilt else "")
            )
        self.get_logger().info(
            f"{self.exc.name}: {s['topics']['target_bucket_twist']} (frame {self.frame!r}) -> "
            f"{s['topics']['rate_commands']}"
            + (f" + {s['topics']['rate_command_array']}" if self.array_pub else "")
        )

    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def on_swing(self, msg: JointState) -> None:
        try:
            angle, rate = message_codec.positions_and_rates(msg, (JOINTS[0],))
            self.plausible.rates((JOINTS[0],), rate.tolist())
        except InputError as error:
            self.log("error", f"rejected joint_states: {error}")
            return
        self.swing.update(message_codec.stamp_ns(msg.header.stamp), float(angle[0]), float(rate[0]), None)

    def on_cylinders(self, msg: JointState) -> None:
        try:
            lengths, _ = joint_values(msg, CYLINDERS, require_position=True)
        except InputError as error:
            self.log("error", f"rejected cylinder_lengths: {error}")
            return
        self.cylinders = (message_codec.stamp_ns(msg.header.stamp), self.now_ns(), lengths)
        # A target that came since the last state was already computed at the newest state but one;
        # recompute only for a target that is older than that (a slower target stream).
        if self.target is not None and not self.target_since_state:
            self.command(msg.header.stamp)
        elif self.zones is not None and self.target is None:  # standing: the clearances still go out
            with contextlib.suppress(ValueError):
                D = self.exc.true_state(self.state())
                self.zones.watch(msg.header.stamp, self.points.positions(D), self.site_pose(D[0])[0])
        self.target_since_state = False

    def on_target(self, msg: TwistStamped) -> None:
        try:
            if msg.header.frame_id not in ("", self.frame):  # empty: the base frame, as on the services
                raise InputError(f"frame_id {msg.header.frame_id!r} is not the base frame {self.frame!r}")
            linear, angular = message_codec.twist_arrays(msg)
            with np.errstate(over="ignore"):  # a norm that overflows is inf: refused just below
                speed, turn = float(np.linalg.norm(linear)), float(np.linalg.norm(angular))
            if not (speed <= self.max_linear and turn <= self.max_angular):
                raise InputError(
                    f"twist of {speed:.6g} m/s, {turn:.6g} rad/s is beyond {PLAUSIBILITY_FACTOR:g} x the "
                    f"fastest bucket motion ({self.max_linear:.6g} m/s, {self.max_angular:.6g} rad/s): "
                    "implausible"
                )
        except InputError as error:
            self.stop(f"rejected target_bucket_twist: {error}")
            return
        self.target = (self.now_ns(), linear, angular)
        self.target_since_state = True
        self.command(msg.header.stamp)

    def on_timer(self) -> None:
        if self.target is not None and self.now_ns() - self.target[0] > self.command_timeout_ns:
            self.stop(f"no target_bucket_twist for {self.command_timeout_ns * 1e-9:g} s", "info", idle=True)

    def state(self) -> np.ndarray:
        """The sensor readings [theta1, d2, d3, d4] now (:meth:`Excavator.true_state` makes D of
        them); StaleInput when missing or late, InputError when wrong."""
        if self.cylinders is None:
            raise StaleInput("no cylinder_lengths received yet")
        stamp_ns, received_ns, lengths = self.cylinders
        age = self.now_ns() - received_ns
        if age > self.state_timeout_ns:
            raise StaleInput(
                f"cylinder_lengths is {age * 1e-9:.3f} s old "
                f"(state_timeout {self.state_timeout_ns * 1e-9:g} s)"
            )
        theta1, _, _ = self.swing.at(stamp_ns)
        return np.concatenate(([theta1], lengths))

    def site_pose(self, theta1: float) -> tuple[tuple[np.ndarray, np.ndarray] | None, str]:
        """(R, t) of base_link in the site frame (p_site = R p + t) at the current state's stamp
        and "", or None and why there is none (fresh enough) while a site-frame zone needs it;
        (None, "") without site-frame zones."""
        if self.site is None:
            return None, ""
        stamp_ns = self.cylinders[0]
        pose, why = self.site.at(stamp_ns)
        if pose is not None and self.tilt is not None:
            up, why = self.tilt.at(stamp_ns)
            pose = None if up is None else pose.levelled(base_up(up, theta1))
        if pose is None:
            return None, f"site-frame zones cannot be checked: {why}"
        return (pose.rotation, pose.translation), ""

    def command(self, stamp: Time) -> None:
        """Publish the rates for the current target at the current state (or stop, saying why)."""
        _, linear, angular = self.target
        try:
            D = self.exc.true_state(self.state())
            Q = self.exc.pose(D)
            tip = Q[:3]
            split = split_twist(D[0], tip, linear, angular)
            residual = float(np.linalg.norm(split.residual))
            if residual > self.residual_tolerance:
                self.log(
                    "warning",
                    f"target twist not achievable: angular velocity residual {residual:.4f} rad/s "
                    f"({split.residual.round(4).tolist()}); following its linear velocity and alpha rate",
                )
            line = self.line
            if line is None or not (np.array_equal(line[0], linear) and np.array_equal(line[1], angular)):
                line = self.line = (linear, angular, Q, split.q_dot)
                self.stopped_on_line = None
            correction = toward_line(line[2], line[3], Q, self.line_gain, not self.bucket_angle_gives_way)
            if correction is None:  # moved, not drifted: a new line from here
                self.line, correction = (linear, angular, Q, split.q_dot), np.zeros(4)
                self.stopped_on_line = None
            if self.stopped_on_line is not None:
                self.publish(stamp, np.zeros(4))
                self.report(stamp, LEVELS[STOPPED], self.stopped_on_line)
                return
            rates = rate_command(
                self.exc.jc0(D),
                D,
                split.q_dot + correction,
                self.exc.limits,
                self.condition_threshold,
                self.stroke_horizon,
                self.bucket_angle_gives_way,
            )
            site, blind = self.site_pose(D[0])
            zone = (
                None
                if self.zones is None
                else self.zones(
                    stamp, *self.points.motion(D, rates.d_dot), rates.d_dot, self.cylinders[0], site
                )
            )
            if blind:  # the clearances went out (site-frame zones STALE); the machine stops
                raise StaleInput(blind)
        except ValueError as error:  # InputError, StrokeError, an overflowing target
            # A late state (StaleInput: start-up, a loaded machine) stops the motion as any other
            # reason does, but it is transient: a warning, not an error that needs a person.
            self.stop(f"cannot command: {error}", "warning" if isinstance(error, StaleInput) else "error")
            return
        if rates.damping > 0.0:
            self.log(
                "warning",
                f"JC0 badly conditioned (cond {rates.condition:.0f}): slowed to the speed of damped least "
                "squares, direction kept",
            )
        self.publish(stamp, rates.d_dot if zone is None else zone.scale * rates.d_dot)
        self.moving = True
        state, message = describe(rates, ACTUATORS)
        if state == STOPPED:
            self.stopped_on_line = message
        elif zone is not None and zone.scale < 1.0:  # the zones slow it further (a zone stop is not held)
            state, message = zone.state, zone.message
        scale = rates.scale * (1.0 if zone is None else zone.scale)
        self.report(stamp, LEVELS[state], message, scale=scale, condition=rates.condition)

    def report(
        self,
        stamp: Time,
        level: bytes,
        message: str,
        scale: float = 0.0,
        condition: float = float("nan"),
        log: bool = True,
    ) -> None:
        """Publish the status on a change of ``message`` or after ``status_period``; log a change to
        slowed or stopped once (throttled)."""
        now = self.now_ns()
        changed = self.status_sent is None or self.status_sent[1] != message
        if not changed and now - self.status_sent[0] < self.status_period_ns:
            return
        if changed and log and level != DiagnosticStatus.OK:
            self.log("warning" if message.startswith(STOPPED) else "info", message)
        self.status_sent = (now, message)
        # No NaN in the status either: a condition not computed (no command) is "n/a".
        values = {
            "scale": f"{scale:.6g}",
            "condition": f"{condition:.6g}" if np.isfinite(condition) else "n/a",
            "bucket_angle_gives_way": str(self.bucket_angle_gives_way).lower(),
        }
        status = DiagnosticStatus(
            level=level,
            name=self.get_fully_qualified_name(),
            message=message,
            hardware_id=self.exc.name,
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )
        self.status_pub.publish(DiagnosticArray(header=Header(stamp=stamp), status=[status]))

    def stop(self, reason: str, severity: str = "error", idle: bool = False) -> None:
        """Log ``reason`` at ``severity``; drop the target and publish zero rates once if a motion
        may be in force. ``idle``: no target any more, an OK status, not a stop."""
        self.log(severity, reason)
        self.target = None
        now = self.get_clock().now().to_msg()
        if self.moving:
            self.publish(now, np.zeros(4))
            self.moving = False
        level = DiagnosticStatus.OK if idle else STOP_LEVELS[severity]
        message = f"idle: {reason}" if idle else f"{STOPPED}: {reason}"
        self.report(now, level, message, log=False)  # logged just above

    def publish(self, stamp: Time, d_dot: np.ndarray) -> None:
        # rate_command guarantees both; a command is what moves the machine, so it is checked here.
        if not (np.all(np.isfinite(d_dot)) and np.all(np.abs(d_dot) <= self.max_rates)):
            self.log("error", f"command {d_dot.tolist()} not finite or beyond the speed limits: zero sent")
            d_dot = np.zeros(4)
        self.command_pub.publish(message_codec.joint_state(stamp, ACTUATORS, velocities=d_dot))
        if self.array_pub is not None:
            self.array_pub.publish(Float64MultiArray(data=[float(v) for v in d_dot]))


def main(args: Sequence[str] | None = None) -> int:
    return family.run(VelocityIk, NODE, args)  # a family machine file runs the family node


if __name__ == "__main__":
    raise SystemExit(main())
