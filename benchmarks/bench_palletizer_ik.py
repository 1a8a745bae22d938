"""Benchmark (not a test): palletizer closed-form IK against scipy's least squares on the same model.

Prints one table per round and a summary: microseconds per IK with the library (one target per
call; and per target in one batched call of --batch targets) against ``scipy.optimize.least_squares``
(trust-region reflective, bounded by the axis limits, residual = TCP position error and the flange
yaw error, seeded at the home pose) on the same chain (``Palletizer.fkine``). Both run in this
process, one after the other, in every round; the ratio is taken per round. Target: >= 50x per call.

Run: .venv/bin/python benchmarks/bench_palletizer_ik.py [--calls 300] [--batch 100000] [--rounds 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy.optimize import least_squares

from manipulator_kinematics.planar import wrap_angle
from palletizer_kinematics.kinematics import Palletizer


def numerical_ik(model: Palletizer, target: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Axis angles reaching ``target`` (4, 4) by bounded least squares on position and yaw."""
    p, yaw = target[:3, 3], np.arctan2(target[1, 0], target[0, 0])

    def residual(q: np.ndarray) -> np.ndarray:
        pose = model.fkine(q)
        return np.append(pose[:3, 3] - p, wrap_angle(np.arctan2(pose[1, 0], pose[0, 0]) - yaw))

    return least_squares(
        residual, seed, bounds=(model.limits.lower, model.limits.upper), xtol=1e-12, ftol=1e-12, gtol=1e-12
    ).x


def one_round(model: Palletizer, calls: int, batch: int, rng: np.random.Generator) -> dict[str, float]:
    q = rng.uniform(model.limits.lower, model.limits.upper, size=(calls, 4))
    q[:, 3] = wrap_angle(q[:, 3])  # the inner flange turn: the one a home-seeded solver converges to
    targets = model.fkine(q)
    closed, errors = [], []
    for target in targets:
        start = time.perf_counter_ns()
        solution = model.solve_ik(target).solution
        closed.append((time.perf_counter_ns() - start) / 1e3)
        errors.append(
            np.abs(model.fkine(solution) - target).max() if np.all(np.isfinite(solution)) else np.nan
        )
    numeric, numeric_errors = [], []
    for target in targets:
        start = time.perf_counter_ns()
        solution = numerical_ik(model, target, np.zeros(4))
        numeric.append((time.perf_counter_ns() - start) / 1e3)
        numeric_errors.append(np.abs(model.fkine(solution)[:3, 3] - target[:3, 3]).max())
    many = model.fkine(rng.uniform(model.limits.lower, model.limits.upper, size=(batch, 4)))
    start = time.perf_counter()
    result = model.solve_ik(many)
    batch_us = (time.perf_counter() - start) / batch * 1e6
    numeric_errors = np.array(numeric_errors)
    return {
        "closed_us": statistics.median(closed),
        "numeric_us": statistics.median(numeric),
        "batch_us": batch_us,
        "closed_error": float(np.nanmax(errors)),
        "closed_ok": float(np.mean(np.isfinite(errors))),
        "batch_ok": float(np.mean(result.ok)),
        "numeric_converged": float(np.mean(numeric_errors < 1e-6)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--calls", type=int, default=300)
    parser.add_argument("--batch", type=int, default=100_000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    model = Palletizer.default()
    rng = np.random.default_rng(460)
    model.solve_ik(model.fkine(np.zeros(4)))  # warm-up (cached chain)
    print(f"{args.calls} targets per call series, batch of {args.batch}, variant {model.variant}")
    print(
        "round  closed us/call  least_squares us/call  ratio  batch us/target  batch ratio  "
        "closed max err  ls converged"
    )
    ratios = []
    for k in range(args.rounds):
        r = one_round(model, args.calls, args.batch, rng)
        ratio = r["numeric_us"] / r["closed_us"]
        ratios.append(ratio)
        print(
            f"{k + 1:5d}  {r['closed_us']:14.1f}  {r['numeric_us']:21.1f}  {ratio:5.0f}x  "
            f"{r['batch_us']:15.3f}  {r['numeric_us'] / r['batch_us']:10.0f}x  "
            f"{r['closed_error']:14.1e}  {r['numeric_converged']:12.1%}"
        )
    print(
        f"per-call speed-up over the rounds: {min(ratios):.0f}-{max(ratios):.0f}x (target >= 50x: "
        f"met in {sum(r >= 50 for r in ratios)} of {len(ratios)} rounds)"
    )


if __name__ == "__main__":
    main()
