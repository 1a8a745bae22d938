"""Benchmark (not a test): loading the pump boom's region table, and the first region IK after it.

Rows: the code and shipped table of each ``--commits`` commit (default 47c33a1: the 55-square
table before issue #19; and 6afd0b1: 1598 squares, not deflated, the code with issue #22's
compiled kernel), unpacked with ``git archive`` into a temporary directory, and this
checkout with its shipped table (2470 squares). Old and new run in separate processes, with this
venv's Python.

* fresh processes (a node's case: one load per process): ``--processes`` processes per row, each
  imports the package and reads the machine file, then times ``PumpBoom.table`` (the table file
  parsed, checked against the machine file, the cell owners filled), then ONE first call, in
  turn the first ``region_ik_point`` at a point inside a square's core, the first at a point in a
  transition band, or the first ``region_ik`` (numpy, a batch of one) at a band point; then the
  same call again at another point of its kind (warm: the call's own cost, the numba kernel still
  loading in the background). The first call's extra cost is what it builds on first use.
* in-process: after a first load, ``--rounds`` loads (``RegionTable.load`` with the machine's
  ``built_for``) one after the other in one process, the parsed-file cache cleared before each;
  three such processes per row; all loads, and those during which the process was not preempted
  (no involuntary context switch: on the shared cores another process's time slice of a few ms
  lands in a load of 5 ms far more often than in one of 2 ms); and in one process of this
  checkout, the load's steps one by one, and what the table builds on first use.

Medians with min-max in ms. Target (issue #19 item 1): the shipped table loads as fast as the
55-square table did, and its first IK call costs no more than with the table before it (6afd0b1:
the same code of the first call; against 47c33a1 the first single-point call pays for starting
issue #22's kernel loader, whatever the table).

Run: .venv/bin/python benchmarks/bench_pump_boom_table.py [--processes 9] [--rounds 15]
     [--commits 47c33a1 6afd0b1]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from tables import print_table

ROOT = Path(__file__).resolve().parent.parent

#: Points (x, y, z) m in the boom plane y = 0 covered by both tables: inside a 5 m square's core
#: (farther than half a band from its edges), and two in the band along the edge z = 10 m.
CORE = (22.75, 0.0, 7.5)
BAND = ((22.75, 0.0, 10.2), (23.1, 0.0, 9.85))

_FRESH = """
import json, sys, time
import numpy as np
from pump_boom_kinematics.kinematics import PumpBoom
call, first, again = sys.argv[1], json.loads(sys.argv[2]), json.loads(sys.argv[3])
boom = PumpBoom.default()
start = time.perf_counter()
table = boom.table
load = time.perf_counter() - start
times = []
for point in (first, again):
    start = time.perf_counter()
    if call == "region_ik_point":
        q, failure = boom.region_ik_point(*point, 0.0)
        ok = q is not None
    else:
        ok = bool(boom.region_ik(np.array(point)).ok)
    times.append(time.perf_counter() - start)
    assert ok, point
blended = boom.region_ik(np.array([first, again])).blended.tolist()
print(json.dumps({"squares": len(table), "load": load, "first": times[0], "warm": times[1],
                  "blended": blended, "module": __import__("pump_boom_kinematics").__file__}))
"""

_IN_PROCESS = """
import json, resource, sys, time
from manipulator_kinematics import param_files
from pump_boom_kinematics.kinematics import PumpBoom
from pump_boom_kinematics.regions import RegionTable
boom = PumpBoom.default()
# The code of older commits (baseline rows) named these privately, and cached no parse.
path, key = getattr(boom, "table_path", getattr(boom, "_table_path", None))(), boom.table_key()
old_cache = getattr(getattr(param_files, "_parse", None), "cache_clear", lambda: None)
clear = getattr(param_files, "clear_cache", old_cache)
RegionTable.load(path, key)  # the process's first load is the fresh-process column's
times = []
for _ in range(int(sys.argv[1])):
    clear()
    switches = resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw
    start = time.perf_counter()
    RegionTable.load(path, key)
    times.append((time.perf_counter() - start, resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw > switches))
print(json.dumps(times))
"""

_PHASES = """
import json, sys, time
import numpy as np
from manipulator_kinematics import param_files
from manipulator_kinematics.schema import validate
from pump_boom_kinematics import regions
from pump_boom_kinematics.kinematics import PumpBoom
boom = PumpBoom.default()
path, key = boom.table_path(), boom.table_key()
regions.RegionTable.load(path, key)
times = {}
def timed(name, call):
    start = time.perf_counter()
    result = call()
    times.setdefault(name, []).append(time.perf_counter() - start)
    return result
