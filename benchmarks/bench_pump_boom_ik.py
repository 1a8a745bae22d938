"""Benchmark (not a test): the pump boom's region IK against a numerical position-only IK on the same model.

Four pours, each a straight line interpolated every 100 mm (eqs. 5-7): the paper's two typical
pours (a horizontal line in a vertical plane, a slanted line in a horizontal plane with theta1
turning) and two more across five transition bands each (a vertical line, and a line 12.5 m below
the root pin's ground level in the plane theta1 = -1 rad, as into a basement). Every round solves
every point of every pour three ways, in this process, one after the other:

* region IK per point: ``PumpBoom.region_ik_point``, one pour point per call with the previous
  slew angle as seed, as a controller solves one point per cycle (the compiled kernel, loaded
  before the timing starts);
* region IK batched: ``PumpBoom.region_ik`` of all the points in one call (and, for reference, the
  same numpy path called with one point: the per-call overhead that the kernel avoids);
* numerical: ``scipy.optimize.least_squares`` on the tip position (residual tip(q) - p with the
  closed-form tip Jacobian, bounded by the joint limits, method ``dogbox``, the fastest of scipy's
  methods on this problem; tolerances 1e-10), seeded with the previous point's solution and the
  first point with the region IK's, as a controller without region planning would do.

Speed: median microseconds per point, ratios per round (target: per point >= 100x). Smoothness on
the same pours, and on 40 random 10 m lines in 3-D inside the table: the largest joint jump (deg)
between consecutive points (100 mm apart); the share of points where the solution leaves
positive-envelope shape (a section joint below the root-tip chord, paper Fig. 4); the share where
the numerical solver does not reach the point (tip error > 1 mm: stuck at a joint limit); and
repeatability: the pour driven out and back, the largest joint difference at the start point
(the region IK gives one shape per point; a seeded solver's shape depends on the way there).

Run: .venv/bin/python benchmarks/bench_pump_boom_ik.py [--rounds 5]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from scipy.optimize import least_squares

from pump_boom_kinematics.kinematics import PumpBoom, compiled_kernel
from pump_boom_kinematics.pour import TYPICAL_POURS, pour_line

C1, S1 = math.cos(-1.0), math.sin(-1.0)
#: name -> (start, end) in the base frame (m).
POURS = {
    **{name: (start, end) for name, (_, start, end) in TYPICAL_POURS.items()},
    "vertical_line": ((17.75, 0.0, 0.5), (17.75, 0.0, 29.5)),
    "basement_line": ((1.0 * C1, 1.0 * S1, -12.5), (30.0 * C1, 30.0 * S1, -12.5)),
}
TOLERANCE = 1e-10
RANDOM_LINES = 40
RANDOM_LENGTH = 10.0  # m
PLANE_LINES = 20_000


def numerical_ik(boom: PumpBoom, points: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, list[float]]:
    """Position-only least squares along a pour, each point seeded with the previous solution."""
    q, solutions, times = start, [], []
    bounds = (boom.limits.lower, boom.limits.upper)
    for p in points:
        begin = time.perf_counter_ns()
        q = least_squares(
            lambda x, p=p: boom.tip(x) - p,
            q,
            jac=boom.tip_jacobian,
            bounds=bounds,
            method="dogbox",
            xtol=TOLERANCE,
            ftol=TOLERANCE,
            gtol=TOLERANCE,
        ).x
        times.append((time.perf_counter_ns() - begin) / 1e3)
        solutions.append(q)
    return np.array(solutions), times


def region_per_point(boom: PumpBoom, points: np.ndarray, slew: float) -> tuple[np.ndarray, list[float]]:
    solutions, times = [], []
    for x, y, z in points.tolist():
        begin = time.perf_counter_ns()
        q, _ = boom.region_ik_point(x, y, z, slew)
        times.append((time.perf_counter_ns() - begin) / 1e3)
        solutions.append(q)
        slew = q[0]
    return np.array(solutions, dtype=float), times


def random_lines(boom: PumpBoom, count: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Points of ``count`` straight pours of RANDOM_LENGTH in random 3-D directions, every point
    solvable by the region IK (lines leaving the table are drawn again)."""
    lines = []
    while len(lines) < count:
        i, j, level = boom.table.index[rng.integers(len(boom.table))]
        r, z = np.array(boom.grid.corner(i, j, level)) + boom.grid.side(level) * rng.random(2)
        heading = rng.uniform(-math.pi, math.pi)
        start = np.array([r * math.cos(heading), r * math.sin(heading), z])
        direction = rng.normal(size=3)
        plan = pour_line(boom, start, start + RANDOM_LENGTH * direction / np.linalg.norm(direction))
        if plan.ok and not plan.truncated:
            lines.append(plan.points)
    return lines


