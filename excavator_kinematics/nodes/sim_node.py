"""excavator_sim: a simulated excavator for closed-loop runs without hardware.

Integrates the rate commands of ``cylinder_rate_commands`` (JointState velocities of swing_joint,
boom_cylinder, arm_cylinder, bucket_cylinder) with :class:`excavator_kinematics.core.plant.Plant`
(speed limits, stroke ends, optional first-order lag) and publishes, at ``rate`` Hz and with one
stamp, ``cylinder_lengths`` (position m, velocity m/s) and ``joint_states`` (swing_joint angle and
rate), the positions as the machine's sensors read them: true - zero_offset (the machine file's;
the plant and ``initial_*`` are true values). A command older than ``command_timeout`` s counts as
zero. A command that is not finite or beyond 1000 x a speed limit
(:class:`excavator_kinematics.nodes.state_input.Plausible`) is refused with a reason and leaves the
previous one in force; a plausible one is saturated at the speed limits by the plant. What is
published is checked to be finite. Steps use the measured time between timer calls, so timer jitter
does not change the integrated motion.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import JointState

from excavator_kinematics.core.kinematics import ACTUATORS, CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.nodes import family, message_codec
from excavator_kinematics.nodes.node_schemas import NODES_CONFIG, SIM
from excavator_kinematics.nodes.state_input import InputError, Plausible
from manipulator_kinematics.joint_state import joint_values
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes import MachineNode
from manipulator_kinematics.nodes.base import input_qos
from manipulator_kinematics.registry import Machine

NODE = "excavator_sim"


class Simulator(MachineNode):
    """The node's state and callbacks."""

    SETTINGS = SIM
    DEFAULTS_FILE = NODES_CONFIG

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        s = self.settings
        self.exc: Excavator = self.model
        given = s["initial_cylinder_lengths"]
        lengths = self.exc.limits.reference[1:] if given is None else given
        self.plant = Plant(
            self.exc.limits, np.array([s["initial_swing_angle"], *lengths], dtype=float), s["time_constant"]
        )
        self.command_timeout_ns = int(s["command_timeout"] * 1e9)
        self.command = np.zeros(4)
        self.command_received_ns: int | None = None
        self.log = ThrottledLog(self, s["warning_period"])
        self.plausible = Plausible(ACTUATORS, self.exc.limits.max_rates.tolist())

        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        self.cylinder_pub = self.create_publisher(JointState, s["topics"]["cylinder_lengths"], qos)
        self.swing_pub = self.create_publisher(JointState, s["topics"]["joint_states"], qos)
        # Only the latest command matters; a queue of old ones would delay the loop.
        latest = input_qos(s["input_queue_depth"], s["input_reliability"])
        self.create_subscription(JointState, s["topics"]["rate_commands"], self.on_command, latest)
        self.last_ns = self.now_ns()
        self.create_timer(1.0 / s["rate"], self.on_timer)
        self.get_logger().info(
            f"{self.exc.name} simulated at {s['rate']:g} Hz from D = {self.plant.d.round(6).tolist()}"
        )

    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def on_command(self, msg: JointState) -> None:
        try:
            _, rates = joint_values(msg, ACTUATORS, require_velocity=True)
            self.plausible.rates(ACTUATORS, rates.tolist())
        except InputError as error:
            self.log("error", f"rejected rate command: {error}")
            return
        self.command = rates
        self.command_received_ns = self.now_ns()

    def on_timer(self) -> None:
        now = self.now_ns()
        fresh = (
            self.command_received_ns is not None and now - self.command_received_ns <= self.command_timeout_ns
        )
        self.plant.step(self.command if fresh else np.zeros(4), (now - self.last_ns) * 1e-9)
        self.last_ns = now
        stamp = Time(nanoseconds=now).to_msg()
        d, d_dot = self.plant.d, self.plant.d_dot
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(d_dot))):  # the plant's promise, kept here
            self.log("error", f"simulated D = {d.tolist()}, D_dot = {d_dot.tolist()} not finite: not sent")
            return
        # Swing first: a node combining the two (excavator_forward) then usually holds the swing
        # state of this very step when the cylinder message arrives.
        # What the machine's sensors would read (true - zero_offset); rates are unchanged.
        reading = self.exc.readings(d)
        self.swing_pub.publish(message_codec.joint_state(stamp, JOINTS[:1], reading[:1], d_dot[:1]))
        self.cylinder_pub.publish(message_codec.joint_state(stamp, CYLINDERS, reading[1:], d_dot[1:]))


def main(args: Sequence[str] | None = None) -> int:
    return family.run(Simulator, NODE, args)  # a family machine file runs the family node


if __name__ == "__main__":
    raise SystemExit(main())
