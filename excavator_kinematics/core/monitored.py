"""The excavator's monitored points: where they are and how fast a command moves them.

The avoidance zones (:mod:`manipulator_kinematics.zones`, docs/zones.md) watch, in the base frame:
every pin of :meth:`excavator_kinematics.core.kinematics.Excavator.pins` (the bucket tip, the tool point
Q[:3] of eq. 3, among them), both ends of the cutting edge (tip +- w/2 along the boom-plane normal
(-sin theta1, cos theta1, 0), as the grade outputs), the bucket's side outline on both side faces
(``bucket.outline`` of the machine file, bucket frame) and the upper structure's tail
(``swing.tail_radius`` at each of ``swing.tail_heights``, behind the swing axis), when the machine
file gives them.

They are the hydraulic family's monitored points of the same machine
(:meth:`manipulator_kinematics.hydraulic.HydraulicModel.monitored_motion` of the machine file's
``hydraulic_machine`` section, whose pose and JC0 equal the excavator model's to 1e-12:
test/test_excavator_family_file.py) under the excavator's names: positions, velocities and
accelerations at constant actuator rates in closed form (the dyads' derivatives, the swing's
centripetal and Coriolis terms), one state compiled (the family kernel: a velocity-IK command
costs microseconds), a batch in numpy. The excavator's own model has a closed form for the tip's
velocity only (eq. 8).
"""

from __future__ import annotations

import numpy as np

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.machine_file import PINS
from manipulator_kinematics.hydraulic.model import StrokeError


class MonitoredPoints:
    """Names, positions, velocities and accelerations of the points the avoidance zones watch on
    one excavator (module docstring)."""

    def __init__(self, exc: Excavator) -> None:
        self.exc = exc
        d = exc.description
        #: The family's model of the machine file's linkage (module docstring): the excavator's own
        #: numpy core (Excavator.hydraulic).
        self.family = exc.hydraulic
        pins = list(exc.pins(exc.limits.reference))
        self.names: list[str] = [
            *pins,
            "left_corner",
            "right_corner",
            *(
                f"bucket_outline_{i}_{side}"
                for side in ("left", "right")
                for i in range(len(d.bucket_outline))
            ),
            *(f"tail_{i}" for i in range(len(d.tail))),
        ]
        family = self.family.monitored_points.names

        def family_name(name: str) -> str:
            if name.startswith("bucket_outline_"):  # one point per outline point where the width is 0
                tool = "tool_outline_" + name.removeprefix("bucket_outline_")
                return tool if tool in family else tool.rsplit("_", 1)[0]
            return PINS.get(name, name)

        # Where each of ``names`` is among the family's points.
        self._order = np.array([family.index(family_name(name)) for name in self.names])

    def positions(self, D: np.ndarray) -> np.ndarray:
        """Positions (..., P, 3) in the base frame of states D (..., 4), in the order of ``names``."""
        D = self.exc.family_state(D)
        return self.family.monitored_motion(D, np.zeros(D.shape))[1][..., self._order, :]

    def __call__(self, D: np.ndarray, D_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (P, 3) at state D (4,) for the actuator rates D_dot (4,)."""
        return self.motion(D, D_dot)[:2]

    def motion(self, D: np.ndarray, D_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations (P, 3) at state D (4,) for the actuator rates
        D_dot (4,) held: the accelerations are how the points' paths curve (the zones' check)."""
        try:
            _, p, v, a = self.family.monitored_motion(D, D_dot)
        except StrokeError:  # a state the excavator takes (a round-off beyond an end), or none
            _, p, v, a = self.family.monitored_motion(self.exc.family_state(D), D_dot)
        order = self._order
        return p[order], v[order], a[order]


class ReadingPoints(MonitoredPoints):
    """The monitored points of sensor readings (as joint_states / cylinder_lengths carry them; D =
    reading + zero_offset): the registry's ``monitored`` hook, whose states are the machine's
    joint values (machine_markers draws the zones' points with it)."""

    def positions(self, D: np.ndarray) -> np.ndarray:
        return super().positions(np.asarray(D, dtype=float) + self.exc.zero_offset)


__all__ = ["MonitoredPoints", "ReadingPoints"]
