"""The avoidance-zone scenario of the hydraulic family's tests (in one process and across
processes), for the wheel loader and the knuckle crane: each machine's zone file
(test/data/zones/<machine>_zones.yaml: a ceiling, a wall, a floor and a LandXML TIN), random
target twists (test/zone_scenario.py's, with the loader's bucket turning too: it commands z and
alpha, its reach follows them), and the zones' clearances computed from their definitions (heights,
a coordinate, the TIN's plane), independently of :mod:`manipulator_kinematics.zones`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from zone_scenario import DATA, Targets


@dataclass(frozen=True)
class Scenario:
    """One machine's zones: the boundaries plus margins (nothing above ``ceiling``, ahead of
    ``wall`` in x, below ``floor``), the TIN's plane z = c + a x + b y and its margin, the zones
    it must come near, its targets' directions at the zones and turn rate (rad/s), and the
    opening (seconds, tool velocity or twist) that takes it straight at them first."""

    machine: str
    config: str
    ceiling: float
    wall: float
    floor: float
    plane: tuple[float, float, float]
    surface_margin: float
    names: tuple[str, str, str, str]  # ceiling, wall, floor, surface
    reached: tuple[str, ...]
    at_zones: tuple[np.ndarray, ...]
    turn: float
    opening: tuple[tuple[float, np.ndarray], ...]

    @property
    def zones(self):
        return DATA / f"{self.machine}_zones.yaml"

    def clearances(self, points: np.ndarray) -> dict[str, np.ndarray]:
        """Smallest clearance per zone (N,) of the monitored points (N, P, 3), base frame."""
        c, a, b = self.plane
        ground = c + a * points[..., 0] + b * points[..., 1]
        ceiling, wall, floor, surface = self.names
        return {
            ceiling: self.ceiling - points[..., 2].max(axis=-1),
            wall: self.wall - points[..., 0].max(axis=-1),
            floor: points[..., 2].min(axis=-1) - self.floor,
            surface: (points[..., 2] - ground).min(axis=-1) - self.surface_margin,
        }

    def targets(self, seed: int, home: np.ndarray, opening: tuple | None = None) -> FamilyTargets:
        """Random targets after ``opening`` (default: the scenario's)."""
        return FamilyTargets(
            seed, home, self.at_zones, self.turn, self.opening if opening is None else opening
        )


class FamilyTargets(Targets):
    """:class:`zone_scenario.Targets` with this machine's directions at the zones and, with each
    new target, a random turn about the boom-plane normal (y) up to ``turn`` rad/s; an opening's
    entries may be whole twists [v, omega] (6,)."""

    def __init__(
        self, seed: int, home: np.ndarray, at_zones: tuple[np.ndarray, ...], turn: float, opening: tuple = ()
    ) -> None:
        super().__init__(seed, home, opening)
        self.AT_ZONES, self.turn = at_zones, turn
        self.held, self.angular = self.until, np.zeros(3)

    def __call__(self, t: float, tip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        linear, _ = super().__call__(t, tip)
        if len(linear) == 6:  # an opening's twist [v, omega]
            return linear[:3], linear[3:]
        if self.until != self.held:  # a new random target began
            self.held = self.until
            self.angular = np.array([0.0, self.rng.uniform(-self.turn, self.turn), 0.0])
        return linear, self.angular


SCENARIOS = {
    "wheel_loader": Scenario(
        "wheel_loader",
        "wheel_loader_wl20.yaml",
        ceiling=3.4 - 0.3,
        wall=3.9 - 0.3,
        floor=-0.6 + 0.1,
        plane=(-1.2, 0.25, 0.0),
        surface_margin=0.1,
        names=("roof", "wall", "floor", "ground"),
        reached=("roof", "wall", "ground"),
        # Up, down, and the bucket curled and dumped (its tip goes ahead and back with alpha).
        at_zones=(np.array([0.0, 0.0, 0.4]), np.array([0.0, 0.0, -0.4]), np.array([0.0, 0.0, 0.1])),
        turn=0.5,
        # The bucket curled back to its stroke end (about 2 s; 5 s leave room for the nodes'
        # start-up: half curled, the lift's arc meets the wall before the roof), lifted to the
        # roof (4 cm from the wall on the way), dumped at the top (its tip goes out to the wall),
        # curled back and lowered (dumped, the way down runs into the wall). The ground is met
        # in the random targets.
        opening=(
            (5.0, np.array([0.0, 0.0, 0.0, 0.0, 0.3, 0.0])),
            (12.0, np.array([0.0, 0.0, 0.4])),
            (3.0, np.array([0.0, 0.0, 0.0, 0.0, -0.3, 0.0])),
            (3.0, np.array([0.0, 0.0, 0.0, 0.0, 0.3, 0.0])),
            (10.0, np.array([0.0, 0.0, -0.6])),
        ),
    ),
    "knuckle_crane": Scenario(
        "knuckle_crane",
        "knuckle_crane_kc100.yaml",
        ceiling=7.0 - 0.5,
        wall=9.0 - 0.3,
        floor=-2.0 + 0.3,
        plane=(-1.0, 0.05, 0.15),
        surface_margin=0.3,
        names=("power_line", "road_edge", "floor", "gas_main"),
        reached=("power_line", "road_edge", "gas_main"),
        at_zones=Targets.AT_ZONES,
        turn=0.0,
        # Ahead to the wall, up along it to the ceiling, down to the TIN. Not up first: held at
        # the ceiling, the tool's path curves up into it within the check's horizon, so it slides
        # ahead only slowly (docs/zones.md, "Checked"; test_zones_family.py's creep test).
        opening=(
            (8.0, np.array([0.6, 0.0, 0.0])),
            (14.0, np.array([0.0, 0.0, 0.6])),
            (16.0, np.array([0.0, 0.0, -0.6])),
        ),
    ),
}
