"""The avoidance zones' cost per velocity-IK command, printed as tables (a benchmark, not a test).

Issue 34's budget: the check adds at most 0.2 ms per command at 30 monitored points and 10 zones.
What a velocity IK adds per command because of zones is the monitored points' positions,
velocities and accelerations at the command and the check of them (``ZoneGuard.check``). Measured
as the CPU time of this thread (``time.thread_time``: what a loaded machine distorts least; the
time other processes take the core is not counted) per call, averaged over ``repeat`` calls in a
round, the median of the rounds printed with every round; at 30 points (random, about a machine)
and 10 zones (a ceiling, a floor, three walls, two boxes, two swing sectors and a 1,800-triangle
LandXML-style TIN surface):

* ``ZoneGuard.check`` at 30 points; ``Monitor.check`` alone: compiled
  (:mod:`manipulator_kinematics.zone_kernel`), without the TIN, on the numpy path
  (``compiled=False``), and zone by zone (a loop over ``Zone.clearance`` and ``scale_for``: the
  baseline);
* beside them, what a node adds with each check besides it: the ``zone_clearance`` message
  (:func:`manipulator_kinematics.nodes.zone_output.clearance_message`, built; its serialization
  and sending are rclpy's);
* per machine, the excavator (``MonitoredPoints.motion``: 23 points), the wheel loader WL20 and
  the knuckle crane KC100 (``HydraulicModel.monitored_motion``: 12 and 13 points): the points,
  their check, and the two together, the per-command total, beside the budget.

``--tree PATH`` measures the same calls with the package of another source tree (e.g. main's,
``git archive main | tar -x -C PATH``) in a child process, a round of it before each round here,
so both run at the same load: the code before and after in one run. Its numba caches are that
tree's (a first child fills them: minutes).

Run: python benchmarks/bench_zones.py [--quick] [--tree PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from builtin_interfaces.msg import Time
from matplotlib.tri import Triangulation
from tables import print_table

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.grade.design_surface import Tin
from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.hydraulic import model as hydraulic
from manipulator_kinematics.nodes.zone_output import clearance_message
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.zone_guard import ZoneGuard
from manipulator_kinematics.zones import KERNEL, Monitor, Zone, scale_for, stop_time

POINTS, PERIOD, STOP = 30, 0.05, 0.3
#: How long the command in force goes on (s): the check's in-flight term (its cost is the same at any value).
DELAY = 0.02
#: Issue 34's budget per command, us.
BUDGET = 200.0
MACHINES = ("excavator", "wheel loader", "knuckle crane")


def zones(rng: np.random.Generator) -> list[Zone]:
    xy = rng.uniform(-15.0, 15.0, (900, 2))
    tin = Tin(
        np.column_stack([xy, -1.5 + 0.05 * xy[:, 0]]), Triangulation(xy[:, 0], xy[:, 1]).triangles, "bench"
    )
    made = [
        ("ceiling", {"height": 7.0}, None),
        ("floor", {"height": -3.0}, None),
        ("wall", {"point": [7.0, 0.0], "normal": [1.0, 0.0]}, None),
        ("wall", {"point": [0.0, 6.0], "normal": [0.2, 1.0]}, None),
        ("wall", {"point": [-5.0, 0.0], "normal": [-1.0, 0.3]}, None),
        ("box", {"min": [2.0, 3.0, 0.0], "max": [5.0, 5.0, 3.0]}, None),
        ("box", {"min": [-6.0, -6.0, -1.0], "max": [-3.0, -4.0, 2.0]}, None),
        ("sector", {"from": 2.5, "to": -2.5}, None),
        ("sector", {"from": -1.2, "to": -0.9}, None),
        ("surface", {"side": "below", "surface": "", "file": "bench.xml"}, tin),
    ]
    return [
        Zone(f"{kind}_{i}", kind, "base", 0.3, values, surface)
        for i, (kind, values, surface) in enumerate(made)
    ]


def zone_by_zone(all_zones: list[Zone], p: np.ndarray, v: np.ndarray, T: float) -> float:
    """The baseline: each zone's clearance and scale on its own."""
    scale = 1.0
    for zone in all_zones:
        c, g = zone.clearance(p)
        scale = min(scale, float(scale_for(c, -np.sum(g * v, axis=-1), T, PERIOD).min()))
    return scale


