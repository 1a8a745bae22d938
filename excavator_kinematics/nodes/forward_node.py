"""excavator_forward: bucket pose, twist and acceleration from cylinder and swing states.

A thin adapter around :meth:`Excavator.state` (paper eqs. 3-11; one state per message: the compiled
single call, :mod:`excavator_kinematics.core.state_kernel`, loaded in the background from the
node's construction on, numpy answering until then). On each ``cylinder_lengths`` message it takes
the latest swing state from ``joint_states`` (extrapolated to the cylinder stamp, at most
``swing_max_age`` apart), turns the sensor readings into the true state D = reading + zero_offset
(the machine file's, :meth:`Excavator.true_state`; rates unchanged) and accelerations as finite
differences of successive rates (:mod:`excavator_kinematics.nodes.state_input`), and publishes with
the cylinder message's stamp:

* ``bucket_pose`` (PoseStamped), ``bucket_twist`` (TwistStamped), ``bucket_accel`` (AccelStamped,
  only once accelerations are known: from the second message on);
* ``open_chain_joint_states`` (JointState theta1..theta4 with rates);
* ``urdf_joint_states`` (JointState of every joint of ``urdf/excavator.urdf``, the passive ones of
  the cut loops included, with rates;
  :func:`excavator_kinematics.nodes.display_outputs.urdf_joint_states`) for robot_state_publisher,
  at most ``urdf_joint_states_rate`` per second of input stamps;
* ``grade_height`` (PointStamped, if ``grade.enabled``): the bucket tip in the design surface's
  frame, z = its height above the design plane
  (:class:`excavator_kinematics.nodes.display_outputs.DesignPlane`);
* ``grade/tip``, ``grade/left``, ``grade/right`` (PointStamped) and ``grade/status`` (if
  ``design_surface.file``): the cutting edge's heights above a LandXML TIN in the site frame
  (:mod:`manipulator_kinematics.nodes.surface_grade`);
* ``bucket_pose_level`` (PoseStamped, if ``level.enabled``): the bucket pose in the
  gravity-aligned level frame, from the machine's tilt (:mod:`excavator_kinematics.sensing.level_pose`).

Bad input is rejected with a logged reason; nothing is published for it. That includes finite
values no machine can have: rates beyond 1000 x the speed limits and accelerations beyond that in
10 ms (:class:`excavator_kinematics.nodes.state_input.Plausible`; an implausible acceleration costs only
that message's ``bucket_accel``). Every output is checked to be finite before it goes out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import AccelStamped, PointStamped, PoseStamped, TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from excavator_kinematics.core.kinematics import (
    ACTUATORS,
    CYLINDERS,
    JOINTS,
    Excavator,
    StrokeError,
    bucket_angular_acceleration,
    bucket_angular_velocity,
    compiled_kernel,
)
from excavator_kinematics.core.urdf_joints import URDF_JOINTS
from excavator_kinematics.nodes import family, message_codec
from excavator_kinematics.nodes.display_outputs import DesignPlane, urdf_joint_states
from excavator_kinematics.nodes.node_schemas import FORWARD, NODES_CONFIG
from excavator_kinematics.nodes.state_input import Plausible, RateDifferentiator, StaleInput, SwingHold
from excavator_kinematics.sensing.level_pose import LevelPose
from manipulator_kinematics.codec.packed import PackedMessage
from manipulator_kinematics.joint_state import InputError, decode_joint_state
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes import MachineNode
from manipulator_kinematics.nodes.base import input_qos
from manipulator_kinematics.nodes.surface_grade import SurfaceGrade
from manipulator_kinematics.registry import Machine

NODE = "excavator_forward"
SWING = JOINTS[0]
# What changes in a stamped geometry message from one input to the next: everything but frame_id.
STAMPED = ("header.stamp", "pose", "twist", "accel", "point")
JOINT_FIELDS = ("header.stamp", "position", "velocity")


class ForwardKinematics(MachineNode):
    """The node's state and callbacks."""

    SETTINGS = FORWARD
    DEFAULTS_FILE = NODES_CONFIG

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        settings = self.settings
        self.exc: Excavator = self.model
        self.frame = settings["frame_prefix"] + settings["base_frame"]
        self.swing = SwingHold(settings["swing_max_age"])
        tau, gap = settings["acceleration_time_constant"], settings["acceleration_max_gap"]
        self.cylinder_acceleration = RateDifferentiator(tau, gap)
        self.swing_acceleration = RateDifferentiator(tau, gap)
        self.plausible = Plausible(ACTUATORS, self.exc.limits.max_rates.tolist())
        self.log = ThrottledLog(self, settings["warning_period"])
        self.outputs_sent = self.waiting_said = False

        qos = QoSProfile(depth=settings["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        topic = settings["topics"]
        # Outputs go out as bytes of a fixed layout: building them as rclpy messages would cost
        # more than the kinematics (see manipulator_kinematics.codec.packed).
        header = Header(frame_id=self.frame)
        self.pose = PackedMessage(PoseStamped(header=header), STAMPED)
        self.twist = PackedMessage(TwistStamped(header=header), STAMPED)
        self.accel = PackedMessage(AccelStamped(header=header), STAMPED)
        self.joints = PackedMessage(
            JointState(name=list(JOINTS), position=[0.0] * 4, velocity=[0.0] * 4), JOINT_FIELDS
        )
        n = len(URDF_JOINTS)
        self.urdf_joints = PackedMessage(
            JointState(name=list(URDF_JOINTS), position=[0.0] * n, velocity=[0.0] * n), JOINT_FIELDS
        )
        rate = settings["urdf_joint_states_rate"]
        # By input stamps, so a replayed bag gives the same messages; 0 Hz: every input.
        self.urdf_period_ns = int(1e9 / rate) if rate > 0 else 0
        self.urdf_last_ns: int | None = None
        grade = settings["grade"]
        self.plane = DesignPlane.from_settings(grade) if grade["enabled"] else None
        grade_frame = settings["frame_prefix"] + grade["frame"]
        self.grade = PackedMessage(PointStamped(header=Header(frame_id=grade_frame)), STAMPED)
        self.pose_pub = self.create_publisher(PoseStamped, topic["bucket_pose"], qos)
        self.twist_pub = self.create_publisher(TwistStamped, topic["bucket_twist"], qos)
        self.accel_pub = self.create_publisher(AccelStamped, topic["bucket_accel"], qos)
        self.joints_pub = self.create_publisher(JointState, topic["open_chain_joint_states"], qos)
        self.urdf_pub = self.create_publisher(JointState, topic["urdf_joint_states"], qos)
        self.grade_pub = (
            self.create_publisher(PointStamped, topic["grade_height"], qos)
            if self.plane is not None
            else None
        )
        surface = settings["design_surface"]
        self.surface = (
            SurfaceGrade(self, surface, topic, self.exc.bucket_width, qos, self.log)
            if surface["file"]
            else None
        )
        level = settings["level"]
        self.level = LevelPose(self, level, topic, qos, self.log) if level["enabled"] else None
        # raw: the callbacks decode the bytes themselves (decode_joint_state), at a third of the cost.
        inputs = input_qos(settings["qos_depth"], settings["input_reliability"])
        self.create_subscription(JointState, topic["joint_states"], self.on_swing, inputs, raw=True)
        self.create_subscription(JointState, topic["cylinder_lengths"], self.on_cylinders, inputs, raw=True)
        # Start loading the compiled single call now (a background thread, numpy answering until
        # it is ready): numba's import (about a second of CPU) then overlaps discovery; started by
        # the first message, it stalled a 1 kHz input for over a second (queues overflowed).
        compiled_kernel(self.exc)
        self.get_logger().info(
            f"{self.exc.name}: {topic['cylinder_lengths']} + {topic['joint_states']} -> "
            f"{topic['bucket_pose']}, {topic['bucket_twist']}, {topic['bucket_accel']}, "
            f"{topic['open_chain_joint_states']}, {topic['urdf_joint_states']}"
            + (f", {topic['grade_height']}" if self.plane is not None else "")
            + f" in frame {self.frame!r}"
        )

    def on_swing(self, raw: bytes) -> None:
        try:
            msg = decode_joint_state(raw)
            angle, rate = message_codec.positions_and_rates(msg, (SWING,))
            self.plausible.rates((SWING,), rate.tolist())
        except InputError as error:
            self.log("error", f"rejected joint_states: {error}")
            return
        stamp = msg.stamp_ns
        acceleration = self.acceleration(self.swing_acceleration, (SWING,), stamp, rate)
        self.swing.update(
            stamp, float(angle[0]), float(rate[0]), None if acceleration is None else acceleration[0]
        )

    def on_cylinders(self, raw: bytes) -> None:
        try:
            msg = decode_joint_state(raw)
            lengths, rates = message_codec.positions_and_rates(msg, CYLINDERS)
            self.plausible.rates(CYLINDERS, rates.tolist())
            stamp_ns = msg.stamp_ns
            swing_reading, theta1_dot, theta1_ddot = self.swing.at(stamp_ns)
            # Sensor readings -> true state (reading + zero_offset), validated on the true strokes.
            D = self.exc.true_state([swing_reading, *lengths])
        except StaleInput as error:
            # Transient (start-up, a loaded machine): one info line until the first output, then
            # throttled warnings. ERROR is kept for inputs that need a person.
            if self.outputs_sent:
                self.log("warning", f"rejected cylinder_lengths: {error}")
            elif not self.waiting_said:
                self.waiting_said = True
                self.get_logger().info(f"waiting for inputs that belong together: {error}")
            return
        except (InputError, StrokeError) as error:
            self.log("error", f"rejected cylinder_lengths: {error}")
            return
        theta1 = float(D[0])
        # Only accepted messages feed the differencing, so a rejected one cannot spike it.
        cylinder_ddot = self.acceleration(self.cylinder_acceleration, CYLINDERS, stamp_ns, rates)
        known = cylinder_ddot is not None and theta1_ddot is not None
        s = self.exc.state(D, [theta1_dot, *rates], [theta1_ddot, *cylinder_ddot] if known else None)

        # Python floats from here on: unpacking numpy arrays element by element costs more.
        Q, Q_dot = s.Q.tolist(), s.Q_dot.tolist()
        pose = message_codec.bucket_pose_values(theta1, Q)
        twist = [*Q_dot[:3], *bucket_angular_velocity(theta1, theta1_dot, Q_dot[3]).tolist()]
        joints = [*s.theta.tolist(), *s.theta_dot.tolist()]
        accel = []
        if known:
            Q_ddot = s.Q_ddot.tolist()
            angular_acc = bucket_angular_acceleration(theta1, theta1_dot, theta1_ddot, Q_dot[3], Q_ddot[3])
            accel = [*Q_ddot[:3], *angular_acc.tolist()]
        grade = self.plane.local(Q[:3]).tolist() if self.plane is not None else []
        urdf = self.urdf_values(stamp_ns, D, [theta1_dot, *rates.tolist()])
        surface = self.surface.values(stamp_ns, theta1, Q[:3]) if self.surface is not None else []
        # The input checks keep the arithmetic far from overflow; this is the promise itself.
        edge = [v for point in surface if point is not None for v in point]
        if not all(map(math.isfinite, (*pose, *twist, *joints, *accel, *grade, *urdf, *edge))):
            self.log(
                "error",
                f"dropped the outputs of cylinder_lengths D = {D.tolist()}, "
                f"D_dot = {[theta1_dot, *rates.tolist()]}: not finite",
            )
            return
        sec_nanosec = (msg.sec, msg.nanosec)
        self.outputs_sent = True
        self.pose_pub.publish(self.pose.pack((*sec_nanosec, *pose)))
        self.twist_pub.publish(self.twist.pack((*sec_nanosec, *twist)))
        if known:
            self.accel_pub.publish(self.accel.pack((*sec_nanosec, *accel)))
        self.joints_pub.publish(self.joints.pack((*sec_nanosec, *joints)))
        if urdf:
            self.urdf_last_ns = stamp_ns
            self.urdf_pub.publish(self.urdf_joints.pack((*sec_nanosec, *urdf)))
        if grade:
            self.grade_pub.publish(self.grade.pack((*sec_nanosec, *grade)))
        if surface:
            self.surface.publish(sec_nanosec, surface)
        if self.level is not None:
            self.level.pose(stamp_ns, sec_nanosec, theta1, pose)

    def urdf_values(self, stamp_ns: int, D: np.ndarray, D_dot: list[float]) -> list[float]:
        """Positions then rates of every URDF joint when urdf_joint_states is due, else []."""
        last = self.urdf_last_ns
        if last is not None and 0 <= stamp_ns - last < self.urdf_period_ns:
            return []
        positions, velocities = urdf_joint_states(self.exc, D, D_dot)
        return [*positions.tolist(), *velocities.tolist()]

    def acceleration(
        self, differentiator: RateDifferentiator, names: Sequence[str], stamp_ns: int, rates: np.ndarray
    ) -> list[float] | None:
        """The finite-difference accelerations of ``names``, or None while unknown or implausible
        (a jump between two plausible rates a nanosecond apart; logged, differencing restarted)."""
        acceleration = differentiator.update(stamp_ns, rates)
        if acceleration is None:
            return None
        values = acceleration.tolist()
        try:
            self.plausible.accelerations(names, values)
        except InputError as error:
            differentiator.restart()
            self.log("warning", f"no acceleration for this message: {error}")
            return None
        return values


def main(args: Sequence[str] | None = None) -> int:
    return family.run(ForwardKinematics, NODE, args)  # a family machine file runs the family node


if __name__ == "__main__":
    raise SystemExit(main())
