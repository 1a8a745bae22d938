"""machine_markers: any registered machine drawn as visualization_msgs/MarkerArray in its base frame.

    machine_markers --ros-args --params-file config/<machine>.yaml [--params-file my_settings.yaml]

The machine is the one whose section (``/**: ros__parameters: <section>:``) the given params
files hold (exactly one machine; several, or none, stop the node at start-up with exit code 2).
Settings (``/**/machine_markers`` of ``config/machine_markers.yaml``, the one file for every
machine): ``base_frame``, ``rate`` (Hz, the most MarkerArrays per second), ``qos_depth``,
``warning_period``, ``topics.states`` (sensor_msgs/JointState inputs) and ``topics.markers``
(the output).

The machine's state (``Machine.joint_names``: a serial machine's joints, the excavator's swing
joint and three cylinders) is gathered by joint name from every topic of ``topics.states``: the
latest finite position of each joint within its limits widened by their span wins (a value beyond
is logged, throttled, and ignored), whatever topic brought it, so one setting serves the
serial machines (``joint_states``) and the excavator (``joint_states`` for the swing,
``cylinder_lengths`` for the cylinders). Once every joint has a value, each timer tick that
follows a new message draws the state (``Machine.scene``) and publishes one MarkerArray, stamped
with the newest input's stamp: cylinders for links, barrels and rods, spheres for joints and
pins, namespace = the kind of solid (``link``, ``barrel``, ``rod``, ...) so a display can hide a
kind. A state the machine cannot take (a cylinder beyond its stroke), or one whose solids are not
finite, is logged, throttled, and not drawn: nothing publishes NaN or inf.

With ``zones_file`` (docs/zones.md) every MarkerArray also holds the avoidance zones in the base
frame and the machine's monitored points (its ``monitored`` hook), coloured by their clearance
(:mod:`manipulator_kinematics.nodes.zone_markers`).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes import run_node
from manipulator_kinematics.nodes.base import (
    FRAME_PREFIX,
    MachineNode,
    input_qos,
    input_reliability,
)
from manipulator_kinematics.nodes.help import help_text, wants_help
from manipulator_kinematics.nodes.zone_markers import point_marker, stamped, zone_markers
from manipulator_kinematics.param_files import ConfigError, given_parameters
from manipulator_kinematics.registry import Machine, machines, machines_described
from manipulator_kinematics.scene import Solids, solids
from manipulator_kinematics.schema import Names, Number, Text
from manipulator_kinematics.zone_guard import ZoneGuard

NODE_NAME = "machine_markers"
DEFAULTS_FILE = "machine_markers.yaml"

SETTINGS = {
    "base_frame": Text(empty=False, doc="frame_id of the markers (the machine's base)"),
    "frame_prefix": FRAME_PREFIX,
    "rate": Number(
        min=0.0,
        max=1000.0,
        exclusive_min=True,
        unit="Hz",
        doc="most MarkerArrays per second; a new state is drawn at the next tick",
    ),
    "qos_depth": Number(min=1, max=100_000, integer=True, doc="keep-last depth of every topic"),
    "input_reliability": input_reliability("topics.states"),
    "warning_period": Number(
        min=0.0, max=3600.0, unit="s", doc="the same kind of rejection is logged at most this often"
    ),
    "zones_file": Text(
        doc="avoidance zone file (docs/zones.md): zones and monitored points drawn; empty: none"
    ),
    "topics": {
        "states": Names(doc="inputs: sensor_msgs/JointState topics, merged by joint name"),
        "markers": Text(empty=False, doc="output: visualization_msgs/MarkerArray"),
    },
}


def marker_array(parts: Solids, stamp: Time, frame_id: str) -> MarkerArray:
    """One state's solids (``parts`` of an unbatched scene) as markers (ns = kind, id = row)."""
    header = Header(stamp=stamp, frame_id=frame_id)
    markers = []
    for i, (kind, cylinder) in enumerate(zip(parts.kinds, parts.cylinder.tolist(), strict=True)):
        m = Marker(
            header=header,
            ns=kind,
            id=i,
            type=Marker.CYLINDER if cylinder else Marker.SPHERE,
            action=Marker.ADD,
        )
        m.pose.position.x, m.pose.position.y, m.pose.position.z = parts.position[i].tolist()
        o = m.pose.orientation
        o.x, o.y, o.z, o.w = parts.orientation[i].tolist()
        m.scale.x, m.scale.y, m.scale.z = parts.scale[i].tolist()
        m.color = ColorRGBA(**dict(zip("rgba", parts.color[i].tolist(), strict=True)))
        markers.append(m)
    return MarkerArray(markers=markers)


