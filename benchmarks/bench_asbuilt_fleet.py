"""mk_asbuilt --fleet on Dask against the single-bag step, in the same run.

    python benchmarks/bench_asbuilt_fleet.py [--bags 20] [--minutes 10] [--rate 100]
        [--workers 1 2 4] [--rounds 1] [--data out/bench_fleet]

Writes ``--bags`` synthetic excavator bags (the golden-bag motion, ``--minutes`` at ``--rate`` Hz;
kept in ``--data`` and reused while their size matches), then per round: every bag through the
single-bag step (``process_bag``, in this process, one after another), and ``run_fleet`` (Dask's
local process scheduler) with each worker count. Prints wall seconds, seconds per bag and the
speed-up over one worker; the issue's benchmark is the default (20 bags of 10 min at 100 Hz).
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from pathlib import Path

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.bag.asbuilt import process_bag, run_fleet
from manipulator_kinematics.bag.synthetic import write_bag


def make_bags(folder: Path, count: int, samples: int, rate: float) -> list[Path]:
    marker = folder / f"{count}x{samples}@{rate:g}"
    paths = [folder / f"bag{i:03d}" for i in range(count)]
    if not marker.exists():
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        topics = excavator_bag(Excavator.default(), samples, rate)
        for path in paths:
            write_bag(path, topics)
        marker.touch()
    return paths


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bags", type=int, default=20)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--data", type=Path, default=Path("out/bench_fleet"))
    args = parser.parse_args()
    samples = int(args.minutes * 60 * args.rate)
    t = time.perf_counter()
    paths = make_bags(args.data / "bags", args.bags, samples, args.rate)
    print(
        f"{args.bags} bags of {args.minutes:g} min at {args.rate:g} Hz ({samples} samples each), "
        f"ready in {time.perf_counter() - t:.1f} s; {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
    )
    print("Dask local process scheduler (dask.compute(scheduler='processes', num_workers=N)); wall time")
    print("| round | what | wall s | s per bag | speed-up vs 1 worker |")
    print("| ---: | --- | ---: | ---: | ---: |")
    for r in range(1, args.rounds + 1):
        out = args.data / "out"
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        for path in paths:
            process_bag(path, out, [], 0.25)
        single = time.perf_counter() - t
        print(f"| {r} | single-bag step, one after another | {single:.1f} | {single / len(paths):.2f} | - |")
        base = None
        for n in args.workers:
            shutil.rmtree(out, ignore_errors=True)
            t = time.perf_counter()
            results = run_fleet(paths, out, [], 0.25, workers=n)
            wall = time.perf_counter() - t
            assert not any(x.error for x in results)
            base = wall if base is None else base
            print(
                f"| {r} | fleet, {n} worker{'s' if n > 1 else ''} | {wall:.1f} | {wall / len(paths):.2f} "
                f"| {base / wall:.2f} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
