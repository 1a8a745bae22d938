"""Benchmark (not a test): the excavator's closed-form pose IK against scipy's least squares on the
same model.

Per round: microseconds per call of ``Excavator.ik`` with one target Q = [x, y, z, alpha] (every
candidate judged, the rule applied), of ``Excavator.solve_ik`` with one 6-D pose (the IK server's
call), of ``Excavator.position_ik`` with one position (the stroke-margin search), and of
``scipy.optimize.least_squares`` (trust-region reflective, bounded by the stroke box and the swing
range, residual = pose(D) - Q, seeded at the reference state) on the same targets; batch
throughput (targets per second) of one ``ik`` call on --batch targets. Both run in this process,
one after the other, in every round; ratios per round. Targets: one call <= 20 us, batch >= 1 M
targets/s.

Run: .venv/bin/python benchmarks/bench_excavator_ik.py [--calls 300] [--batch 100000] [--rounds 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy.optimize import least_squares

from excavator_kinematics.kinematics import Excavator
from manipulator_kinematics.planar import wrap_angle


def numerical_ik(model: Excavator, Q: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """D reaching Q by bounded least squares on eq. 3 (alpha wrapped)."""
    limits = model.joint_limits

    def residual(D: np.ndarray) -> np.ndarray:
        error = model.pose(D) - Q
        error[3] = wrap_angle(error[3])
        return error

    return least_squares(residual, seed, bounds=(limits.lower, limits.upper), xtol=1e-12, ftol=1e-12,
                         gtol=1e-12).x


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
    closed, results = timed(model.ik, Q)
    errors = [np.abs(r.solution - d).max() for r, d in zip(results, D, strict=True)]
    six_d, _ = timed(model.solve_ik, poses)
    position, _ = timed(model.position_ik, Q[: max(calls // 10, 1), :3])
    numeric, solutions = timed(lambda q: numerical_ik(model, q, model.limits.reference), Q)
    numeric_errors = np.array([np.abs(model.pose(s) - q)[:3].max()
                               for s, q in zip(solutions, Q, strict=True)])
    many = model.pose(rng.uniform(limits.lower, limits.upper, (batch, 4)))
    start = time.perf_counter()
    result = model.ik(many)
    seconds = time.perf_counter() - start
    return {
        "closed_us": statistics.median(closed),
        "six_d_us": statistics.median(six_d),
        "position_us": statistics.median(position),
        "numeric_us": statistics.median(numeric),
        "batch_rate": batch / seconds,
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
    model = Excavator.default()
    rng = np.random.default_rng(200)
    model.ik(model.pose(model.limits.reference))  # warm-up
    print(f"{args.calls} targets per call series, batch of {args.batch}, machine {model.name}")
    print("round  ik us/call  solve_ik 6-D us  position us  least_squares us  ratio  batch targets/s  "
          "batch ratio  max |D error|  ls converged")
    rows = []
    for k in range(args.rounds):
        r = one_round(model, args.calls, args.batch, rng)
        rows.append(r)
        print(f"{k + 1:5d}  {r['closed_us']:10.1f}  {r['six_d_us']:15.1f}  {r['position_us']:11.0f}  "
              f"{r['numeric_us']:16.0f}  {r['numeric_us'] / r['closed_us']:4.0f}x  {r['batch_rate']:15.3g}  "
              f"{r['numeric_us'] * 1e-6 * r['batch_rate']:10.0f}x  {r['closed_error']:13.1e}  "
              f"{r['numeric_converged']:12.1%}")
    best_call = min(r["closed_us"] for r in rows)
    best_rate = max(r["batch_rate"] for r in rows)
    print(f"one call: best {best_call:.1f} us (target <= 20 us: {'met' if best_call <= 20 else 'MISSED'}); "
          f"batch: best {best_rate:.3g} targets/s (target >= 1e6: {'met' if best_rate >= 1e6 else 'MISSED'})")


if __name__ == "__main__":
    main()
