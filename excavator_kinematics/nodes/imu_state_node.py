"""excavator_imu_state: cylinder lengths and rates from four inclination sensors (sensor_msgs/Imu).

Inputs ``imu/cab``, ``imu/boom``, ``imu/arm``, ``imu/bucket_linkage`` (topics.*), each a
sensor_msgs/Imu in its sensor's frame, mounted as the machine file says (``excavator.imu``). Up in
each sensor's frame comes from its orientation when the driver gives one
(``orientation_covariance[0] != -1``), else from gravity in ``linear_acceleration`` through the
complementary filter of :class:`excavator_kinematics.sensing.imu.TiltFilter` (time constant
``gravity_time_constant``). :class:`excavator_kinematics.sensing.imu.ImuArm` turns the four into theta2..4
relative to the upper structure (a tilted cab cancels) and the cylinder lengths and rates, which
go out on ``cylinder_lengths`` (sensor_msgs/JointState, boom/arm/bucket_cylinder, position and
velocity; the positions as a length sensor would read them, true - the machine file's
zero_offset): the topic excavator_forward and excavator_velocity_ik read, so the chain runs on IMUs
unchanged (the swing still comes from its encoder on ``joint_states``). With each set it also
publishes ``machine_tilt`` (geometry_msgs/Vector3Stamped, frame_id ``upper_structure_frame``):
world up in the upper structure's frame from the cab IMU, from which excavator_forward's
``level.*`` builds the gravity-aligned level frame (:func:`excavator_kinematics.sensing.imu.level_rotation`).

A set is published once every sensor has a message newer than the last set and the four stamps
lie within ``max_skew`` s, stamped with the newest. A reading that is not finite, a quaternion
that is not of unit length (1e-3), a rate beyond ``max_angular_rate`` or a specific force whose
magnitude is more than ``max_dynamic_acceleration`` from g is rejected (the sensor then counts as
missing until its next good message); a missing sensor, a skew beyond ``max_skew`` or angles the
machine cannot take mean no output; each with a throttled reason.

Staleness: a timer every ``max_age`` / 4 s (node clock) finds the sensors whose newest message
arrived more than ``max_age`` s ago, or that have sent nothing in the first ``max_age`` s after
start-up; they count as missing (their filter restarts) until their next good message, and a
throttled "no cylinder state: imu ... stale" names them. So a sensor, or all four, falling silent
is said, not only a set that never completes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time as Stamp
from geometry_msgs.msg import Vector3, Vector3Stamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Header

from excavator_kinematics.core.kinematics import CYLINDERS, Excavator, StrokeError
from excavator_kinematics.nodes import message_codec
from excavator_kinematics.nodes.node_schemas import IMU_STATE, NODES_CONFIG
from excavator_kinematics.sensing.imu import GRAVITY, SENSORS, ImuArm, TiltFilter, up_from_orientation
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes import MachineNode, run_node
from manipulator_kinematics.nodes.base import input_qos
from manipulator_kinematics.registry import Machine

NODE = "excavator_imu_state"

#: A cylinder rate beyond this many times its speed limit (machine file) is refused: the gyros'
#: noise at full speed stays far below it, a rate the cylinder cannot have does not.
RATE_MARGIN = 2.0


class ImuState(MachineNode):
    """The node's state and callbacks."""

    SETTINGS = IMU_STATE
    DEFAULTS_FILE = NODES_CONFIG

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        s = self.settings
        self.exc: Excavator = self.model
        self.arm = ImuArm(self.exc)
        self.log = ThrottledLog(self, s["warning_period"])
        self.max_skew_ns = int(s["max_skew"] * 1e9)
        self.max_rate = s["max_angular_rate"]
        self.max_dynamic = s["max_dynamic_acceleration"]
        self.max_rates = RATE_MARGIN * self.exc.limits.max_rates[1:]
        self.filters = {name: TiltFilter(s["gravity_time_constant"]) for name in SENSORS}
        # Per sensor: (stamp ns, up (3,), omega (3,)) of its latest good message, or None.
        self.latest: dict[str, tuple[int, np.ndarray, np.ndarray] | None] = dict.fromkeys(SENSORS)
        self.published_ns = -1
        self.max_age_ns = int(s["max_age"] * 1e9)
        # Per sensor: node-clock time its newest message (good or not) arrived; start-up until then.
        started = self.get_clock().now().nanoseconds
        self.arrived: dict[str, int] = dict.fromkeys(SENSORS, started)
        self.heard: set[str] = set()
        self.create_timer(s["max_age"] / 4.0, self.check_stale)
        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        topics = s["topics"]
        self.cylinder_pub = self.create_publisher(JointState, topics["cylinder_lengths"], qos)
        self.tilt_pub = self.create_publisher(Vector3Stamped, topics["machine_tilt"], qos)
        self.upper_frame = s["frame_prefix"] + s["upper_structure_frame"]
        sensors = input_qos(s["qos_depth"], s["input_reliability"])
        for name in SENSORS:
            self.create_subscription(
                Imu, topics[f"imu_{name}"], lambda msg, n=name: self.on_imu(n, msg), sensors
            )
        linkage = self.exc.description.imu["bucket_linkage"]["body"]
        self.get_logger().info(
            f"{self.exc.name}: {', '.join(topics[f'imu_{n}'] for n in SENSORS)} (bucket linkage IMU on the "
            f"{linkage}) -> {topics['cylinder_lengths']}"
        )

    def on_imu(self, name: str, msg: Imu) -> None:
        now = self.get_clock().now().nanoseconds
        self.arrived[name] = now
        self.heard.add(name)
        stamp_ns = self.checked_stamp(name, msg.header.stamp, now)
        if stamp_ns is None:
            return
        q, w, f = msg.orientation, msg.angular_velocity, msg.linear_acceleration
        omega = np.array([w.x, w.y, w.z])
        has_orientation = msg.orientation_covariance[0] != -1.0
        reason = self.implausible(has_orientation, (q.x, q.y, q.z, q.w), omega, (f.x, f.y, f.z))
        if reason:
            self.latest[name] = None
            self.filters[name].up = None
            self.log("error", f"rejected imu {name}: {reason}", kind=f"reject {name}")
            return
        if has_orientation:
            up = up_from_orientation([q.x, q.y, q.z, q.w])
        else:
            previous = self.latest[name]
            dt = (stamp_ns - previous[0]) * 1e-9 if previous is not None else 0.0
            up = self.filters[name].update(dt, omega, [f.x, f.y, f.z])
        self.latest[name] = (stamp_ns, up, omega)
        self.publish_if_complete()

    def checked_stamp(self, name: str, stamp: Stamp, now: int) -> int | None:
        """The message's stamp (ns), or None with a throttled reason: a negative stamp, one more than
        ``max_age`` ahead of the node clock (one such set would otherwise hold back every later set
        until the clock caught up), or one not newer than the sensor's previous message (or the last
        set). A stamp more than ``max_age`` behind those is a clock that went back (a bag played
        again): every sensor and the set start over from it."""
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        if stamp.sec < 0:
            self.log("error", f"rejected imu {name}: negative stamp (sec {stamp.sec})", kind="negative stamp")
            return None
        ahead = stamp_ns - now
        if now > 0 and ahead > self.max_age_ns:
            self.log(
                "error",
                f"rejected imu {name}: stamp {ahead * 1e-9:.3f} s ahead of the node clock "
                f"(max_age {self.max_age_ns * 1e-9:g} s)",
                kind="future stamp",
            )
            return None
        previous = self.latest[name]
        # The newest stamp this sensor's next message must pass: its previous one, or the last set's.
        reference = max(previous[0] if previous is not None else -1, self.published_ns)
        if stamp_ns > reference:
            return stamp_ns
        behind = (reference - stamp_ns) * 1e-9
        if reference - stamp_ns <= self.max_age_ns:
            self.log(
                "warning",
                f"rejected imu {name}: stamp {behind:.3f} s behind (or equal to) its "
                "previous message or the last set",
                kind="stamp out of order",
            )
            return None
        self.log(
            "warning",
            f"imu {name}: stamp {behind:.3f} s behind its previous message or the last set, "
            "more than max_age: the clock went back, every sensor starts over",
            kind="clock back",
        )
        for sensor in SENSORS:
            self.latest[sensor] = None
            self.filters[sensor].up = None
        self.published_ns = -1
        return stamp_ns

    def check_stale(self) -> None:
        """Timer: sensors silent for more than ``max_age`` count as missing, with a reason."""
        now = self.get_clock().now().nanoseconds
        stale = [name for name in SENSORS if now - self.arrived[name] > self.max_age_ns]
        if not stale:
            return
        for name in stale:
            self.latest[name] = None
            self.filters[name].up = None
        said = [
            f"{name} (no message for {(now - self.arrived[name]) * 1e-9:.3f} s)"
            if name in self.heard
            else f"{name} (no message since start-up)"
            for name in stale
        ]
        self.log(
            "warning",
            f"no cylinder state: imu {', '.join(said)} stale, max_age {self.max_age_ns * 1e-9:g} s",
            kind=f"stale {' '.join(stale)}",
        )

    def implausible(
        self, has_orientation: bool, q: tuple[float, ...], omega: np.ndarray, f: tuple[float, ...]
    ) -> str:
        """The reason a reading cannot be used, or ''."""
        if not np.all(np.isfinite(omega)) or float(np.max(np.abs(omega))) > self.max_rate:
            return f"angular velocity {omega.tolist()} not finite or beyond {self.max_rate:g} rad/s"
        if has_orientation:
            norm = math.sqrt(sum(v * v for v in q))
            if not abs(norm - 1.0) <= 1e-3:
                return f"orientation quaternion of length {norm:.6g}, not 1"
            return ""
        magnitude = math.sqrt(sum(v * v for v in f))
        if not abs(magnitude - GRAVITY) <= self.max_dynamic:
            return (
                f"no orientation and |linear_acceleration| = {magnitude:.6g} m/s^2 is more than "
                f"{self.max_dynamic:g} from g: no gravity direction"
            )
        return ""

    def publish_if_complete(self) -> None:
        missing = [name for name, value in self.latest.items() if value is None]
        if missing:
            self.log("warning", f"no cylinder state: no good message yet from imu {', '.join(missing)}")
            return
        stamps = [value[0] for value in self.latest.values()]
        if max(stamps) - min(stamps) > self.max_skew_ns:
            stale = SENSORS[int(np.argmin(stamps))]
            behind = (max(stamps) - min(stamps)) * 1e-9
            self.log(
                "warning",
                f"no cylinder state: imu {stale} is {behind:.3f} s "
                f"behind the newest sensor (max skew {self.max_skew_ns * 1e-9:g} s)",
            )
            return
        if min(stamps) <= self.published_ns:
            return  # waiting for the rest of the next set
        up = np.stack([value[1] for value in self.latest.values()])
        omega = np.stack([value[2] for value in self.latest.values()])
        try:
            joints = self.arm.joints(up, omega)
        except StrokeError as error:
            self.log("error", f"no cylinder state: {error}")
            return
        if not (np.all(np.isfinite(joints.lengths)) and np.all(np.isfinite(joints.rates))):
            self.log("error", f"no cylinder state: not finite ({joints.lengths.tolist()})")
            return
        too_fast = np.abs(joints.rates) > self.max_rates
        if np.any(too_fast):
            i = int(np.argmax(too_fast))
            self.log(
                "error",
                f"no cylinder state: {CYLINDERS[i]} rate {joints.rates[i]:.6g} m/s from the "
                f"gyros is beyond {self.max_rates[i]:g} m/s ({RATE_MARGIN:g} x its speed limit): "
                "not a motion this machine can make (gyro fault or noise)",
            )
            return
        newest = max(stamps)
        self.published_ns = newest
        stamp = Time(nanoseconds=newest).to_msg()
        # The tilt first: excavator_forward pairs each cylinder message with the tilt of its stamp.
        x, y, z = joints.up_cab.tolist()
        self.tilt_pub.publish(
            Vector3Stamped(
                header=Header(stamp=stamp, frame_id=self.upper_frame), vector=Vector3(x=x, y=y, z=z)
            )
        )
        # The lengths from the geometry are true ones; cylinder_lengths carries sensor readings
        # (true - zero_offset), which excavator_forward turns back into true lengths.
        readings = joints.lengths - self.exc.zero_offset[1:]
        self.cylinder_pub.publish(message_codec.joint_state(stamp, CYLINDERS, readings, joints.rates))


def main(args: Sequence[str] | None = None) -> int:
    return run_node(ImuState, "excavator", NODE, args)


if __name__ == "__main__":
    raise SystemExit(main())
