"""Excavator core speed, printed as tables (a benchmark, not a test).

Measures, in one run and over several rounds, the CPU time of this thread (time.thread_time:
what a call costs, not counting the time other processes on a shared machine take the core; read
the ratios, which compare numbers of the same round; absolute times vary by machine and load):

* one call (one state) of pose, the full state (pose + twist + JC0 + acceleration, eqs. 1-11),
  JC0 and the inverse rates (eq. 9), beside the peer of the single call: a plain numba function
  computing the pose only (the kernel's steps, its result a new array), the kernel's ``pose``
  called directly with its output preallocated (the floor of any call from Python), the
  construction of the result record (a BucketState over one table, as ``state`` makes it; its
  fields are views made when read) and the full state with all seven fields read;
* batches of 10^3 and 10^5 states (full state and pose, M states/s);
* a root-finding baseline: every joint angle found by bisecting the angle -> length map after
  bracketing it on 240 samples, the way public excavator tools invert the cylinder linkages.

Run: python benchmarks/bench_excavator_core.py [--quick] [--rounds 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
from numba import njit

from excavator_kinematics.core import state_kernel
from excavator_kinematics.core.kinematics import BucketState, Excavator, compiled_kernel

SAMPLES = 240


@njit(cache=True, error_model="numpy")
def plain_pose(packed: np.ndarray, D: np.ndarray) -> np.ndarray:
    """The peer: a plain numba function of the pose (the kernel's steps), returning a new array."""
    Q = np.empty(4)
    state_kernel.pose(packed, D, Q)
    return Q


def per_call_us(fn: Callable[[], object], repeat: int, runs: int = 20) -> float:
    """Best of ``runs`` runs of ``repeat`` calls, in microseconds per call (short runs, many of
    them: on a loaded machine the best run is the one nobody preempted)."""
    best = float("inf")
    for _ in range(runs):
        start = time.thread_time()
        for _ in range(repeat):
            fn()
        best = min(best, (time.thread_time() - start) / repeat)
    return best * 1e6


def best_seconds(fn: Callable[[], object], rounds: int = 7) -> float:
    """Best of a few timed calls (the first also pays for warming the allocator)."""
    best = float("inf")
    for _ in range(rounds):
        start = time.thread_time()
        fn()
        best = min(best, time.thread_time() - start)
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


def one_round(exc: Excavator, scale: float, batches: dict[int, tuple[np.ndarray, ...]]) -> dict[str, float]:
    """us per single call and M states/s per batch of one round."""
    D = exc.limits.reference.copy()
    D_dot = np.array([0.3, 0.05, -0.08, 0.1])
    D_ddot = np.array([0.1, 0.02, 0.01, -0.03])
    Q_dot = exc.state(D, D_dot).Q_dot
    kernel = compiled_kernel(exc, wait=True)
    packed, out, table = exc.packed, np.empty(4), np.empty((10, 4))
    n = int(2000 * scale) or 100

    def every_field() -> tuple[np.ndarray, ...]:
        s = exc.state(D, D_dot, D_ddot)
        return s.theta, s.theta_dot, s.theta_ddot, s.Q, s.Q_dot, s.Q_ddot, s.jc0

    row = {
        "peer: plain numba pose function": per_call_us(lambda: plain_pose(packed, D), n),
        "kernel pose, output preallocated": per_call_us(lambda: kernel.pose(packed, D, out), n),
        "pose": per_call_us(lambda: exc.pose(D), n),
        "full state": per_call_us(lambda: exc.state(D, D_dot, D_ddot), n),
        "result record alone": per_call_us(lambda: BucketState(table), n),
        "full state, all 7 fields read": per_call_us(every_field, n),
        "JC0": per_call_us(lambda: exc.jc0(D), n),
        "inverse rates (eq. 9)": per_call_us(lambda: exc.cylinder_rates(D, Q_dot), n // 4),
    }
    for size, (batch, rates, accelerations) in batches.items():
        repeat = max(int(1e5 / size), 1)

        def states(
            batch: np.ndarray = batch,
            rates: np.ndarray = rates,
            accelerations: np.ndarray = accelerations,
            repeat: int = repeat,
        ) -> None:
            for _ in range(repeat):
                exc.state(batch, rates, accelerations)

        def poses(batch: np.ndarray = batch, repeat: int = repeat) -> None:
            for _ in range(repeat):
                exc.pose(batch)

        row[f"batch {size:.0e}: full state"] = size * repeat / best_seconds(states) / 1e6
        row[f"batch {size:.0e}: pose"] = size * repeat / best_seconds(poses) / 1e6
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds of every measurement")
    args = parser.parse_args()
    scale = 0.1 if args.quick else 1.0

    exc = Excavator.default()
    rng = np.random.default_rng(1)
    lo, hi = exc.limits.d_min, exc.limits.d_max
    batches = {}
    for size in (1000, 100_000):
        batch = rng.uniform(lo + 0.01 * (hi - lo), hi - 0.01 * (hi - lo), size=(size, 4))
        batches[size] = (
            batch,
            rng.uniform(-1, 1, size=(size, 4)) * exc.limits.max_rates,
            rng.uniform(-1, 1, size=(size, 4)) * exc.limits.max_rates,
        )
    rounds = [one_round(exc, scale, batches) for _ in range(args.rounds)]
    D = exc.limits.reference.copy()
    baseline = BisectionBaseline(exc)
    bisection_us = per_call_us(lambda: baseline.pose(D), max(int(50 * scale), 5))
    error = np.max(np.abs(baseline.pose(D) - exc.pose(D)))

    print(f"Excavator core benchmark ({exc.name}), {args.rounds} rounds, load {os.getloadavg()}")
    print(f"{'one call (one state)':<34}{'us/call: median':>16}{'min':>8}{'max':>8}")
    print("-" * 66)
    names = list(rounds[0])
    for name in names:
        if name.startswith("batch"):
            continue
        values = [r[name] for r in rounds]
        print(f"{name:<34}{statistics.median(values):>16.2f}{min(values):>8.2f}{max(values):>8.2f}")
    print(f"{'baseline: pose by bisection':<34}{bisection_us:>16.1f}")
    print()
    print(f"{'batch':<34}{'M states/s: median':>19}{'min':>8}{'max':>8}")
    print("-" * 69)
    for name in names:
        if not name.startswith("batch"):
            continue
        values = [r[name] for r in rounds]
        print(f"{name:<34}{statistics.median(values):>19.2f}{min(values):>8.2f}{max(values):>8.2f}")
    print()
    ratios = [r["full state"] / r["peer: plain numba pose function"] for r in rounds]
    floors = [r["full state"] / r["kernel pose, output preallocated"] for r in rounds]
    ratio = statistics.median(ratios)
    print(f"full state / plain numba pose function, per round: {', '.join(f'{v:.2f}' for v in ratios)}")
    print(f"full state / kernel pose preallocated, per round: {', '.join(f'{v:.2f}' for v in floors)}")
    batch_rate = statistics.median(r["batch 1e+05: full state"] for r in rounds)
    speedup = bisection_us / statistics.median(r["pose"] for r in rounds)
    print(f"closed form vs bisection: {speedup:.0f}x faster, max |dQ| {error:.2e}")
    targets = [
        ("full state one call <= 2x the plain numba pose (median ratio)", ratio <= 2.0),
        ("batch of 1e5 >= 1 M states/s", batch_rate >= 1.0),
        (">= 50x the bisection baseline (pose)", speedup >= 50.0),
    ]
    for name, met in targets:
        print(f"target {name:<62} {'met' if met else 'MISSED'}")


if __name__ == "__main__":
    main()
