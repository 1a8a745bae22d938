"""The avoidance zones' cost per velocity-IK command, printed as a table (a benchmark, not a test).

Issue 34's budget: the check adds at most 0.2 ms per command at 30 monitored points and 10 zones.
Measured in the same run, in rounds, at 30 points (random, about a machine) and 10 zones (a
ceiling, a floor, three walls, two boxes, two swing sectors and a 1,800-triangle LandXML-style
TIN surface):

* ``ZoneGuard.check``: what the velocity IK adds per command given the points' positions,
  velocities and accelerations (stop time, clearances, the command in flight, the scale, the
  verdict);
* ``Monitor.check`` alone: compiled (:mod:`manipulator_kinematics.zone_kernel`, the TIN in
  numpy), without the TIN, on the numpy path (``compiled=False``: every zone of a kind in one
  array operation), and zone by zone (a loop over ``Zone.clearance`` and ``scale_for``: the
  baseline);
* the excavator's 23 monitored points with their velocities and accelerations
  (``MonitoredPoints.motion``: one batched ``Excavator.pins`` of four states), the
  machine-specific part of the command's cost;
* the same for the hydraulic family's wheel loader (WL20) and knuckle crane (KC100):
  ``HydraulicModel.monitored_motion`` (every pin and both corners, velocities and accelerations
  in closed form), alone and
  with ``ZoneGuard.check``: what hydraulic_velocity_ik adds per command.

Run: python benchmarks/bench_zones.py [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np
from matplotlib.tri import Triangulation
from tables import print_table

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.grade.design_surface import Tin
from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.zone_guard import ZoneGuard
from manipulator_kinematics.zones import KERNEL, Monitor, Zone, scale_for, stop_time

POINTS, PERIOD, STOP = 30, 0.05, 0.3
#: How long the command in force goes on (s): the check's in-flight term (its cost is the same at any value).
DELAY = 0.02


def per_call_us(fn: Callable[[], object], repeat: int, rounds: int) -> list[float]:
    """Microseconds per call of each round of ``repeat`` calls."""
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(repeat):
            fn()
        times.append((time.perf_counter() - start) / repeat * 1e6)
    return times


def zones(rng: np.random.Generator) -> list[Zone]:
    xy = rng.uniform(-15.0, 15.0, (900, 2))
    tin = Tin(
        np.column_stack([xy, -1.5 + 0.05 * xy[:, 0]]), Triangulation(xy[:, 0], xy[:, 1]).triangles, "bench"
    )
    made = [
        ("ceiling", {"height": 7.0}, None),
        ("floor", {"height": -3.0}, None),
        ("wall", {"point": [7.0, 0.0], "normal": [1.0, 0.0]}, None),
        ("wall", {"point": [0.0, 6.0], "normal": [0.2, 1.0]}, None),
        ("wall", {"point": [-5.0, 0.0], "normal": [-1.0, 0.3]}, None),
        ("box", {"min": [2.0, 3.0, 0.0], "max": [5.0, 5.0, 3.0]}, None),
        ("box", {"min": [-6.0, -6.0, -1.0], "max": [-3.0, -4.0, 2.0]}, None),
        ("sector", {"from": 2.5, "to": -2.5}, None),
        ("sector", {"from": -1.2, "to": -0.9}, None),
        ("surface", {"side": "below", "surface": "", "file": "bench.xml"}, tin),
    ]
    return [
        Zone(f"{kind}_{i}", kind, "base", 0.3, values, surface)
        for i, (kind, values, surface) in enumerate(made)
    ]


def zone_by_zone(all_zones: list[Zone], p: np.ndarray, v: np.ndarray, T: float) -> float:
    """The baseline: each zone's clearance and scale on its own."""
    scale = 1.0
    for zone in all_zones:
        c, g = zone.clearance(p)
        scale = min(scale, float(scale_for(c, -np.sum(g * v, axis=-1), T, PERIOD).min()))
    return scale


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = parser.parse_args()
    rounds, repeat = (3, 300) if args.quick else (5, 1000)
    rng = np.random.default_rng(34)
    all_zones = zones(rng)
    names = [f"point_{i}" for i in range(POINTS)]
    p = rng.uniform([-4.0, -4.0, -1.0], [8.0, 4.0, 7.0], (POINTS, 3))
    v = rng.normal(0.0, 0.5, (POINTS, 3))
    a = rng.normal(0.0, 0.3, (POINTS, 3))
    rates = rng.uniform(-0.2, 0.2, 4)
    decelerations = np.array([1.0, 0.15, 0.18, 0.2]) / STOP
    guard = ZoneGuard(all_zones, names, decelerations, PERIOD)
    monitor, without_tin = Monitor(all_zones, names), Monitor(all_zones[:-1], names)
    T = stop_time(rates, decelerations)
    assert KERNEL.get(wait=True) is not None
    assert (
        abs(monitor.check(p, v, T, PERIOD, compiled=False).scale - monitor.check(p, v, T, PERIOD).scale)
        < 1e-12
    )
    # The batched check and the zone-by-zone baseline agree (the benchmark measures one answer).
    assert abs(monitor.check(p, v, T, PERIOD).scale - zone_by_zone(all_zones, p, v, T)) < 1e-12

    exc = Excavator.default()
    points = MonitoredPoints(exc)
    D, D_dot = exc.limits.reference, np.array([0.3, 0.1, -0.1, 0.15])
    q, qv, qa = points.motion(D, D_dot)
    excavator_guard = ZoneGuard(all_zones, points.names, exc.limits.max_rates / STOP, PERIOD)

    def excavator_check(q: np.ndarray, qv: np.ndarray, qa: np.ndarray) -> object:
        return excavator_guard.check(q, qv, D_dot, accelerations=qa, delay=DELAY)

    rows = [
        (
            f"ZoneGuard.check, {POINTS} points x 10 zones",
            per_call_us(lambda: guard.check(p, v, rates, accelerations=a, delay=DELAY), repeat, rounds),
        ),
        (
            f"Monitor.check, {POINTS} x 10",
            per_call_us(lambda: monitor.check(p, v, T, PERIOD), repeat, rounds),
        ),
        (
            f"Monitor.check, {POINTS} x 9 (no TIN)",
            per_call_us(lambda: without_tin.check(p, v, T, PERIOD), repeat, rounds),
        ),
        (
            f"Monitor.check numpy path, {POINTS} x 10",
            per_call_us(lambda: monitor.check(p, v, T, PERIOD, compiled=False), repeat, rounds),
        ),
        (
            f"zone by zone (baseline), {POINTS} x 10",
            per_call_us(lambda: zone_by_zone(all_zones, p, v, T), repeat, rounds),
        ),
        (
            f"excavator: {len(points.names)} points + velocities + accelerations",
            per_call_us(lambda: points.motion(D, D_dot), repeat, rounds),
        ),
        (
            f"excavator: points + ZoneGuard.check ({len(points.names)} x 10)",
            per_call_us(lambda: excavator_check(*points.motion(D, D_dot)), repeat, rounds),
        ),
    ]
    for label, file in (
        ("wheel loader", "wheel_loader_wl20.yaml"),
        ("knuckle crane", "knuckle_crane_kc100.yaml"),
    ):
        h = HydraulicModel.from_file(config_path(file))
        rate = 0.5 * h.max_speed
        names = h.monitored(h.reference, rate)[0]
        family_guard = ZoneGuard(all_zones, names, h.max_speed / STOP, PERIOD)

        def family_check(
            h: HydraulicModel = h, rate: np.ndarray = rate, g: ZoneGuard = family_guard
        ) -> object:
            _, fp, fv, fa = h.monitored_motion(h.reference, rate)
            return g.check(fp, fv, rate, accelerations=fa, delay=DELAY)

        rows += [
            (
                f"{label}: {len(names)} points + velocities + accelerations",
                per_call_us(lambda h=h, rate=rate: h.monitored_motion(h.reference, rate), repeat, rounds),
            ),
            (
                f"{label}: points + ZoneGuard.check ({len(names)} x 10)",
                per_call_us(family_check, repeat, rounds),
            ),
        ]
    assert q.shape == qv.shape == qa.shape == (len(points.names), 3)
    print_table(
        ["per command", f"us, median of {rounds} rounds", "rounds (us)"],
        [
            [name, f"{statistics.median(times):.1f}", ", ".join(f"{t:.1f}" for t in times)]
            for name, times in rows
        ],
    )
    ratio = [b / a for a, b in zip(rows[1][1], rows[4][1], strict=True)]
    print(
        f"\nzone by zone / Monitor.check: median {statistics.median(ratio):.2f} x "
        f"(rounds: {', '.join(f'{r:.2f}' for r in ratio)}); budget 200 us per command: "
        f"ZoneGuard.check median {statistics.median(rows[0][1]):.1f} us"
    )


if __name__ == "__main__":
    main()
