"""The excavator's monitored points: where they are and how fast a command moves them (numpy).

The avoidance zones (:mod:`manipulator_kinematics.zones`, docs/zones.md) watch, in the base frame:
every pin of :meth:`excavator_kinematics.core.kinematics.Excavator.pins` (the bucket tip, the tool point
Q[:3] of eq. 3, among them), both ends of the cutting edge (tip +- w/2 along the boom-plane normal
(-sin theta1, cos theta1, 0), as the grade outputs), the bucket's side outline on both side faces
(``bucket.outline`` of the machine file, bucket frame) and the upper structure's tail
(``swing.tail_radius`` at each of ``swing.tail_heights``, behind the swing axis), when the machine
file gives them.

Velocities are forward differences along the command: (p(D + h D_dot) - p(D)) / h with h =
:data:`STEP` s. The model has a closed form for the tip's velocity only (eq. 8), not for the
linkage pins, and the differences need no second model (errors: round-off ~1e-9 m/s, the step's
curvature ~h |p''| / 2 < 1e-5 m/s at the CET200's speeds; test/test_zones_excavator.py checks them
against central differences). Forward, not central: the velocity IK never commands an actuator
outward within 1e-4 of its end (rate_command.END_ZONE), so D + h D_dot is always inside the
strokes, where D - h D_dot may not be. Both states are one batched call of the model.
"""

from __future__ import annotations

import numpy as np

from excavator_kinematics.core.kinematics import Excavator

#: Time step (s) of the differences along the command: the velocities' and the accelerations'
#: (the second differences need a longer one: the positions' round-off, about 1e-11 m, over k^2).
STEP, CURVE_STEP = 1e-6, 1e-3


class MonitoredPoints:
    """Names, positions and velocities of the points the avoidance zones watch on one excavator."""

    def __init__(self, exc: Excavator) -> None:
        self.exc = exc
        d = exc.description
        pins = list(exc.pins(exc.limits.reference))
        self._outline = np.array(d.bucket_outline, dtype=float).reshape(-1, 2)
        self._tail = np.array(d.tail, dtype=float).reshape(-1, 2)
        self.names: list[str] = [
            *pins,
            "left_corner",
            "right_corner",
            *(f"bucket_outline_{i}_{side}" for side in ("left", "right") for i in range(len(self._outline))),
            *(f"tail_{i}" for i in range(len(self._tail))),
        ]

    def positions(self, D: np.ndarray) -> np.ndarray:
        """Positions (..., P, 3) in the base frame of states D (..., 4), in the order of ``names``."""
        exc = self.exc
        pins = exc.pins(D)
        t1 = np.asarray(D, dtype=float)[..., 0]
        c1, s1, zero = np.cos(t1), np.sin(t1), np.zeros_like(t1)
        across = np.stack((-s1, c1, zero), axis=-1)  # boom-plane normal, left
        half = 0.5 * exc.bucket_width * across
        tip = pins["bucket_tip"]
        points = [*pins.values(), tip + half, tip - half]
        if len(self._outline):
            pin = pins["bucket_pin"]
            x = tip - pin
            x /= np.linalg.norm(x, axis=-1, keepdims=True)
            radial = np.stack((c1, s1, zero), axis=-1)
            # The bucket frame's y: x turned +90 deg in the boom plane (r, z).
            horizontal = np.sum(x * radial, axis=-1, keepdims=True)
            y = np.concatenate((-x[..., 2:3] * radial[..., :2], horizontal), axis=-1)
            side = [pin + u * x + v * y for u, v in self._outline]
            points += [p + half for p in side] + [p - half for p in side]
        for radius, height in self._tail:
            points.append(np.stack((-radius * c1, -radius * s1, np.full_like(t1, height)), axis=-1))
        return np.stack(points, axis=-2)

    def __call__(self, D: np.ndarray, D_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (P, 3) at state D (4,) for the actuator rates D_dot (4,)."""
        return self.motion(D, D_dot)[:2]

    def motion(self, D: np.ndarray, D_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations (P, 3) at state D (4,) for the actuator rates
        D_dot (4,) held: the accelerations are how the points' paths curve (the zones' check),
        second differences along the command with k = :data:`CURVE_STEP`: central, (p(D + k D_dot)
        - 2 p(D) + p(D - k D_dot)) / k^2, where both states are inside the strokes, else one-sided
        (p(D) - 2 p(D + k D_dot) + p(D + 2k D_dot)) / k^2 ahead, or behind (k < 0), whichever is
        (a command close to an end), else ahead in a quarter of the room there is (none: zero, a
        straight path). The four states in one batched call."""
        D = np.asarray(D, dtype=float)
        D_dot = np.asarray(D_dot, dtype=float)
        k, central = self._curve_step(D, D_dot)
        if k == 0.0:  # no room on either side (a command outward at an end): taken as straight
            p, v = self.positions(np.stack((D, D + STEP * D_dot)))
            return p, (v - p) / STEP, np.zeros_like(p)
        offsets = (-k, k) if central else (k, 2.0 * k)
        at = self.positions(np.stack((D, D + STEP * D_dot, D + offsets[0] * D_dot, D + offsets[1] * D_dot)))
        middle, side = (at[0], at[2]) if central else (at[2], at[0])
        return at[0], (at[1] - at[0]) / STEP, (side - 2.0 * middle + at[3]) / (k * k)

    def _curve_step(self, D: np.ndarray, D_dot: np.ndarray) -> tuple[float, bool]:
        """(k, central) of :meth:`motion`'s second difference."""
        limits = self.exc.limits
        lo, hi = limits.d_min.copy(), limits.d_max.copy()
        if limits.continuous_swing:
            lo[0], hi[0] = -np.inf, np.inf

        def inside(*offsets: float) -> bool:
            ends = D + np.multiply.outer(offsets, D_dot)
            return bool(np.all((lo <= ends) & (ends <= hi)))

        if inside(-CURVE_STEP, CURVE_STEP):
            return CURVE_STEP, True
        for k in (CURVE_STEP, -CURVE_STEP):
            if inside(k, 2.0 * k):
                return k, False
        room = np.where(D_dot > 0.0, hi - D, D - lo) / np.maximum(np.abs(D_dot), 1e-300)
        return max(0.25 * float(np.min(room)), 0.0), False


class ReadingPoints(MonitoredPoints):
    """The monitored points of sensor readings (as joint_states / cylinder_lengths carry them; D =
    reading + zero_offset): the registry's ``monitored`` hook, whose states are the machine's
    joint values (machine_markers draws the zones' points with it)."""

    def positions(self, D: np.ndarray) -> np.ndarray:
        return super().positions(np.asarray(D, dtype=float) + self.exc.zero_offset)


__all__ = ["CURVE_STEP", "STEP", "MonitoredPoints", "ReadingPoints"]