class MarkersNode(MachineNode):
    """Latest joint states of a registered machine -> MarkerArray (module docstring)."""

    SETTINGS = SETTINGS
    DEFAULTS_FILE = DEFAULTS_FILE

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        if machine.scene is None:
            raise ConfigError(f"machine {machine.name!r} has no scene hook: nothing to draw")
        s = self.settings
        if not s["topics"]["states"]:
            raise ConfigError("topics.states: give at least one sensor_msgs/JointState topic")
        self.frame = s["frame_prefix"] + s["base_frame"]
        self.joint_names = tuple(machine.joint_names(self.model))
        self.index = {name: i for i, name in enumerate(self.joint_names)}
        self.state = np.full(len(self.joint_names), np.nan)
        # A value beyond a joint's limits by more than their span is no state of this machine
        # (1e308 drew markers of infinite size); one a little beyond is still drawn, as measured.
        limits = machine.limits(self.model)
        bounds = dict(
            zip(limits.names, zip(limits.lower.tolist(), limits.upper.tolist(), strict=True), strict=True)
        )
        self.bounds = {
            name: (low - (high - low), high + (high - low))
            for name, (low, high) in bounds.items()
            if name in self.index
        }
        self.stamp: Time | None = None
        self.fresh = False
        self.log = ThrottledLog(self, s["warning_period"])
        qos = QoSProfile(depth=s["qos_depth"], reliability=ReliabilityPolicy.RELIABLE)
        self.publisher = self.create_publisher(MarkerArray, s["topics"]["markers"], qos)
        for topic in s["topics"]["states"]:
            self.create_subscription(
                JointState, topic, self.on_state, input_qos(s["qos_depth"], s["input_reliability"])
            )
        self.create_timer(1.0 / s["rate"], self.on_tick)
        self.zones = self.zones_of(s["zones_file"])
        self.get_logger().info(
            f"{machine.name}: {s['topics']['states']} {list(self.joint_names)} -> {s['topics']['markers']} "
            f"in frame {self.frame!r}, at most {s['rate']:g} Hz"
        )

    def on_state(self, msg: JointState) -> None:
        if len(msg.position) != len(msg.name):
            if msg.position:  # a velocity-only message is no state, and no error
                self.log(
                    "warning", f"ignored JointState: {len(msg.name)} names, {len(msg.position)} positions"
                )
            return
        taken = False
        for name, value in zip(msg.name, msg.position, strict=True):
            i = self.index.get(name)
            if i is None or not math.isfinite(value):
                continue
            low, high = self.bounds.get(name, (-math.inf, math.inf))
            if not low <= value <= high:
                self.log(
                    "warning",
                    f"ignored {name} = {value:.6g}: beyond its limits by more than "
                    f"their span [{low:.6g}, {high:.6g}]",
                )
                continue
            self.state[i] = value
            taken = True
        if taken:
            self.stamp, self.fresh = msg.header.stamp, True

    def on_tick(self) -> None:
        if not self.fresh or not np.all(np.isfinite(self.state)):
            return
        self.fresh = False
        try:
            parts = solids(self.machine.scene(self.model, self.state.copy()))
        except ValueError as error:  # StrokeError and the like: a state the machine cannot take
            self.log("warning", f"not drawn: {error}")
            return
        drawn = (parts.position, parts.orientation, parts.scale)
        if not all(np.all(np.isfinite(values)) for values in drawn):
            self.log("warning", f"not drawn: state {self.state.tolist()} gives non-finite markers")
            return
        markers = marker_array(parts, self.stamp, self.frame)
        if self.zones is not None:
            markers.markers += stamped(self.draw_zones(parts), self.stamp, self.frame)
        self.publisher.publish(markers)

    def zones_of(self, file: str) -> tuple[list, Any, list] | None:
        """(zones, the machine's monitored points, the zones' markers) of ``zones_file``; None
        without one (docs/zones.md)."""
        if not file:
            return None
        if self.machine.monitored is None:
            raise ConfigError(f"zones_file: machine {self.machine.name!r} has no monitored points")
        points = self.machine.monitored(self.model)
        zones = ZoneGuard.from_file(
            file, points.names, [1.0], 1.0, self.machine.read_surface, site_pose=True
        ).zones
        skipped = [z.name for z in zones if z.frame != "base"]
        if skipped:
            self.get_logger().warning(f"zones in the site frame are not drawn: {', '.join(skipped)}")
        return zones, points, zone_markers(zones)

    def draw_zones(self, parts: Solids) -> list[Marker]:
        """The zones and the monitored points at the state drawn (their size: the pins')."""
        zones, points, drawn = self.zones
        p = points.positions(self.state.copy())
        base = [z for z in zones if z.frame == "base"]
        clearance = np.min([z.clearance(p)[0] for z in base], axis=0) if base else np.full(len(p), np.inf)
        return [*drawn, point_marker(p, clearance, 2.5 * float(np.min(parts.scale)))]


def machine_of(argv: Sequence[str]) -> Machine:
    """The one registered machine whose section the ``--params-file`` files of ``argv`` hold."""
    given = given_parameters(argv)
    found = {m.name: m for m in machines_described(given).values()}
    if len(found) == 1:
        return next(iter(found.values()))
    if found:
        raise ConfigError(
            f"the params files describe several machines ({', '.join(sorted(found))}); "
            "give one machine's file"
        )
    files = ", ".join(f"config/{m.config_file} ({m.name})" for m in machines().values())
    raise ConfigError(f"no machine section in the params files; give a machine's file: {files}")


def main(args: Sequence[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    if wants_help(argv):
        print(help_text(MarkersNode, None, NODE_NAME, DEFAULTS_FILE))
        return 0
    try:
        machine = machine_of(argv)
    except ConfigError as error:
        print(f"configuration error: {error}", file=sys.stderr)
        return 2
    return run_node(MarkersNode, machine.name, NODE_NAME, argv)


if __name__ == "__main__":
    raise SystemExit(main())
