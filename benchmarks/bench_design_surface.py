"""Design-surface queries on a 10^5-triangle TIN, printed as a table (a benchmark, not a test).

The forward node asks, per input message (up to 1 kHz), for the heights of three points (tip and
both ends of the cutting edge) above the design TIN. Measured in the same run, in rounds:

* ``Tin.heights`` (matplotlib's TrapezoidMapTriFinder point location + the triangle's plane);
* the baseline ``Tin.locate_all_triangles`` (every point against every triangle, numpy) + the
  same plane, i.e. what one writes without a spatial index;
* the whole per-message grade step (cutting edge, site pose, heights) and a batch of 10^4 points;
* loading: writing and reading the LandXML file, and building the index.

Run: python benchmarks/bench_design_surface.py [--quick]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from matplotlib.tri import Triangulation

from excavator_kinematics.grade.design_surface import SitePose, Tin, cutting_edge, read_landxml, write_landxml

E0, N0 = 431_000.0, 5_861_000.0


def per_call_us(fn: Callable[[], object], repeat: int, rounds: int) -> list[float]:
    """Microseconds per call of each round of ``repeat`` calls."""
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(repeat):
            fn()
        times.append((time.perf_counter() - start) / repeat * 1e6)
    return times


def terrain(triangles: int, rng: np.random.Generator) -> Tin:
    """A scattered-point Delaunay TIN of about ``triangles`` triangles over 500 m x 500 m."""
    xy = rng.uniform(0.0, 500.0, (triangles // 2 + 2, 2))
    z = 100.0 + 2.0 * np.sin(xy[:, 0] / 40.0) + 0.01 * xy[:, 1] + rng.normal(0.0, 0.05, len(xy))
    faces = Triangulation(xy[:, 0], xy[:, 1]).triangles
    return Tin(np.column_stack([xy + [E0, N0], z]), faces, "bench")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--triangles", type=int, default=100_000)
    args = parser.parse_args()
    rounds, repeat = (3, 200) if args.quick else (5, 2000)
    rng = np.random.default_rng(7)
    tin = terrain(args.triangles, rng)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.xml"
        start = time.perf_counter()
        write_landxml(path, tin)
        written = time.perf_counter() - start
        start = time.perf_counter()
        loaded = read_landxml(path)
        read = time.perf_counter() - start
        size = path.stat().st_size
    start = time.perf_counter()
    Tin(tin.vertices, tin.faces)
    index = time.perf_counter() - start
    print(
        f"TIN: {len(tin.faces)} triangles, {len(tin.vertices)} points; LandXML {size / 1e6:.1f} MB: "
        f"written in {written:.2f} s, read + indexed in {read:.2f} s (index alone {index:.2f} s)"
    )
    assert np.array_equal(loaded.faces, tin.faces)

    pose = SitePose.from_rpy([E0 + 250.0, N0 + 250.0, 99.0], [0.01, -0.05, 0.4])
    tip = np.array([6.0, 0.5, -0.5])
    three = pose.apply(cutting_edge(tip, 0.3, 1.0))
    batch = np.column_stack([rng.uniform(0, 500, (10_000, 2)) + [E0, N0], np.full(10_000, 101.0)])

    def brute(points: np.ndarray) -> np.ndarray:
        triangle = tin.locate_all_triangles(points[..., :2])
        a, b, c = np.moveaxis(tin.planes[triangle], -1, 0)
        local = points - tin.origin
        return local[..., 2] - (a * local[..., 0] + b * local[..., 1] + c)

    np.testing.assert_allclose(tin.heights(three).height, brute(three), rtol=0, atol=1e-9)
    rows = [
        ("3 points: Tin.heights (trapezoid map)", per_call_us(lambda: tin.heights(three), repeat, rounds)),
        (
            "3 points: brute force (all triangles)",
            per_call_us(lambda: brute(three), max(repeat // 100, 5), rounds),
        ),
        (
            "grade step: edge + site pose + heights",
            per_call_us(lambda: tin.heights(pose.apply(cutting_edge(tip, 0.3, 1.0))), repeat, rounds),
        ),
        ("10^4 points: Tin.heights", per_call_us(lambda: tin.heights(batch), 5, rounds)),
    ]
    print(f"\n| query ({len(tin.faces)} triangles) | us per call, median of {rounds} rounds | rounds |")
    print("| --- | --- | --- |")
    for name, times in rows:
        print(f"| {name} | {np.median(times):.1f} | {', '.join(f'{t:.1f}' for t in times)} |")
    ratio = [b / i for i, b in zip(rows[0][1], rows[1][1], strict=True)]
    print(
        f"\nbrute force / trapezoid map, 3 points: median {np.median(ratio):.0f} x "
        f"(rounds: {', '.join(f'{r:.0f}' for r in ratio)}); "
        f"batch: {np.median(rows[3][1]) / 1e4 * 1e3:.0f} ns per point"
    )


if __name__ == "__main__":
    main()