def calls() -> dict[str, Callable[[], object]]:
    """Every measured call, labelled, made with whichever package this process imports."""
    rng = np.random.default_rng(34)
    all_zones = zones(rng)
    names = [f"point_{i}" for i in range(POINTS)]
    p = rng.uniform([-4.0, -4.0, -1.0], [8.0, 4.0, 7.0], (POINTS, 3))
    v = rng.normal(0.0, 0.5, (POINTS, 3))
    a = rng.normal(0.0, 0.3, (POINTS, 3))
    rates = rng.uniform(-0.2, 0.2, 4)
    guard = ZoneGuard(all_zones, names, np.array([1.0, 0.15, 0.18, 0.2]) / STOP, PERIOD)
    monitor, without_tin = Monitor(all_zones, names), Monitor(all_zones[:-1], names)
    T = stop_time(rates, guard.decelerations)
    assert KERNEL.get(wait=True) is not None and hydraulic.compiled_kernel(wait=True) is not None
    numpy_path = monitor.check(p, v, T, PERIOD, compiled=False, accelerations=a)
    assert abs(numpy_path.scale - monitor.check(p, v, T, PERIOD, accelerations=a).scale) < 1e-12
    # The batched check and the zone-by-zone baseline agree (the benchmark measures one answer).
    assert abs(monitor.check(p, v, T, PERIOD).scale - zone_by_zone(all_zones, p, v, T)) < 1e-12
    measured: dict[str, Callable[[], object]] = {
        f"ZoneGuard.check, {POINTS} points x 10 zones": lambda: guard.check(
            p, v, rates, accelerations=a, delay=DELAY
        ),
        f"Monitor.check, {POINTS} x 10": lambda: monitor.check(p, v, T, PERIOD, accelerations=a),
        f"Monitor.check, {POINTS} x 9 (no TIN)": lambda: without_tin.check(p, v, T, PERIOD, accelerations=a),
        f"Monitor.check numpy path, {POINTS} x 10": lambda: monitor.check(
            p, v, T, PERIOD, compiled=False, accelerations=a
        ),
        f"zone by zone (baseline), {POINTS} x 10": lambda: zone_by_zone(all_zones, p, v, T),
    }
    # Not the check but beside it in a node: the zone_clearance message of the check, built.
    verdict = guard.check(p, v, rates, accelerations=a, delay=DELAY)
    measured[f"zone_clearance message, {POINTS} x 10 (built, not sent)"] = lambda: clearance_message(
        Time(), "bench", guard, verdict.check
    )
    exc = Excavator.default()
    points = MonitoredPoints(exc)
    D, D_dot = exc.limits.reference, np.array([0.3, 0.1, -0.1, 0.15])
    machines: list[tuple[str, Callable[[], tuple[np.ndarray, ...]], list[str], np.ndarray, np.ndarray]] = [
        ("excavator", lambda: points.motion(D, D_dot), points.names, exc.limits.max_rates, D_dot)
    ]
    for label, file in (
        ("wheel loader", "wheel_loader_wl20.yaml"),
        ("knuckle crane", "knuckle_crane_kc100.yaml"),
    ):
        h = HydraulicModel.from_file(config_path(file))
        rate = 0.5 * h.max_speed

        def motion(h: HydraulicModel = h, rate: np.ndarray = rate) -> tuple[np.ndarray, ...]:
            return h.monitored_motion(h.reference, rate)[1:]

        machines.append((label, motion, h.monitored(h.reference, rate)[0], h.max_speed, rate))
    for label, motion, point_names, max_rates, command in machines:
        machine_guard = ZoneGuard(all_zones, point_names, max_rates / STOP, PERIOD)
        mp, mv, ma = motion()
        assert mp.shape == mv.shape == ma.shape == (len(point_names), 3)

        def check(
            g: ZoneGuard = machine_guard, m: tuple = (mp, mv, ma), rates: np.ndarray = command
        ) -> object:
            return g.check(m[0], m[1], rates, accelerations=m[2], delay=DELAY)

        def total(
            g: ZoneGuard = machine_guard, motion: Callable = motion, rates: np.ndarray = command
        ) -> object:
            q, qv, qa = motion()
            return g.check(q, qv, rates, accelerations=qa, delay=DELAY)

        n = len(point_names)
        measured[f"{label}: {n} points + velocities + accelerations"] = motion
        measured[f"{label}: ZoneGuard.check ({n} x 10)"] = check
        measured[f"{label}: points + check (per command)"] = total
    return measured


