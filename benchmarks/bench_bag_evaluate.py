"""Benchmark: `mk_evaluate` on a 1 hour, 100 Hz excavator bag (about 1.5 million messages).

    python benchmarks/bench_bag_evaluate.py [--hours 1.0] [--storage mcap|sqlite3] [--keep DIR]

The bag is synthesised with the bag writer from core-library numbers (excavator_kinematics
.synthetic): cylinder_lengths, joint_states, bucket_pose and bucket_twist at 100 Hz and
target_bucket_twist at 20 Hz. Then the `mk_evaluate` command runs on it as a separate process
(wall time, imports included), and its phases are timed in-process. Prints a table. The goal is
under 60 s for the whole command.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.bag.evaluate import evaluate_bag, render, write_plots
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.synthetic import write_bag

RATE_HZ = 100.0
TARGET_EVERY = 5  # 20 Hz commands
GOAL_S = 60.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    parser.add_argument("--keep", type=Path, help="write the bag and report here and keep them")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or Path(tmp)
        bag_path, out = where / "bench_evaluate_bag", where / "bench_evaluate_report"
        samples = int(args.hours * 3600 * RATE_HZ)

        start = time.perf_counter()
        topics = excavator_bag(
            Excavator.default(),
            samples,
            RATE_HZ,
            outputs=("bucket_pose", "bucket_twist"),
            target_every=TARGET_EVERY,
        )
        rows.append(("synthesise messages (core + CDR encode)", time.perf_counter() - start))
        start = time.perf_counter()
        count = write_bag(bag_path, topics, args.storage, overwrite=True)
        rows.append((f"write bag ({args.storage}, BagWriter)", time.perf_counter() - start))
        del topics
        size = sum(f.stat().st_size for f in bag_path.iterdir()) / 1e6

        start = time.perf_counter()
        result = subprocess.run(
            [sys.executable, "-m", "manipulator_kinematics.bag.evaluate", str(bag_path), "-o", str(out)],
            capture_output=True,
            text=True,
        )
        total = time.perf_counter() - start
        if result.returncode:
            print(result.stdout, result.stderr, file=sys.stderr)
            return 1
        rows.append(("mk_evaluate command, total", total))

        start = time.perf_counter()
        bag = BagReader(bag_path)
        rows.append(("  open + index", time.perf_counter() - start))
        start = time.perf_counter()
        bag.arrays()
        rows.append(("  decode all topics", time.perf_counter() - start))
        start = time.perf_counter()
        report, plots = evaluate_bag(bag)
        rows.append(("  evaluate_bag (decode + analysis)", time.perf_counter() - start))
        start = time.perf_counter()
        render(report)
        write_plots(plots, out)
        rows.append(("  table + plots", time.perf_counter() - start))

    hours = samples / RATE_HZ / 3600
    print(f"\nbag: {count} messages, {hours:g} h at {RATE_HZ:g} Hz, {size:.0f} MB {args.storage}\n")
    width = max(len(name) for name, _ in rows)
    print(f"{'step':<{width}}  seconds")
    print(f"{'-' * width}  -------")
    for name, seconds in rows:
        print(f"{name:<{width}}  {seconds:7.2f}")
    verdict = "meets" if total < GOAL_S else "MISSES"
    print(f"\nevaluate: {count / total / 1e3:.0f} k messages/s; {verdict} the {GOAL_S:g} s goal")
    return 0 if total < GOAL_S else 1


if __name__ == "__main__":
    raise SystemExit(main())
