"""Benchmark (not a test): the shared SerialChain's FK, frames and FK + Jacobian for every machine's
chain, one configuration per call and batches of 10, 10^3 and 10^5, against a baseline revision in
one run.

Columns: ``ours`` (the default path: the compiled kernel, loaded first, see
manipulator_kinematics.chain_kernel), ``numpy`` (``compiled=False``: the vectorised reference) and,
with ``--baseline REV``, the SerialChain of git revision REV (``git archive`` into a temporary
directory), built from the same rows as ours. Each side runs in a process of its own (a worker:
this script with ``--worker``, its checkout first on PYTHONPATH), started once and kept
for the whole run; the parent asks the sides for a fifth of a case's calls at a time, in turn (the
order swapped every time), so the machine's drift hits both sides of a ratio alike; the idle worker
waits on its pipe. Times are medians over rounds, ratios medians of per-round ratios with their
range (min-max). One call: median over ``--single`` random configurations; a batch of N: median of
repeated calls on one (N, n) array; batches of 10^3 and more in thread CPU time (see timed).

Run: .venv/bin/python benchmarks/bench_serial_chain.py [--rounds 5] [--baseline 47c33a1]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np
from tables import print_table

REPO = Path(__file__).resolve().parent.parent
SIZES = (1, 10, 1000, 100_000)
WHATS = ("fkine", "frames", "fkine_jacob0")
CPU_TIMED = 1000
PARTS = 5  # a case's calls come in this many parts, the sides' parts in turn


def chains() -> dict:
    """Every machine's chain as its default config builds it."""
    from palletizer_kinematics.kinematics import Palletizer
    from pump_boom_kinematics.kinematics import PumpBoom
    from scara_kinematics.kinematics import Scara
    from tool_changer_kinematics.kinematics import ToolChanger

    return {
        "tool_changer": ToolChanger.default().chain,
        "palletizer": Palletizer.default().chain,
        "scara": Scara.default().chain,
        "pump_boom": PumpBoom.default().chain,
    }


def described(chain) -> dict:
    """A chain as JSON data: its rows and transforms (what a worker builds its SerialChain from)."""
    fields = ("a", "alpha", "d", "theta", "prismatic", "offset")
    rows = [{field: np.asarray(getattr(row, field)).item() for field in fields} for row in chain.rows]
    return {
        "rows": rows,
        "modified": chain.modified,
        "base": chain.base.tolist(),
        "tool": chain.tool.tolist(),
        "coupling": chain.coupling.tolist(),
    }


