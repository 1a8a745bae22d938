"""Benchmark (not a test): every batch API of every machine against N single calls, and the cost
per state of large batches in a fresh process (issue #32 item 3); Markdown tables on stdout.

Table 1, per API and batch size N (1, 2, 5, 10, 30, 100, 10^3, 10^4, 10^5): the batch's time, N
times one single call's, their ratio and the rounds' spread. One process (a worker: this script
with ``--worker``, the tree under test first on ``sys.path``), every kernel loaded first; per round
every case times the single call (over 500 different states in turn) and each batch size in turn
(the order reversed every other round), each figure the median of 3 blocks of about 2 ms of thread
CPU time (``time.thread_time_ns``: the machine is a shared VM whose other processes wall time would
count). A ratio is the median of the per-round ratios batch(N) / (N x one call), with their range
(min-max); <= 1 means a batch never costs more than the single calls it replaces.

Table 2, per API: the cost per state of a batch of 10^3, 3x10^3, 10^4, 3x10^4 and 10^5 states in a
process of its own that has run nothing larger (the kernels loaded, one batch of 2 run first): the
median of 7 calls. glibc's malloc hands out blocks above its mmap threshold (128 KiB in a fresh
process, raised by each such block freed) by mmap and gives them back by munmap, so a path that
makes large temporaries pays page faults on every call in a band of sizes until a larger batch has
run once (issue #32: excavator states of 3k-16k at about 3x the cost per state); flat means no size
pays for allocation.

``--tree PATH`` measures another checkout of the project (e.g. ``git archive`` of the code before a
change); the APIs timed are public ones, the same in both.

Run: .venv/bin/python benchmarks/bench_batch.py [--rounds 5] [--tree PATH] [--only NAME ...]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SIZES = (1, 2, 5, 10, 30, 100, 1000, 10_000, 100_000)
FRESH = (1000, 3000, 10_000, 30_000, 100_000)
BLOCK_US = 2000.0  # a timed block's length, about
SINGLES = 500  # different states the single call takes in turn
FRESH_CALLS = 7  # calls of a size in its fresh process, at least, and at least FRESH_US of CPU
FRESH_US = 200_000.0
#: The hydraulic family's machines timed (HydraulicModel of each machine file in config/).
FAMILY = {
    "CET200 (family)": "excavator_cet200.yaml",
    "wheel loader": "wheel_loader_wl20.yaml",
    "knuckle crane": "knuckle_crane_kc100.yaml",
}


def apis(largest: int) -> dict:
    """{name: (one(i): the single call of state i, batch(n): the batch of states :n)}, every kernel
    loaded."""
    import numpy as np

    from excavator_kinematics.core import inverse
    from excavator_kinematics.core import kinematics as excavator
    from manipulator_kinematics import serial_chain
    from manipulator_kinematics.param_files import config_path
    from palletizer_kinematics import kinematics as palletizer
    from pump_boom_kinematics import kinematics as pump_boom
    from scara_kinematics import kinematics as scara_module
    from tool_changer_kinematics.kinematics import ToolChanger

    rng = np.random.default_rng(32)
    serial_chain.compiled_kernel(wait=True)
    arm = ToolChanger.default()
    arm.compiled_kernel(wait=True)
    q = rng.uniform(arm.limits.lower, arm.limits.upper, (largest, 6))
    T = arm.fkine(q)
    pal = palletizer.Palletizer.default()
    palletizer.compiled_kernel(pal, wait=True)
    pq = rng.uniform(pal.limits.lower, pal.limits.upper, (largest, pal.limits.lower.size))
    pT = pal.fkine(pq)
    scara = scara_module.Scara.default()
    scara_module.compiled_kernel(scara, wait=True)
    sT = scara.fkine(rng.uniform(scara.limits.lower, scara.limits.upper, (largest, 3)))
    exc = excavator.Excavator.default()
    excavator.compiled_kernel(exc, wait=True)
    inverse.compiled_kernel(exc, wait=True)
    lo, hi = exc.limits.d_min, exc.limits.d_max
    D = rng.uniform(lo + 0.01 * (hi - lo), hi - 0.01 * (hi - lo), (largest, 4))
    D_dot = rng.uniform(-1, 1, (largest, 4)) * exc.limits.max_rates
    D_ddot = rng.uniform(-1, 1, (largest, 4)) * exc.limits.max_rates
    Q = exc.pose(D)
    boom = pump_boom.PumpBoom.default()
    pump_boom.compiled_kernel(boom, wait=True)
    bT = boom.fkine(rng.uniform(boom.limits.lower, boom.limits.upper, (largest, 6)))
    family = {}
    for machine, file in FAMILY.items():
        family[machine] = family_apis(config_path(file), rng, largest)
    return {
        "tool changer fkine_jacob0": (
            lambda i: arm.chain.fkine_jacob0(q[i]),
            lambda n: arm.chain.fkine_jacob0(q[:n]),
        ),
        "tool changer fkine": (lambda i: arm.chain.fkine(q[i]), lambda n: arm.chain.fkine(q[:n])),
        "palletizer fkine_jacob0": (
            lambda i: pal.chain.fkine_jacob0(pq[i]),
            lambda n: pal.chain.fkine_jacob0(pq[:n]),
        ),
        "tool changer solve_ik": (lambda i: arm.solve_ik(T[i]), lambda n: arm.solve_ik(T[:n])),
        "palletizer solve_ik": (lambda i: pal.solve_ik(pT[i]), lambda n: pal.solve_ik(pT[:n])),
        "SCARA solve_ik": (lambda i: scara.solve_ik(sT[i]), lambda n: scara.solve_ik(sT[:n])),
        "excavator pose": (lambda i: exc.pose(D[i]), lambda n: exc.pose(D[:n])),
        "excavator state": (
            lambda i: exc.state(D[i], D_dot[i], D_ddot[i]),
            lambda n: exc.state(D[:n], D_dot[:n], D_ddot[:n]),
        ),
        "excavator ik": (lambda i: exc.ik(Q[i]), lambda n: exc.ik(Q[:n])),
        "pump boom solve_ik": (
            lambda i: boom.solve_ik(bT[i], use_orientation=False),
            lambda n: boom.solve_ik(bT[:n], use_orientation=False),
        ),
        **{f"{machine} {name}": api for machine, apis in family.items() for name, api in apis.items()},
    }


def family_apis(path: Path, rng, largest: int) -> dict:
    """``state``, ``pose`` and ``jc0`` of a hydraulic family machine file (HydraulicModel), states
    inside its stroke box and rates within its speed limits."""

    from manipulator_kinematics.hydraulic import HydraulicModel
    from manipulator_kinematics.hydraulic import model as family

    family.compiled_kernel(wait=True)
    h = HydraulicModel.from_file(path)
    span = h.upper - h.lower
    D = rng.uniform(h.lower + 0.01 * span, h.upper - 0.01 * span, (largest, h.m))
    D_dot, D_ddot = (rng.uniform(-1, 1, (largest, h.m)) * h.max_speed for _ in range(2))
    return {
        "state": (
            lambda i: h.state(D[i], D_dot[i], D_ddot[i]),
            lambda n: h.state(D[:n], D_dot[:n], D_ddot[:n]),
        ),
        "pose": (lambda i: h.pose(D[i]), lambda n: h.pose(D[:n])),
        "jc0": (lambda i: h.jc0(D[i]), lambda n: h.jc0(D[:n])),
    }


def cpu_us(function, items, calls: int) -> float:
    """Microseconds of thread CPU time per call of ``function(item)`` (items in turn)."""
    start = time.thread_time_ns()
    for i in range(calls):
        function(items[i % len(items)])
    return (time.thread_time_ns() - start) / 1e3 / calls


def worker(job: dict) -> dict:
    sys.path.insert(0, job["tree"])
    if job.get("fresh"):
        name, n = job["fresh"]
        _, batch = apis(max(n, 2))[name]
        batch(2)
        times = []
        while len(times) < FRESH_CALLS or sum(times) * n < FRESH_US:
            start = time.thread_time_ns()
            batch(n)
            times.append((time.thread_time_ns() - start) / 1e3 / n)
        return {"per_state": sorted(times)[len(times) // 2]}
    sizes = [n for n in SIZES if n <= job["largest"]]
    cases = {
        name: api for name, api in apis(job["largest"]).items() if not job["only"] or name in job["only"]
    }
    calls = {}
    for name, (one, batch) in cases.items():
        for n in sizes:
            batch(n)  # the first call of a size is not timed
        once = cpu_us(one, range(SINGLES), 50)
        calls[name] = {"one": max(1, int(BLOCK_US / once))}
        for n in sizes:
            calls[name][n] = max(1, int(BLOCK_US / max(cpu_us(batch, [n], 1), 0.05)))
    rounds = {name: [] for name in cases}
    for index in range(job["rounds"]):
        for name, (one, batch) in cases.items():
            sides = ["one", *sizes]
            if index % 2:
                sides.reverse()
            times = {side: [] for side in sides}
            for _ in range(3):
                for side in sides:
                    if side == "one":
                        times[side].append(cpu_us(one, range(SINGLES), calls[name][side]))
                    else:
                        times[side].append(cpu_us(batch, [side], calls[name][side]))
            rounds[name].append({str(side): sorted(t)[1] for side, t in times.items()})
    return {"rounds": rounds, "sizes": sizes}


def run(job: dict) -> dict:
    """The worker on ``job`` in a fresh interpreter (this venv's Python)."""
    done = subprocess.run(
        [sys.executable, __file__, "--worker"],
        input=json.dumps(job),
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode:
        sys.exit(f"worker failed: {done.stderr[-2000:]}")
    return json.loads(done.stdout)


def median(values: list[float]) -> float:
    values = sorted(values)
    return values[len(values) // 2]


def shown(micro: float) -> str:
    return f"{micro:.3g} us" if micro < 1e4 else f"{micro / 1e3:.3g} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--largest", type=int, default=100_000, help="the largest batch")
    parser.add_argument("--tree", default=str(REPO), help="the checkout to measure (default: this one)")
    parser.add_argument("--only", nargs="*", default=[], help="API names (default: all)")
    parser.add_argument("--no-fresh", action="store_true", help="skip table 2")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        json.dump(worker(json.load(sys.stdin)), sys.stdout)
        return
    from tables import print_table

    before = os.getloadavg()
    job = {"tree": str(Path(args.tree).resolve()), "rounds": args.rounds, "largest": args.largest}
    result = run({**job, "only": args.only})
    sizes = result["sizes"]
    rows, ratios = [], []
    for name, rounds in result["rounds"].items():
        one = median([r["one"] for r in rounds])
        ratios.append([name, shown(one)])
        for n in sizes:
            per = [r[str(n)] / (n * r["one"]) for r in rounds]
            batch = median([r[str(n)] for r in rounds])
            rows.append(
                [
                    name,
                    str(n),
                    shown(batch),
                    shown(n * one),
                    f"{median(per):.2f} ({min(per):.2f}-{max(per):.2f})",
                ]
            )
            ratios[-1].append(f"{median(per):.2f}")
    fresh = []
    if not args.no_fresh:
        for name in result["rounds"]:
            row = [name]
            for n in (n for n in FRESH if n <= args.largest):
                row.append(f"{run({**job, 'fresh': [name, n]})['per_state']:.3g}")
            fresh.append(row)
    load = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in zip(before, os.getloadavg(), strict=True))
    print(
        f"Measured {time.strftime('%Y-%m-%d %H:%M')}: {os.cpu_count()} cores, load average (1, 5, 15 min) "
        f"{load} (start-end); tree {args.tree}; thread CPU time, {args.rounds} rounds, each figure the "
        "median of the rounds' median of 3 blocks; ratio = batch of N / (N x one call), median "
        "(min-max) of the per-round ratios.\n"
    )
    print_table(["API", "one call", *[f"N={n}" for n in sizes]], ratios)
    print()
    print_table(["API", "N", "batch", "N x one call", "ratio (min-max)"], rows)
    if fresh:
        print(
            "\nPer state (us) in a fresh process (nothing larger run in it), the median of at least "
            f"{FRESH_CALLS} calls and {FRESH_US / 1e6:g} s after one batch of 2:\n"
        )
        print_table(["API", *[f"N={n}" for n in FRESH if n <= args.largest]], fresh)


if __name__ == "__main__":
    main()
