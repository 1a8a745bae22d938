"""Benchmark (not a test): the longest pump boom plan the planner accepts, and what it costs.

The bounds of ``pump_boom_kinematics.pour`` (MAX_WAYPOINTS, MAX_POINTS) make the largest plans:

* ``1000 waypoints``: a zig-zag of MAX_WAYPOINTS waypoints over the boom's front (x 16-28 m,
  y -6..6 m, z 12.5 m) at the step that gives about MAX_POINTS - 2000 points (the worst case:
  one region IK call and one straight line per segment);
* ``2 waypoints``: the paper's slanted line (28.8 m) at the step that gives MAX_POINTS points.

Per round: the plan (region IK of every point, bisection, time scaling) and the JointTrajectory
message the PlanPath service sends (positions, velocities, accelerations per point), in seconds;
median and worst of the rounds. The server runs plan_path in a callback group of its own, so
solve_ik is answered meanwhile (test_pump_boom_ros checks it across processes).

Run: .venv/bin/python benchmarks/bench_pump_boom_plan.py [--rounds 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np
from tables import print_table

from manipulator_kinematics.nodes.messages import joint_trajectory
from pump_boom_kinematics.kinematics import PumpBoom
from pump_boom_kinematics.pour import MAX_POINTS, MAX_WAYPOINTS, TYPICAL_POURS, plan_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    boom = PumpBoom.default()
    zigzag = np.array(
        [[16.0 + 12.0 * (k % 2), -6.0 + 12.0 * k / (MAX_WAYPOINTS - 1), 12.5] for k in range(MAX_WAYPOINTS)]
    )
    line = np.array(TYPICAL_POURS["slanted_line"][1:])
    cases = {
        f"{MAX_WAYPOINTS} waypoints": (zigzag, MAX_POINTS - 2000),
        "2 waypoints": (line, MAX_POINTS - 1),
    }
    rows = []
    for name, (waypoints, steps) in cases.items():
        step = float(np.sum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))) / steps
        plans, messages = [], []
        for _ in range(args.rounds):
            start = time.perf_counter()
            plan = plan_path(boom, waypoints, step=step)
            middle = time.perf_counter()
            joint_trajectory("base_link", boom.joint_names, plan.timing.trajectory)
            plans.append(middle - start)
            messages.append(time.perf_counter() - middle)
        assert plan.ok and not plan.truncated, plan.message
        total = [a + b for a, b in zip(plans, messages, strict=True)]
        rows.append(
            (
                name,
                str(len(plan.q)),
                f"{step:.4g}",
                *(f"{statistics.median(x):.3f} / {max(x):.3f}" for x in (plans, messages, total)),
                f"{plan.t[-1]:.0f}",
            )
        )
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"\nLargest pump boom plans: {os.cpu_count()} cores (load average {load}), Python "
        f"{sys.version.split()[0]}, numpy {np.__version__}; {args.rounds} rounds, median / worst in s.\n"
    )
    header = ("plan", "points", "step (m)", "plan (s)", "message (s)", "total (s)", "trajectory (s)")
    print_table(header, rows)


if __name__ == "__main__":
    main()
