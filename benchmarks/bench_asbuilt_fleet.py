"""mk_asbuilt --fleet on Dask against the single-bag step and against Ray, in the same run; and
the bag readers.

    python benchmarks/bench_asbuilt_fleet.py [--bags 20] [--minutes 10] [--rate 100]
        [--workers 1 2 4] [--rounds 2] [--data DIR] [--no-ray]

Writes one synthetic excavator bag (the golden-bag motion, ``--minutes`` at ``--rate`` Hz) and
copies it to ``--bags`` folders (in a temporary folder removed at the end, or kept in ``--data``
and reused while the size matches). First times the ways to read one bag's messages: the
``BagReader`` (the whole bag indexed in memory; on a copy cut short, ``recover=True``: the
``mcap`` StreamReader scan), the ``mcap`` library's ``make_reader().iter_messages()`` in
record-time order and in file order, and rosbags' ``Reader.messages()`` (``BagStream``'s path).
Then per round: every bag through the single-bag step (``process_bag``, in this process, one
after another), ``run_fleet`` (Dask's local process scheduler) with each worker count, and the
same tasks as Ray remote functions on a local Ray instance of that many CPUs (when ``ray`` is
importable; it is no dependency of the package: ``pip install --target DIR ray`` and put DIR on
PYTHONPATH to measure it). Prints wall seconds, seconds per bag, the speed-up over one worker and
the CPU seconds per bag (user + system of this process and of the worker processes, which Dask's
pool has ended and the OS has reaped by then; Ray's workers are the raylet's children, so no CPU
figure for Ray, and its start-up is shown apart): on a machine shared with other jobs the wall
time says how many cores were free, the CPU time what each bag cost. The issue's benchmark is the
default (20 bags of 10 min at 100 Hz).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.bag.asbuilt import process_bag, run_fleet
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.synthetic import write_bag


def make_bags(folder: Path, count: int, samples: int, rate: float) -> list[Path]:
    marker = folder / f"{count}x{samples}@{rate:g}"
    paths = [folder / f"bag{i:03d}" for i in range(count)]
    if not marker.exists():
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        write_bag(paths[0], excavator_bag(Excavator.default(), samples, rate))
        for path in paths[1:]:
            shutil.copytree(paths[0], path)
        marker.touch()
    return paths


def readers(bag: Path) -> None:
    """Seconds to read every message of one bag, by each way."""
    (file,) = bag.glob("*.mcap")
    cut = bag.parent / "cut_short.mcap"  # what a killed recorder leaves: no summary, no footer
    cut.write_bytes(file.read_bytes()[: file.stat().st_size // 2])

    def mcap(order: bool) -> int:
        with file.open("rb") as stream:
            return sum(1 for _ in make_reader(stream).iter_messages(log_time_order=order))

    def ours(path: Path, recover: bool) -> int:
        return BagReader(path, recover=recover).message_count

    def rosbags() -> int:
        with Reader(file) as reader:
            return sum(1 for _ in reader.messages())

    ways = {
        "BagReader, indexed (mk_evaluate)": lambda: ours(bag, False),
        "BagReader(recover=True), first half (StreamReader scan, CRCs)": lambda: ours(cut, True),
        "mcap make_reader().iter_messages(), record-time order": lambda: mcap(True),
        "mcap make_reader().iter_messages(), file order": lambda: mcap(False),
        "rosbags Reader.messages(), record-time order (BagReader, BagStream)": rosbags,
    }
    print("| reading one bag's messages | s | messages |")
    print("| --- | ---: | ---: |")
    for name, way in ways.items():
        t = time.perf_counter()
        count = way()
        print(f"| {name} | {time.perf_counter() - t:.1f} | {count} |", flush=True)


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and its ended children so far."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bags", type=int, default=20)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--data", type=Path, default=None, help="keep the bags here (default: a temp folder)")
    parser.add_argument("--no-ray", action="store_true", help="Dask only, even where ray is importable")
    args = parser.parse_args()
    ray = None if args.no_ray else ray_module()
    samples = int(args.minutes * 60 * args.rate)
    with tempfile.TemporaryDirectory(prefix="bench_fleet_") as temporary:
        data = args.data or Path(temporary)
        t = time.perf_counter()
        paths = make_bags(data / "bags", args.bags, samples, args.rate)
        print(
            f"{args.bags} bags of {args.minutes:g} min at {args.rate:g} Hz ({samples} samples a topic, "
            f"6 topics), ready in {time.perf_counter() - t:.1f} s; {os.cpu_count()} cores, "
            f"load {os.getloadavg()[0]:.1f}",
            flush=True,
        )
        readers(paths[0])
        print(
            "\nDask local process scheduler (dask.compute(scheduler='processes', num_workers=N)); "
            + ("Ray: ray.init(num_cpus=N), one remote process_bag per bag" if ray else "Ray not importable")
            + "; wall time"
        )
        print("| round | what | wall s | s per bag | speed-up vs 1 worker | CPU s per bag | load |")
        print("| ---: | --- | ---: | ---: | ---: | ---: | ---: |")
        for r in range(1, args.rounds + 1):
            out = data / "out"
            shutil.rmtree(out, ignore_errors=True)
            t, cpu = time.perf_counter(), cpu_seconds()
            for path in paths:
                assert process_bag(path, out, [], 0.25).error is None
            single, cpu = time.perf_counter() - t, cpu_seconds() - cpu
            print(
                f"| {r} | single-bag step, one after another | {single:.1f} | {single / len(paths):.2f} | - "
                f"| {cpu / len(paths):.2f} | {os.getloadavg()[0]:.1f} |",
                flush=True,
            )
            base = None
            for n in args.workers:
                shutil.rmtree(out, ignore_errors=True)
                t, cpu = time.perf_counter(), cpu_seconds()
                results = run_fleet(paths, out, [], 0.25, workers=n)
                wall, cpu = time.perf_counter() - t, cpu_seconds() - cpu
                assert not any(x.error for x in results)
                base = wall if base is None else base
                row(r, f"fleet, {n} worker{'s' if n > 1 else ''}", wall, len(paths), base, cpu)
            if ray is not None:
                ray_rounds(ray, paths, out, args.workers, r)
    return 0


def ray_module() -> Any:
    """``ray`` if importable, else None (it is not a dependency of the package)."""
    try:
        import ray
    except ImportError:
        return None
    return ray


def ray_rounds(ray: Any, paths: list[Path], out: Path, workers: list[int], r: int) -> None:
    """The fleet's tasks on a local Ray instance of each size: wall time after ``ray.init`` (its
    start-up in the row's text), the speed-up over its own one-CPU run."""
    task = ray.remote(process_bag)
    base = None
    for n in workers:
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        ray.init(num_cpus=n, include_dashboard=False, log_to_driver=False, configure_logging=False)
        start = time.perf_counter() - t
        try:
            t = time.perf_counter()
            results = ray.get([task.remote(p, out, (), 0.25) for p in paths])
            wall = time.perf_counter() - t
        finally:
            ray.shutdown()
        assert not any(x.error for x in results)
        base = wall if base is None else base
        row(r, f"Ray, {n} CPU{'s' if n > 1 else ''} (+{start:.1f} s ray.init)", wall, len(paths), base, None)


def row(r: int, what: str, wall: float, bags: int, base: float, cpu: float | None) -> None:
    """One engine's row: wall s, per bag, speed-up over its one-worker run, CPU s per bag (None:
    not measurable), load."""
    per_bag = "-" if cpu is None else f"{cpu / bags:.2f}"
    print(
        f"| {r} | {what} | {wall:.1f} | {wall / bags:.2f} | {base / wall:.2f} | {per_bag} "
        f"| {os.getloadavg()[0]:.1f} |",
        flush=True,
    )


if __name__ == "__main__":
    raise SystemExit(main())
