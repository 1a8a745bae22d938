"""Benchmark (not a test): the shared SerialChain's FK and FK + Jacobian for every machine's chain,
one configuration per call and batches of 10, 10^3 and 10^5, against a baseline revision in one run.

Columns: ``ours`` (the default path: the compiled kernel, loaded first, see
manipulator_kinematics.chain_kernel), ``numpy`` (``compiled=False``: the vectorised reference) and,
with ``--baseline REV``, the SerialChain of git revision REV: its ``serial_chain.py`` (which must
import nothing of the package, as before issue #22) loaded as a module of its own, the chain built
from the same rows. All in one process, the three sides timed in turn within each round, so the
machine's drift hits them alike; times are medians over rounds, ratios medians of per-round ratios.
One call: median over ``--single`` random configurations; a batch of N: median of repeated calls on
one (N, n) array.

Run: .venv/bin/python benchmarks/bench_serial_chain.py [--rounds 5] [--baseline main]
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from tables import print_table

REPO = Path(__file__).resolve().parent.parent
SIZES = (1, 10, 1000, 100_000)


def chains() -> dict:
    """Every machine's chain as its default config builds it."""
    from palletizer_kinematics.kinematics import Palletizer
    from pump_boom_kinematics.kinematics import PumpBoom
    from scara_kinematics.kinematics import Scara
    from tool_changer_kinematics.kinematics import ToolChanger

    return {"tool_changer": ToolChanger.default().chain, "palletizer": Palletizer.default().chain,
            "scara": Scara.default().chain, "pump_boom": PumpBoom.default().chain}


def baseline_module(revision: str, directory: str):
    """serial_chain.py of ``revision`` as a module of its own."""
    where = f"{revision}:manipulator_kinematics/serial_chain.py"
    source = subprocess.run(["git", "-C", str(REPO), "show", where], capture_output=True, text=True,
                            check=True).stdout
    path = Path(directory) / "baseline_serial_chain.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("baseline_serial_chain", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def timed(function, q: np.ndarray, size: int, single: int) -> float:
    """Median microseconds of ``function`` on one configuration (size 1) or on a batch of ``size``."""
    if size == 1:
        times = np.empty(single)
        for i, sample in enumerate(q[:single]):
            start = time.perf_counter_ns()
            function(sample)
            times[i] = time.perf_counter_ns() - start
    else:
        batch = q[:size]
        times = np.empty(max(5, 20_000 // size))
        for i in range(len(times)):
            start = time.perf_counter_ns()
            function(batch)
            times[i] = time.perf_counter_ns() - start
    return float(np.median(times)) / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--single", type=int, default=2000, help="one-call samples per row")
    parser.add_argument("--baseline", help="git revision to compare with (e.g. main)")
    args = parser.parse_args()

    sys.path.insert(0, str(REPO))
    from manipulator_kinematics.serial_chain import compiled_kernel

    compiled_kernel(wait=True)
    rng = np.random.default_rng(7)
    cases = []  # (chain name, what, size, {side: function}, q)
    with tempfile.TemporaryDirectory() as directory:
        old = baseline_module(args.baseline, directory) if args.baseline else None
        for name, chain in chains().items():
            q = rng.uniform(-3.0, 3.0, (SIZES[-1], chain.n))
            sides = {"ours": (chain.fkine, chain.fkine_jacob0),
                     "numpy": (lambda q, c=chain: c.fkine(q, compiled=False),
                               lambda q, c=chain: c.fkine_jacob0(q, compiled=False))}
            if old is not None:
                rows = [old.DHRow(**{field: getattr(r, field) for field in r.__dataclass_fields__})
                        for r in chain.rows]
                former = old.SerialChain(rows, modified=chain.modified, base=chain.base, tool=chain.tool,
                                         coupling=chain.coupling)
                np.testing.assert_allclose(former.jacob0(q[:100]), chain.jacob0(q[:100]), atol=1e-12)
                sides["baseline"] = (former.fkine, former.fkine_jacob0)
            for index, what in enumerate(("fkine", "fkine_jacob0")):
                for size in SIZES:
                    cases.append((name, what, size, {side: f[index] for side, f in sides.items()}, q))
        rounds = [[{side: timed(f, q, size, args.single) for side, f in functions.items()}
                   for _, _, size, functions, q in cases] for _ in range(args.rounds)]

    def med(values) -> float:
        return float(np.median(list(values)))

    def shown(micro: float) -> str:
        return f"{micro:.1f} us" if micro < 1e4 else f"{micro / 1e3:.1f} ms"

    side_names = list(cases[0][3])
    header = ["chain", "what", "N", *side_names, "ours / numpy"]
    if args.baseline:
        header.append(f"ours / {args.baseline}")
    table = []
    for k, (name, what, size, _, _) in enumerate(cases):
        row = [name, what, "one call (n,)" if size == 1 else str(size)]
        row += [shown(med(r[k][side] for r in rounds)) for side in side_names]
        row.append(f"{med(r[k]['ours'] / r[k]['numpy'] for r in rounds):.2f}")
        if args.baseline:
            row.append(f"{med(r[k]['ours'] / r[k]['baseline'] for r in rounds):.2f}")
        table.append(row)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(f"\nSerialChain benchmark: {os.cpu_count()} cores (load {load}), Python {sys.version.split()[0]}, "
          f"numpy {np.__version__}; medians over {args.rounds} rounds.\n")
    print_table(header, table)


if __name__ == "__main__":
    main()
