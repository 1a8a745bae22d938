"""The avoidance-zone scenario of the excavator tests (in one process and across processes): the
zone file, random target twists, and the zones' clearances computed from their definitions
(heights, a coordinate, the TIN's height), independently of :mod:`manipulator_kinematics.zones`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from excavator_kinematics.grade.design_surface import read_landxml

DATA = Path(__file__).resolve().parent / "data" / "zones"
ZONES = DATA / "excavator_zones.yaml"
# The zone file's boundaries plus margins: nothing above, ahead of, below them.
CEILING = 7.0 - 0.5
WALL = 7.0 - 0.3
FLOOR = -1.6 + 0.2
SURFACE_MARGIN = 0.3
#: What the velocity IK is told (settings zones_period, zones_stop_time): the actuators stop from
#: full speed in 0.3 s; a command acts at most 50 ms (10 ms state period plus latency).
PERIOD, STOP_TIME = 0.05, 0.3


def clearances(points: np.ndarray) -> dict[str, np.ndarray]:
    """Smallest clearance per zone (N,) of the monitored points (N, P, 3), base frame."""
    tin = read_landxml(DATA / "service.xml")
    height = tin.heights(points).height  # every point is over the TIN (it spans +-12 m)
    return {
        "power_line": CEILING - points[..., 2].max(axis=-1),
        "road_edge": WALL - points[..., 0].max(axis=-1),
        "floor": points[..., 2].min(axis=-1) - FLOOR,
        "gas_main": height.min(axis=-1) - SURFACE_MARGIN,
    }


class Targets:
    """Random target twists (base frame), each held for 0.5 to 3 s: half of them at a zone (up,
    down, forward, down and to the right, at 0.6 to 0.7 m/s), 30 % a random direction at 0.1 to
    0.8 m/s, 20 % back toward the start at 0.6 m/s (from the stroke ends a random walk runs into);
    the bucket angle held (no angular velocity about the boom-plane normal)."""

    AT_ZONES = (
        np.array([0.0, 0.0, 0.6]),
        np.array([0.0, 0.0, -0.6]),
        np.array([0.6, 0.0, 0.0]),
        np.array([0.0, -0.4, -0.5]),
    )

    def __init__(
        self, seed: int, home: np.ndarray, opening: tuple[tuple[float, np.ndarray], ...] = ()
    ) -> None:
        """``opening``: (seconds, linear velocity) held before the random targets begin."""
        self.rng = np.random.default_rng(seed)
        self.home = np.asarray(home, dtype=float)
        self.until, self.linear = -1.0, np.zeros(3)
        self.opening = np.cumsum([0.0, *(d for d, _ in opening)]), [np.asarray(v, float) for _, v in opening]

    def __call__(self, t: float, tip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The target at time ``t`` (s) with the bucket tip at ``tip``."""
        ends, scripted = self.opening
        if t < ends[-1]:
            return scripted[int(np.searchsorted(ends, t, side="right")) - 1], np.zeros(3)
        if t >= self.until:
            self.until = t + self.rng.uniform(0.5, 3.0)
            kind = self.rng.uniform()
            if kind < 0.5:
                self.linear = self.AT_ZONES[self.rng.integers(len(self.AT_ZONES))]
            else:
                direction = self.rng.normal(size=3) if kind < 0.8 else self.home - tip
                speed = self.rng.uniform(0.1, 0.8) if kind < 0.8 else 0.6
                self.linear = speed * direction / max(float(np.linalg.norm(direction)), 1e-9)
        return self.linear, np.zeros(3)