def plane_continuity(boom: PumpBoom, count: int, rng: np.random.Generator) -> list[str]:
    """Rows of the continuity table: ``count`` random 4 m lines in the boom plane inside the covered
    area (100 mm steps, starts in squares drawn by count and by area), the largest joint change per
    step over all steps, the steps in a square's core, in bands between squares of one size and in
    bands between squares of different sizes (the window around the step's middle holds both)."""
    table = boom.table
    plane = table.random_lines(count, rng)
    result = boom.region_ik(np.stack([plane[..., 0], np.zeros(plane.shape[:-1]), plane[..., 1]], axis=-1))
    assert result.ok.all()
    step = np.degrees(np.abs(np.diff(result.q, axis=1)).max(axis=-1))  # (lines, 40)
    middle = 0.5 * (plane[:, 1:] + plane[:, :-1])
    half = 0.5 * boom.grid.band
    corners = [middle + [dr, dz] for dr in (-half, half) for dz in (-half, half)] + [middle]
    levels = np.stack([table.square(c[..., 0], c[..., 1])[..., 2] for c in corners], axis=-1)
    levels = np.where(levels < 0, levels.max(axis=-1, keepdims=True), levels)
    band = result.blended[:, 1:] | result.blended[:, :-1]
    mixed = band & (levels.min(axis=-1) != levels.max(axis=-1))
    kinds = [
        ("all steps", np.ones_like(band)),
        ("square cores", ~band),
        ("bands, squares of one size", band & ~mixed),
        ("bands between squares of different sizes", mixed),
    ]
    return [
        f"| {name} | {len(plane)} | {int(mask.sum())} | {step[mask].max(initial=0.0):.2f} |"
        for name, mask in kinds
    ]