def timed(function, q: np.ndarray, size: int, single: int, part: int) -> list[int]:
    """Nanoseconds of ``function``, part ``part`` of PARTS of a case: one configuration per call
    (size 1; its share of ``single`` random configurations), or a batch of ``size`` (its share of
    the repeated calls on one (size, n) array).

    Batches of CPU_TIMED rows and more count the thread's CPU time: on the shared machine a call
    of tens of milliseconds is preempted several times, and wall time would count the other
    processes' turns (FK of 10^5 took 2.3x the time per row of 10^3 at load 5). Shorter calls
    count wall time (time.thread_time_ns costs about 0.8 us itself; the median drops the rare
    preempted call)."""
    clock = time.thread_time_ns if size >= CPU_TIMED else time.perf_counter_ns
    times = []
    if size == 1:
        share = single // PARTS
        for sample in q[part * share : (part + 1) * share]:
            start = clock()
            function(sample)
            times.append(clock() - start)
    else:
        batch = q[:size]
        for _ in range(max(1, 20_000 // size // PARTS)):
            start = clock()
            function(batch)
            times.append(clock() - start)
    return times


def worker() -> None:
    """One checkout's side(s): reads the chains from stdin, answers each case number with its time.

    Line protocol (JSON): in, {"chains": ..., "single": ..., "numpy": bool (compiled=False)};
    out, the FK + Jacobian
    of the first 100 configurations per chain (the parent checks the sides agree); then per line
    in a case index and a part, out the part's times (timed).
    """
    from manipulator_kinematics import serial_chain

    setup = json.loads(sys.stdin.readline())
    loaded = getattr(serial_chain, "compiled_kernel", None)  # absent before issue #22
    if loaded is not None:
        loaded(wait=True)
    rng = np.random.default_rng(7)
    built, check = [], {}
    for name, spec in setup["chains"].items():
        chain = serial_chain.SerialChain(
            [serial_chain.DHRow(**row) for row in spec["rows"]],
            modified=spec["modified"],
            base=spec["base"],
            tool=spec["tool"],
            coupling=spec["coupling"],
        )
        q = rng.uniform(-3.0, 3.0, (SIZES[-1], chain.n))
        pose, jacobian = chain.fkine_jacob0(q[:100])
        check[name] = [pose.tolist(), jacobian.tolist()]
        built.append((chain, q))
    cases, options = [], {"compiled": False} if setup["numpy"] else {}
    for chain, q in built:
        functions = {
            "fkine": lambda q, c=chain: c.fkine(q, **options),
            "frames": lambda q, c=chain: c.fkine(q, all_frames=True, **options),
            "fkine_jacob0": lambda q, c=chain: c.fkine_jacob0(q, **options),
        }
        cases += [(functions[what], q, size) for what in WHATS for size in SIZES]
    print(json.dumps({"where": serial_chain.__file__, "check": check}), flush=True)
    for line in sys.stdin:
        case, part = map(int, line.split())
        function, q, size = cases[case]
        print(json.dumps(timed(function, q, size, setup["single"], part)), flush=True)


class Worker:
    """A worker process on the checkout ``tree``."""

    def __init__(self, tree: Path, setup: dict) -> None:
        env = dict(os.environ, PYTHONPATH=str(tree))
        self.process = subprocess.Popen(
            [sys.executable, __file__, "--worker"],
            cwd=tree,
            env=env,
            text=True,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        self.ask(json.dumps(setup))
        answer = json.loads(self.process.stdout.readline())
        where = Path(answer["where"]).resolve()
        if not where.is_relative_to(tree.resolve()):
            raise RuntimeError(f"the worker for {tree} imported {where}")
        self.check = answer["check"]

    def ask(self, line: str) -> None:
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()

    def time(self, case: int, part: int) -> list[int]:
        self.ask(f"{case} {part}")
        return json.loads(self.process.stdout.readline())

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--single", type=int, default=2000, help="one-call samples per row")
    parser.add_argument("--baseline", help="git revision to compare with (e.g. 47c33a1)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker()
        return

    sys.path.insert(0, str(REPO))
    specs = {name: described(chain) for name, chain in chains().items()}
    names = [(name, what, size) for name in specs for what in WHATS for size in SIZES]
    with tempfile.TemporaryDirectory() as directory:
        trees = {"ours": (REPO, False), "numpy": (REPO, True)}
        if args.baseline:
            archive = subprocess.run(
                ["git", "-C", str(REPO), "archive", args.baseline], capture_output=True, check=True
            ).stdout
            with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
                tar.extractall(directory, filter="data")
            trees["baseline"] = (Path(directory), False)
        workers = {
            side: Worker(tree, {"chains": specs, "single": args.single, "numpy": numpy})
            for side, (tree, numpy) in trees.items()
        }
        for side, other in workers.items():
            for name in specs:
                for theirs, ours in zip(other.check[name], workers["ours"].check[name], strict=True):
                    np.testing.assert_allclose(theirs, ours, atol=1e-12, err_msg=f"{side} {name}")
        rounds = []  # per round: per case, {side: median microseconds}
        for index in range(args.rounds):
            times = [{side: [] for side in workers} for _ in names]
            for k in range(len(names)):
                for part in range(PARTS):
                    order = list(workers) if (index + part) % 2 == 0 else list(workers)[::-1]
                    for side in order:
                        times[k][side] += workers[side].time(k, part)
            rounds.append([{side: float(np.median(t)) / 1e3 for side, t in case.items()} for case in times])
        for process in workers.values():
            process.close()

    def med(values) -> float:
        return float(np.median(list(values)))

    def shown(micro: float) -> str:
        return f"{micro:.1f} us" if micro < 1e4 else f"{micro / 1e3:.1f} ms"

    def ratio(k: int, side: str) -> str:
        values = [r[k]["ours"] / r[k][side] for r in rounds]
        return f"{med(values):.2f} ({min(values):.2f}-{max(values):.2f})"

    side_names = list(rounds[0][0])
    header = ["chain", "what", "N", *side_names, "ours / numpy"]
    if args.baseline:
        header.append(f"ours / {args.baseline} (min-max)")
    table = []
    for k, (name, what, size) in enumerate(names):
        row = [name, what, "one call (n,)" if size == 1 else str(size)]
        row += [shown(med(r[k][side] for r in rounds)) for side in side_names]
        row.append(f"{med(r[k]['ours'] / r[k]['numpy'] for r in rounds):.2f}")
        if args.baseline:
            row.append(ratio(k, "baseline"))
        table.append(row)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"\nSerialChain benchmark: {os.cpu_count()} cores (load {load}), Python {sys.version.split()[0]}, "
        f"numpy {np.__version__}; medians over {args.rounds} rounds; each side in its own process; "
        f"batches of {CPU_TIMED} and more in CPU time.\n"
    )
    print_table(header, table)


if __name__ == "__main__":
    main()