for _ in range(int(sys.argv[1])):
    param_files.clear_cache()
    document = timed("YAML parse (libyaml) of the file", lambda: param_files.load_parameters(path))
    section = timed("schema check", lambda: validate(document[regions.TABLE_SECTION], regions.TABLE_SCHEMA,
                                                     regions.TABLE_SECTION))
    squares = timed("squares (base64, zlib) -> arrays",
                    lambda: regions.decode_squares(section["squares"], "squares"))
    index = np.stack([squares["column"], squares["row"], squares["level"]], axis=-1)
    table = timed("cell owners (RegionTable())", lambda: regions.RegionTable(
        boom.grid, index, squares["triple"], squares["margin"], section["built_for"], {}, {}))
    param_files.clear_cache()
    timed("whole load (RegionTable.load)", lambda: regions.RegionTable.load(path, key))
    timed("first use: square extents (nearest)", lambda: table.extent)
print(json.dumps(times))
"""

#: (first call, its point, the warm call's point, the point's kind) of the fresh processes, in turn.
CALLS = (
    ("region_ik_point", CORE, (22.9, 0.0, 7.2), "core"),
    ("region_ik_point", BAND[0], BAND[1], "band"),
    ("region_ik", BAND[0], BAND[1], "band"),
)


def run(code: str, tree: Path, *args: str) -> str:
    env = dict(os.environ, PYTHONPATH=str(tree))
    return subprocess.run(
        [sys.executable, "-c", code, *args], cwd=tree, env=env, check=True, capture_output=True, text=True
    ).stdout


def ms(values: list[float]) -> str:
    return f"{statistics.median(values) * 1e3:.2f} ({min(values) * 1e3:.2f}-{max(values) * 1e3:.2f})"


def fresh_process(tree: Path, k: int) -> dict:
    """One fresh process of ``tree``: its load and the k-th of CALLS (first and warm)."""
    call, first, again, kind = CALLS[k % len(CALLS)]
    result = json.loads(run(_FRESH, tree, call, json.dumps(first), json.dumps(again)))
    assert Path(result["module"]).resolve().is_relative_to(tree.resolve()), result["module"]
    assert result["blended"] == [kind == "band"] * 2, (tree, kind, result["blended"])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--processes", type=int, default=9, help="fresh processes per row and first call")
    parser.add_argument("--rounds", type=int, default=15, help="loads in one process")
    parser.add_argument("--commits", nargs="*", default=["47c33a1", "6afd0b1"], help="baseline commits")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        trees = {}
        for commit in args.commits:
            trees[commit] = Path(scratch) / commit
            trees[commit].mkdir()
            archive = subprocess.run(
                ["git", "archive", commit], cwd=ROOT, check=True, capture_output=True
            ).stdout
            subprocess.run(["tar", "-x", "-C", str(trees[commit])], input=archive, check=True)
        trees["this checkout"] = ROOT
        # Row after row within each turn: the machine's load (shared) falls on every row alike.
        fresh: dict[str, list[dict]] = {name: [] for name in trees}
        for k in range(args.processes * len(CALLS)):
            for name, tree in trees.items():
                fresh[name].append(fresh_process(tree, k))
        loads: dict[str, list[float]] = {name: [] for name in trees}
        for _ in range(3):
            for name, tree in trees.items():
                loads[name] += json.loads(run(_IN_PROCESS, tree, str(args.rounds)))
        phases = json.loads(run(_PHASES, ROOT, str(args.rounds)))
    rows = []
    for name, results in fresh.items():
        calls = [[r for k, r in enumerate(results) if k % len(CALLS) == c] for c in range(len(CALLS))]
        alone = [t for t, preempted in loads[name] if not preempted]
        alone_ms = f"{ms(alone) if alone else '-'}, {len(alone)} of {len(loads[name])}"
        rows.append(
            [
                name,
                str(results[0]["squares"]),
                ms([r["load"] for r in results]),
                ms([t for t, _ in loads[name]]),
                alone_ms,
                *(f"{ms([r['first'] for r in rs])} / {ms([r['warm'] for r in rs])}" for rs in calls),
            ]
        )
    print(
        f"Region table load, ms median (min-max): {args.processes * len(CALLS)} fresh processes per row, "
        f"3 x {args.rounds} loads in one process; first call / the same call warm, ms, "
        f"{args.processes} fresh processes each; load average {os.getloadavg()[0]:.1f} "
        f"({os.cpu_count()} CPUs)"
    )
    print_table(
        [
            "code, shipped table",
            "squares",
            "load, fresh process",
            "load, in-process",
            "in-process, loads not preempted",
            *(f"first {call}, {kind} point" for call, _, _, kind in CALLS),
        ],
        rows,
    )
    print()
    print(
        f"This checkout, where the load's time goes ({args.rounds} rounds in one process), "
        "ms median (min-max):"
    )
    print_table(["step", "ms"], [[name, ms(times)] for name, times in phases.items()])


if __name__ == "__main__":
    main()
