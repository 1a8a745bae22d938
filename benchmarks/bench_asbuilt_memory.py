"""Peak memory of mk_asbuilt's single-bag step on a long bag: read in windows against read whole.

    python benchmarks/bench_asbuilt_memory.py [--minutes 60] [--rate 100] [--chunks 0 60 10]
        [--data out/bench_memory]

Writes one synthetic excavator bag (the golden-bag motion, ``--minutes`` at ``--rate`` Hz: six
topics, 360,000 samples each for the default hour; kept in ``--data`` and reused while its size
matches), then runs ``process_bag`` on it in a fresh process per setting of ``--chunk-seconds``
(0: the whole bag at once) and prints that process's peak resident set size (``VmHWM`` of
``/proc/self/status``: Linux), its wall time and the rows written. The first line is the same step on a bag of
1 s: the floor every setting pays (Python, numpy, pyarrow, matplotlib, the machine model). The
children run with ``MK_COMPILED=0``: the excavator's compiled kernel, which loads numba in the
background for batches of at most 2048 states (about 80 MB), would otherwise come with some
settings and not others.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path


def child(chunk: float | None, bag: Path, out: Path) -> None:
    """In a fresh process: the step; prints the peak RSS, wall time and rows."""
    t = time.perf_counter()
    from manipulator_kinematics.bag.asbuilt import process_bag

    result = process_bag(bag, out, [], 0.25, chunk_seconds=chunk)
    assert result.error is None, result.error
    rows = sum(table["rows"] for table in result.tables)
    # VmHWM, not getrusage's ru_maxrss: that keeps the high-water mark of the parent the child was
    # forked from (the one that wrote the bag) across exec.
    status = Path("/proc/self/status").read_text()
    peak = int(next(line.split()[1] for line in status.splitlines() if line.startswith("VmHWM:"))) / 1024
    print(f"{peak:.0f} {time.perf_counter() - t:.1f} {rows}")


def make_bag(folder: Path, samples: int, rate: float) -> tuple[Path, Path]:
    """The long bag and a bag of 1 s, both along the same motion."""
    from excavator_kinematics.core.kinematics import Excavator
    from excavator_kinematics.tools.synthetic import excavator_bag
    from manipulator_kinematics.bag.synthetic import write_bag

    marker, path, short = folder / f"{samples}@{rate:g}", folder / "bag", folder / "bag_1s"
    if not marker.exists():
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        write_bag(path, excavator_bag(Excavator.default(), samples, rate))
        write_bag(short, excavator_bag(Excavator.default(), round(rate), rate))
        marker.touch()
    return path, short


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--chunks", type=float, nargs="+", default=[0.0, 60.0, 10.0], help="0: whole")
    parser.add_argument("--data", type=Path, default=Path("out/bench_memory"))
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        chunk = float(args.child[0])
        child(None if chunk == 0 else chunk, Path(args.child[1]), Path(args.child[2]))
        return 0
    samples = int(args.minutes * 60 * args.rate)
    t = time.perf_counter()
    bag, short = make_bag(args.data, samples, args.rate)
    size = sum(f.stat().st_size for f in bag.iterdir()) / 2**20
    print(
        f"one bag of {args.minutes:g} min at {args.rate:g} Hz ({samples} samples a topic, {size:.0f} MiB), "
        f"ready in {time.perf_counter() - t:.0f} s; {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
    )
    print("| --chunk-seconds | peak RSS MiB | wall s | rows |")
    print("| --- | ---: | ---: | ---: |")
    for name, chunk, path in [
        ("60 on a bag of 1 s (the floor)", 60.0, short),
        *((f"{c:g}" if c else "0 (whole bag)", c, bag) for c in args.chunks),
    ]:
        out = args.data / "out"
        shutil.rmtree(out, ignore_errors=True)
        run = [sys.executable, __file__, "--child", str(chunk), str(path), str(out)]
        env = {**os.environ, "MK_COMPILED": "0"}
        peak, wall, rows = subprocess.run(
            run, check=True, capture_output=True, text=True, env=env
        ).stdout.split()
        print(f"| {name} | {peak} | {wall} | {rows} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
