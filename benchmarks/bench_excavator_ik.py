"""Benchmark (not a test): the excavator's closed-form pose IK against scipy's least squares on the
same model.

Per round, one after the other in this process: microseconds per call of ``Excavator.ik`` with one
target Q = [x, y, z, alpha] (every candidate judged, the rule applied) through the compiled kernel
(``ik_kernel``) and through the numpy reference path (``compiled=False``), of ``Excavator.solve_ik``
with one 6-D pose (the IK server's call), of ``Excavator.position_ik`` with one position (the
stroke-margin search, kernel), and of ``scipy.optimize.least_squares`` (trust-region reflective,
bounded by the stroke box and the swing range, residual = pose(D) - Q, seeded at the reference
state) on the same targets; batch throughput (targets per second) of one ``ik`` call on --batch
targets and of one ``position_ik`` call on --batch / 100 positions. Ratios per round. Targets: one
call <= 20 us, batch >= 1 M targets/s, position only <= 10 x the pose IK and faster than least
squares. Before the rounds, in fresh processes: the kernel's compile time with an empty numba
cache and its load time from the cache (a new process's single calls take the numpy path until then).

Run: .venv/bin/python benchmarks/bench_excavator_ik.py [--calls 300] [--batch 100000] [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.optimize import least_squares

from excavator_kinematics.core.inverse import compiled_kernel, solve_pose
from excavator_kinematics.core.kinematics import Excavator
from manipulator_kinematics.planar import wrap_angle

_FIRST_CALL = """
import time
start = time.perf_counter()
from excavator_kinematics.core.inverse import compiled_kernel
from excavator_kinematics.core.kinematics import Excavator
model = Excavator.default()
ready = time.perf_counter()
compiled_kernel(model, wait=True)
print(ready - start, time.perf_counter() - ready)
"""


def first_calls() -> tuple[float, float, float]:
    """(import + machine s, kernel ready with an empty cache s, the same from the cache s)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        runs = [
            subprocess.run(
                [sys.executable, "-c", _FIRST_CALL], env=env, check=True, capture_output=True, text=True
            ).stdout.split()
            for _ in range(2)
        ]
    return float(runs[1][0]), float(runs[0][1]), float(runs[1][1])


def numerical_ik(model: Excavator, Q: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """D reaching Q by bounded least squares on eq. 3 (alpha wrapped)."""
    limits = model.joint_limits

    def residual(D: np.ndarray) -> np.ndarray:
        error = model.pose(D) - Q
        error[3] = wrap_angle(error[3])
        return error

    return least_squares(
        residual, seed, bounds=(limits.lower, limits.upper), xtol=1e-12, ftol=1e-12, gtol=1e-12
    ).x


def timed(call, items) -> tuple[list[float], list]:
    times, results = [], []
    for item in items:
        start = time.perf_counter_ns()
        results.append(call(item))
        times.append((time.perf_counter_ns() - start) / 1e3)
    return times, results


def one_round(model: Excavator, calls: int, batch: int, rng: np.random.Generator) -> dict[str, float]:
    limits = model.joint_limits
    D = rng.uniform(limits.lower, limits.upper, (calls, 4))
    Q, poses = model.pose(D), model.fkine(D)
    many = model.pose(rng.uniform(limits.lower, limits.upper, (batch, 4)))
    start = time.perf_counter()
    result = model.ik(many)
    batch_seconds = time.perf_counter() - start
    kernel, results = timed(model.ik, Q)
    errors = [np.abs(r.solution - d).max() for r, d in zip(results, D, strict=True)]
    reference, _ = timed(lambda q: solve_pose(model, q, compiled=False), Q)
    six_d, _ = timed(model.solve_ik, poses)
    position, _ = timed(model.position_ik, Q[: max(calls // 3, 1), :3])
    positions = many[: max(batch // 100, 1), :3]
    start = time.perf_counter()
    model.position_ik(positions)
    position_seconds = time.perf_counter() - start
    numeric, solutions = timed(lambda q: numerical_ik(model, q, model.limits.reference), Q)
    numeric_errors = np.array(
        [np.abs(model.pose(s) - q)[:3].max() for s, q in zip(solutions, Q, strict=True)]
    )
    return {
        "kernel_us": statistics.median(kernel),
        "numpy_us": statistics.median(reference),
        "six_d_us": statistics.median(six_d),
        "position_us": statistics.median(position),
        "numeric_us": statistics.median(numeric),
        "batch_rate": batch / batch_seconds,
        "position_rate": len(positions) / position_seconds,
        "closed_error": float(max(errors)),
        "batch_ok": float(np.mean(result.ok)),
        "numeric_converged": float(np.mean(numeric_errors < 1e-6)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--calls", type=int, default=300)
    parser.add_argument("--batch", type=int, default=100_000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    ready, cold, warm = first_calls()
    print(
        f"fresh process: import + machine {ready:.2f} s; kernel ready (a background thread; single "
        f"calls take the numpy path meanwhile): {cold:.2f} s with an empty numba cache (compile), "
        f"{warm:.3f} s from the cache"
    )
    model = Excavator.default()
    compiled_kernel(model, wait=True)
    rng = np.random.default_rng(200)
    model.ik(model.pose(model.limits.reference))  # warm-up
    model.position_ik([5.0, 0.0, 0.0])
    print(
        f"{args.calls} targets per call series, batch of {args.batch}, machine {model.name}; us per call "
        "(medians), ratio = least squares / ours"
    )
    print(
        "round  kernel us  numpy us  6-D us  position us  least_sq us  ratio  position ratio  "
        "batch targets/s  batch ratio  position/s  max |D error|  ls converged"
    )
    rows = []
    for k in range(args.rounds):
        r = one_round(model, args.calls, args.batch, rng)
        rows.append(r)
        print(
            f"{k + 1:5d}  {r['kernel_us']:9.1f}  {r['numpy_us']:8.0f}  {r['six_d_us']:6.0f}  "
            f"{r['position_us']:11.0f}  {r['numeric_us']:11.0f}  {r['numeric_us'] / r['kernel_us']:4.0f}x  "
            f"{r['numeric_us'] / r['position_us']:13.1f}x  {r['batch_rate']:15.3g}  "
            f"{r['numeric_us'] * 1e-6 * r['batch_rate']:10.0f}x  {r['position_rate']:10.3g}  "
            f"{r['closed_error']:13.1e}  {r['numeric_converged']:12.1%}"
        )
    best_call = min(r["kernel_us"] for r in rows)
    best_rate = max(r["batch_rate"] for r in rows)
    best_position = min(r["position_us"] / r["kernel_us"] for r in rows)
    print(
        f"one call: best {best_call:.1f} us (target <= 20 us: {'met' if best_call <= 20 else 'MISSED'}); "
        f"batch: best {best_rate:.3g} targets/s (>= 1e6: {'met' if best_rate >= 1e6 else 'MISSED'}); "
        f"position only: best {best_position:.1f} x the pose IK (target <= 10x: "
        f"{'met' if best_position <= 10 else 'MISSED'})"
    )


if __name__ == "__main__":
    main()
