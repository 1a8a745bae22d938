"""Excavator core speed, printed as a table (a benchmark, not a test).

Measures microseconds per call of the closed-form paths (one state), batch throughput, and, in
the same run, a root-finding baseline: every joint angle found by bisecting the angle -> length
map after bracketing it on 240 samples, the way public excavator tools invert the cylinder
linkages. Ratios against that baseline are the numbers to read; absolute times vary by machine.

Run: python benchmarks/bench_excavator_core.py [--quick]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from excavator_kinematics.kinematics import Excavator

SAMPLES = 240


def per_call_us(fn: Callable[[], object], repeat: int) -> float:
    """Best of 5 rounds of `repeat` calls, in microseconds per call."""
    best = float("inf")
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(repeat):
            fn()
        best = min(best, (time.perf_counter() - start) / repeat)
    return best * 1e6


def best_seconds(fn: Callable[[], object], rounds: int = 3) -> float:
    """Best of a few timed calls (the first also pays for warming the allocator)."""
    best = float("inf")
    for _ in range(rounds):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


class BisectionBaseline:
    """Joint angles from lengths by sampling + bisection of the inverse map (no closed form)."""

    def __init__(self, exc: Excavator, tolerance: float = 1e-12) -> None:
        self.exc = exc
        ends = exc.joint_angles(np.stack((exc.limits.stroke_min, exc.limits.stroke_max)))
        lo, hi = ends.min(axis=0), ends.max(axis=0)
        self.grid = np.linspace(lo, hi, SAMPLES)  # (240, 3) angles per joint
        self.tolerance = tolerance

    def joint_angles(self, lengths: np.ndarray) -> np.ndarray:
        grid_lengths = self.exc.cylinder_lengths(self.grid)  # the forward map on 240 samples
        columns = np.arange(3)
        # Bracket: the sample interval whose lengths straddle the target (maps are monotonic).
        sign = np.sign(grid_lengths - lengths)
        index = np.argmax(sign[1:] != sign[:-1], axis=0)
        a, b = self.grid[index, columns], self.grid[index + 1, columns]
        fa = grid_lengths[index, columns] - lengths
        while np.max(np.abs(b - a)) > self.tolerance:
            mid = 0.5 * (a + b)
            fm = self.exc.cylinder_lengths(mid) - lengths
            left = np.sign(fm) == np.sign(fa)
            a, fa = np.where(left, mid, a), np.where(left, fm, fa)
            b = np.where(left, b, mid)
        return 0.5 * (a + b)

    def pose(self, D: np.ndarray) -> np.ndarray:
        theta = np.concatenate(([D[0]], self.joint_angles(D[1:])))
        return self.exc.open_chain_pose(theta)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    args = parser.parse_args()
    scale = 0.1 if args.quick else 1.0

    exc = Excavator.default()
    rng = np.random.default_rng(1)
    D = exc.limits.reference.copy()
    D_dot = np.array([0.3, 0.05, -0.08, 0.1])
    D_ddot = np.array([0.1, 0.02, 0.01, -0.03])
    Q_dot = exc.state(D, D_dot).Q_dot
    baseline = BisectionBaseline(exc)

    n = int(1000 * scale) or 100
    rows = [
        ("lengths -> pose (eqs. 1-3)", per_call_us(lambda: exc.pose(D), n)),
        ("full state: pose+twist+JC0+accel (eqs. 1-11)", per_call_us(lambda: exc.state(D, D_dot, D_ddot), n)),
        ("inverse rates Ddot = JC0^-1 Qdot (eq. 9)", per_call_us(lambda: exc.cylinder_rates(D, Q_dot), n)),
        ("baseline: lengths -> pose by bisection", per_call_us(lambda: baseline.pose(D), max(n // 20, 10))),
    ]
    batch_n = 100_000
    lo, hi = exc.limits.d_min, exc.limits.d_max
    batch = rng.uniform(lo + 0.01 * (hi - lo), hi - 0.01 * (hi - lo), size=(batch_n, 4))
    rates = rng.uniform(-1, 1, size=(batch_n, 4)) * exc.limits.max_rates
    accelerations = np.zeros_like(batch)
    batch_state = best_seconds(lambda: exc.state(batch, rates, accelerations))
    batch_pose = best_seconds(lambda: exc.pose(batch))

    error = np.max(np.abs(baseline.pose(D) - exc.pose(D)))
    # Machine speed for reading the absolute numbers: one Python float multiply-add.
    a, b, c = 1.1, 2.2, 3.3
    float_ns = per_call_us(lambda: a * b + c, 100_000) * 1e3
    print(f"Excavator core benchmark ({exc.name}), one state unless stated")
    print(f"{'operation':<48}{'us/call':>12}")
    print("-" * 60)
    for name, us in rows:
        print(f"{name:<48}{us:>12.2f}")
    print("-" * 60)
    print(f"{'batch of 1e5: full state':<48}{batch_n / batch_state / 1e6:>9.2f} M states/s")
    print(f"{'batch of 1e5: pose':<48}{batch_n / batch_pose / 1e6:>9.2f} M states/s")
    speedup = rows[3][1] / rows[0][1]
    print(f"{'speed-up of closed form over bisection (pose)':<48}{speedup:>11.0f}x")
    print(f"{'closed form vs bisection, max |dQ|':<48}{error:>12.2e}")
    print(f"{'machine: Python a*b+c incl. call (ns)':<48}{float_ns:>12.1f}")
    print()
    targets = [
        ("full state <= 30 us per call", rows[1][1] <= 30.0),
        ("batch >= 1 M states/s", batch_n / batch_state >= 1e6),
        (">= 50x the bisection baseline", speedup >= 50.0),
    ]
    for name, met in targets:
        print(f"target {name:<40} {'met' if met else 'MISSED'}")


if __name__ == "__main__":
    main()