def one_round(measured: dict[str, Callable[[], object]], repeat: int) -> dict[str, float]:
    """CPU us per call of each call, averaged over ``repeat`` calls (a tenth of them for the slow
    baselines)."""
    out = {}
    for label, fn in measured.items():
        n = max(repeat // 10, 10) if "numpy" in label or "baseline" in label else repeat
        start = time.thread_time()
        for _ in range(n):
            fn()
        out[label] = (time.thread_time() - start) / n * 1e6
    return out


def child_round(tree: Path, repeat: int) -> dict[str, float]:
    """One round with the package of ``tree`` (module docstring)."""
    env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONDONTWRITEBYTECODE": "1"}
    done = subprocess.run(
        [sys.executable, __file__, "--child", str(repeat)],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise SystemExit(f"--tree {tree}: the child failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def loads() -> str:
    """The load averages (1, 5, 15 min) and the cores they share."""
    return f"{', '.join(f'{x:.1f}' for x in os.getloadavg())} ({os.cpu_count()} cores)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer rounds and repetitions")
    parser.add_argument(
        "--tree", type=Path, help="a source tree to measure beside this one (the code before)"
    )
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)  # one round of --tree's, as JSON
    args = parser.parse_args()
    if args.child:
        import manipulator_kinematics

        print(json.dumps({**one_round(calls(), args.child), "tree": manipulator_kinematics.__file__}))
        return
    rounds, repeat = (3, 300) if args.quick else (5, 1000)
    print(f"load average at the start: {loads()}")
    measured = calls()
    if args.tree:
        tree = args.tree.resolve()
        print(f"before: {tree}; after: {Path(__file__).resolve().parents[1]}", flush=True)
        warm = child_round(tree, 10)  # its kernels compiled or loaded, nothing timed
        if not warm.pop("tree").startswith(str(tree)):
            raise SystemExit(f"--tree {tree}: the child imported another manipulator_kinematics")
    before: list[dict[str, float]] = []
    after: list[dict[str, float]] = []
    for _ in range(rounds):
        if args.tree:
            before.append(child_round(tree, repeat))
        after.append(one_round(measured, repeat))
    load = loads()

    def median(runs: list[dict[str, float]], label: str) -> str:
        return f"{statistics.median(r[label] for r in runs):.1f}" if runs and label in runs[0] else "-"

    def spread(runs: list[dict[str, float]], label: str) -> str:
        return ", ".join(f"{r[label]:.1f}" for r in runs) if runs and label in runs[0] else "-"

    print(f"\nCPU us per call (time.thread_time), median of {rounds} rounds of {repeat} calls")
    header = ["per command", "after", "after, rounds"]
    if args.tree:
        header[1:1] = ["before", "before, rounds"]
    rows = []
    for label in measured:
        row = [label, median(after, label), spread(after, label)]
        if args.tree:
            row[1:1] = [median(before, label), spread(before, label)]
        rows.append(row)
    print_table(header, rows)
    print(f"\nPer command, what the zones add (the points + their check) against the {BUDGET:.0f} us budget")
    rows = []
    for machine in MACHINES:
        label = next(k for k in measured if k.startswith(machine) and k.endswith("(per command)"))
        total = statistics.median(r[label] for r in after)
        row = [machine, median(after, label), f"{BUDGET:.0f}", "yes" if total <= BUDGET else "NO"]
        if args.tree:
            row[1:1] = [median(before, label)]
        rows.append(row)
    header = ["machine", "after, us", "budget, us", "within"]
    if args.tree:
        header[1:1] = ["before, us"]
    print_table(header, rows)
    print(f"\nload average at the end: {load}")


if __name__ == "__main__":
    main()
