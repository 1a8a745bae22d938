"""Benchmark (not a test): the shared SerialChain's FK and FK + Jacobian for every machine's chain,
one configuration per call and batches of 10, 10^3 and 10^5, against a baseline revision in one run.

Columns: ``ours`` (the default path: the compiled kernel for one call once it is loaded, see
manipulator_kinematics.chain_kernel), ``numpy`` (the same checkout with ``MK_COMPILED=0``: the
vectorised reference) and, with ``--baseline REV``, the chain of git revision REV (exported with
``git archive`` into a temporary directory). Each side runs in its own process, round by round in
turn, so machine drift hits all alike; times are medians over rounds, ratios medians of per-round
ratios. One call: median over ``--single`` random configurations; a batch of N: median of repeated
calls on one (N, n) array.

Run: .venv/bin/python benchmarks/bench_serial_chain.py [--rounds 3] [--baseline main]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tables import print_table

REPO = Path(__file__).resolve().parent.parent
SIZES = (1, 10, 1000, 100_000)
MACHINES = ("tool_changer", "palletizer", "scara", "pump_boom")


def chains() -> dict:
    """Every machine's chain as its default config builds it."""
    from palletizer_kinematics.kinematics import Palletizer
    from pump_boom_kinematics.kinematics import PumpBoom
    from scara_kinematics.kinematics import Scara
    from tool_changer_kinematics.kinematics import ToolChanger

    return {"tool_changer": ToolChanger.default().chain, "palletizer": Palletizer.default().chain,
            "scara": Scara.default().chain, "pump_boom": PumpBoom.default().chain}


def worker(single: int) -> None:
    """Times of every chain, operation and size in this process, as JSON on stdout."""
    import numpy as np

    from manipulator_kinematics import serial_chain

    out = {}
    rng = np.random.default_rng(7)
    for name, chain in chains().items():
        q = rng.uniform(-3.0, 3.0, (SIZES[-1], chain.n))
        loaded = getattr(serial_chain, "compiled_kernel", None)
        if loaded is not None:
            loaded(wait=True)
        for label, function in (("fk", chain.fkine), ("fkj", chain.fkine_jacob0)):
            for size in SIZES:
                if size == 1:
                    samples = q[:single]
                    times = np.empty(len(samples))
                    for i, sample in enumerate(samples):
                        start = time.perf_counter_ns()
                        function(sample)
                        times[i] = time.perf_counter_ns() - start
                else:
                    batch = q[:size]
                    repeat = max(3, 20_000 // size)
                    times = np.empty(repeat)
                    for i in range(repeat):
                        start = time.perf_counter_ns()
                        function(batch)
                        times[i] = time.perf_counter_ns() - start
                out[f"{name} {label} {size}"] = float(np.median(times)) / 1e3
    json.dump(out, sys.stdout)


def run(tree: Path, single: int, numpy_only: bool = False) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    if numpy_only:
        env["MK_COMPILED"] = "0"
    done = subprocess.run([sys.executable, __file__, "--worker", "--single", str(single)], cwd=tree, env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--single", type=int, default=2000, help="one-call samples per row")
    parser.add_argument("--baseline", help="git revision to compare with (e.g. main)")
    args = parser.parse_args()

    import numpy as np

    sides = {"ours": (REPO, False), "numpy": (REPO, True)}
    with tempfile.TemporaryDirectory() as temporary:
        if args.baseline:
            archive = subprocess.run(["git", "-C", str(REPO), "archive", args.baseline], capture_output=True,
                                     check=True).stdout
            subprocess.run(["tar", "-x", "-C", temporary], input=archive, check=True)
            sides["baseline"] = (Path(temporary), False)
        rounds = [{side: run(tree, args.single, numpy_only) for side, (tree, numpy_only) in sides.items()}
                  for _ in range(args.rounds)]

    def med(values) -> float:
        return float(np.median(list(values)))

    def shown(micro: float) -> str:
        return f"{micro:.1f} us" if micro < 1e4 else f"{micro / 1e3:.1f} ms"

    header = ["chain", "what", "N", *(f"{side}" for side in sides), "ours / numpy"]
    if args.baseline:
        header.append(f"ours / {args.baseline}")
    rows = []
    for key in rounds[0]["ours"]:
        name, label, size = key.split()
        row = [name, {"fk": "fkine", "fkj": "fkine_jacob0"}[label], "one call (n,)" if size == "1" else size]
        row += [shown(med(r[side][key] for r in rounds)) for side in sides]
        row.append(f"{med(r['ours'][key] / r['numpy'][key] for r in rounds):.2f}")
        if args.baseline:
            row.append(f"{med(r['ours'][key] / r['baseline'][key] for r in rounds):.2f}")
        rows.append(row)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(f"\nSerialChain benchmark: {os.cpu_count()} cores (load {load}), Python {sys.version.split()[0]}, "
          f"numpy {np.__version__}; medians over {args.rounds} rounds.\n")
    print_table(header, rows)


if __name__ == "__main__":
    if "--worker" in sys.argv:
        worker(int(sys.argv[sys.argv.index("--single") + 1]))
    else:
        main()