def quality(boom: PumpBoom, q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per pour: largest joint jump between consecutive points (deg), points outside positive
    envelope, points not reached (tip error > 1 mm), point count."""
    error = np.abs(boom.tip(q) - points).max(axis=-1)
    return np.array(
        [
            math.degrees(float(np.abs(np.diff(q, axis=0)).max())),
            float(np.sum(~boom.positive_envelope(q))),
            float(np.sum(error > 1e-3)),
            float(len(points)),
        ]
    )


def smoothness_row(boom: PumpBoom, name: str, pours: list[np.ndarray]) -> str:
    """One table row over ``pours``: both solvers' quality and the out-and-back repeatability."""
    region, numeric, repeat = [], [], []
    for points in pours:
        q_region, _ = region_per_point(boom, points, math.atan2(points[0, 1], points[0, 0]))
        region.append(quality(boom, q_region, points))
        q_numeric, _ = numerical_ik(boom, points, q_region[0])
        numeric.append(quality(boom, q_numeric, points))
        back, _ = numerical_ik(boom, points[::-1], q_numeric[-1])
        repeat.append(math.degrees(float(np.abs(back[-1] - q_numeric[0]).max())))
    region_q, numeric_q = np.array(region), np.array(numeric)
    count = region_q[:, 3].sum()
    return (
        f"| {name} | {int(count)} | {region_q[:, 0].max():.1f} / {numeric_q[:, 0].max():.1f} "
        f"| {region_q[:, 1].sum() / count:.1%} / {numeric_q[:, 1].sum() / count:.1%} "
        f"| {numeric_q[:, 2].sum() / count:.1%} | {max(repeat):.1f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    boom = PumpBoom.default()
    compiled_kernel(boom, wait=True)  # numba: from its cache, or compiled the first time
    plans = {name: pour_line(boom, start, end) for name, (start, end) in POURS.items()}
    for name, plan in plans.items():
        assert plan.ok and not plan.truncated, (name, plan.message)
    everything = np.vstack([plan.points for plan in plans.values()])
    count = len(everything)
    print(
        f"{len(plans)} pours, {count} points every 100 mm; {args.rounds} rounds; numerical: "
        f"least_squares dogbox, tolerances {TOLERANCE:g}"
    )
    print(
        "round  region us/point  batched us/point  numpy path 1 point/call us  numerical us/point  "
        "per point  batched"
    )
    per_point_ratios, batch_ratios = [], []
    results: dict[str, dict[str, np.ndarray]] = {}
    for k in range(args.rounds):
        region_times, numeric_times = [], []
        for name, plan in plans.items():
            q_region, times = region_per_point(boom, plan.points, float(plan.q[0, 0]))
            region_times += times
            q_numeric, times = numerical_ik(boom, plan.points, plan.q[0])
            numeric_times += times
            results[name] = {"region": q_region, "numerical": q_numeric}
        repeats = 20
        begin = time.perf_counter()
        for _ in range(repeats):
            batched = boom.region_ik(everything)
        batch_us = (time.perf_counter() - begin) / (repeats * count) * 1e6
        assert batched.ok.all()
        numpy_times = []
        for point in everything:
            begin = time.perf_counter_ns()
            boom.region_ik(point)
            numpy_times.append((time.perf_counter_ns() - begin) / 1e3)
        region_us, numeric_us = statistics.median(region_times), statistics.median(numeric_times)
        per_point_ratios.append(numeric_us / region_us)
        batch_ratios.append(numeric_us / batch_us)
        print(
            f"{k + 1:5d}  {region_us:15.1f}  {batch_us:16.2f}  {statistics.median(numpy_times):27.0f}  "
            f"{numeric_us:18.0f}  "
            f"{per_point_ratios[-1]:8.0f}x  {batch_ratios[-1]:6.0f}x"
        )
    print(
        f"speed-up per point over the rounds: {min(per_point_ratios):.0f}-{max(per_point_ratios):.0f}x "
        f"(target >= 100x: met in {sum(r >= 100 for r in per_point_ratios)} of {len(per_point_ratios)}); "
        f"batched {min(batch_ratios):.0f}-{max(batch_ratios):.0f}x"
    )
    for name, plan in plans.items():  # the per-point path gives the plan's joints
        np.testing.assert_allclose(results[name]["region"], plan.q, atol=1e-12)
    print()
    print(
        "| pour | points | largest joint jump per 100 mm (deg), region / numerical "
        "| outside positive envelope, region / numerical | numerical: point not reached "
        "| numerical: out and back, joint difference at the start (deg) |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for name, plan in plans.items():
        print(smoothness_row(boom, name, [plan.points]))
    lines = random_lines(boom, RANDOM_LINES, np.random.default_rng(1))
    print(smoothness_row(boom, f"{RANDOM_LINES} random {RANDOM_LENGTH:g} m lines", lines))
    print()
    print(f"Continuity in the boom plane ({PLANE_LINES} random 4 m lines drawn; those inside the table):")
    print("| steps of 100 mm | lines | steps | largest joint change per 100 mm (deg, limit 8) |")
    print("| --- | ---: | ---: | ---: |")
    for row in plane_continuity(boom, PLANE_LINES, np.random.default_rng(2)):
        print(row)


if __name__ == "__main__":
    main()
