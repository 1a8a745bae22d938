"""Hydraulic family speed (issue 31 item 6), printed as Markdown tables (a benchmark, not a test).

Side by side in one process, over several rounds, the CPU time of this thread (time.thread_time:
what a call costs, not what other processes on a shared machine take; read the ratios, which
compare numbers of the same round):

* one call (one state): the full state (Q, Q_dot, Q_ddot, JC0, theta, K) through the generic
  core :class:`manipulator_kinematics.hydraulic.HydraulicModel` for the CET200's family section, the
  WL20 and the KC100, through its compiled kernel and through the numpy path (the code before
  the kernel: ``KERNEL.ready`` set aside); ``pose``, ``jc0``, ``cylinder_rates`` (eq. 9);
  beside the excavator's dedicated ``Excavator.state`` and the peers of the issue's target: a
  plain numba pose function returning a new array (the excavator's kernel, as
  bench_excavator_core.py, and the family kernel's pose of the same machine);
* batches of 1 to 10^4 states through ``state``: us per state, and the batch against as many
  single calls (issue 32: a batch is never slower).

Run: python benchmarks/bench_family.py [--rounds 5] [--quick]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
from numba import njit
from tables import print_table

from excavator_kinematics.core import state_kernel
from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.kinematics import compiled_kernel as excavator_kernel
from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.hydraulic import kernel as family_kernel
from manipulator_kinematics.hydraulic import model as core
from manipulator_kinematics.param_files import config_path

MACHINES = {
    "CET200 (family core)": "excavator_cet200.yaml",
    "WL20": "wheel_loader_wl20.yaml",
    "KC100": "knuckle_crane_kc100.yaml",
}
BATCHES = (1, 10, 100, 1000, 10_000)


@njit(cache=True, error_model="numpy")
def excavator_pose(packed: np.ndarray, D: np.ndarray) -> np.ndarray:
    """The issue's peer: a plain numba pose function returning a new array (the excavator's)."""
    Q = np.empty(4)
    state_kernel.pose(packed, D, Q)
    return Q


@njit(cache=True, error_model="numpy")
def family_pose(code: np.ndarray, values: np.ndarray, D: np.ndarray, nq: int) -> np.ndarray:
    """The same peer for a family machine: the family kernel's pose into a new array."""
    Q = np.empty(nq)
    family_kernel.pose(code, values, D, Q)
    return Q


def per_call_us(fn: Callable[[], object], repeat: int, runs: int = 15) -> float:
    """Best of ``runs`` runs of ``repeat`` calls, us per call (on a loaded machine the best run
    is the one nobody preempted)."""
    best = float("inf")
    for _ in range(runs):
        start = time.thread_time()
        for _ in range(repeat):
            fn()
        best = min(best, (time.thread_time() - start) / repeat)
    return best * 1e6


def numpy_path_us(fn: Callable[[], object], repeat: int) -> float:
    """:func:`per_call_us` with the family kernel set aside (every call on the numpy path)."""
    ready = core.KERNEL.ready
    os.environ["MK_COMPILED"] = "0"
    core.KERNEL.ready = None
    try:
        return per_call_us(fn, repeat, runs=3)
    finally:
        core.KERNEL.ready = ready
        del os.environ["MK_COMPILED"]


def machine_round(name: str, model: HydraulicModel, row: dict[str, float], n: int, scale: float) -> None:
    """One family machine's numbers of one round into ``row``."""
    D, V, A = model.reference.copy(), 0.3 * model.max_speed, 0.1 * model.max_speed
    code, values, nq = model.program.code, model.program.values, model.program.nq
    Q_dot = model.state(D, V).Q_dot
    row[f"{name}: plain numba pose"] = per_call_us(lambda: family_pose(code, values, D, nq), n)
    row[f"{name}: state"] = per_call_us(lambda: model.state(D, V, A), n)
    row[f"{name}: pose"] = per_call_us(lambda: model.pose(D), n)
    row[f"{name}: jc0"] = per_call_us(lambda: model.jc0(D), n)
    row[f"{name}: cylinder_rates"] = per_call_us(lambda: model.cylinder_rates(D, Q_dot), n // 10)
    row[f"{name}: state, numpy path"] = numpy_path_us(lambda: model.state(D, V, A), max(int(20 * scale), 3))
    rng = np.random.default_rng(6)
    for size in BATCHES:
        batch = rng.uniform(model.lower, model.upper, size=(size, model.m))
        rates = rng.uniform(-1.0, 1.0, size=batch.shape) * model.max_speed
        repeat = max(int(2e4 * scale / size), 1)
        row[f"{name}: batch {size}"] = (
            per_call_us(lambda b=batch, r=rates: model.state(b, r, r), repeat, 5) / size
        )


def one_round(models: dict[str, HydraulicModel], exc: Excavator, scale: float) -> dict[str, float]:
    """us per call (one state) and us per state of each batch, of one round."""
    n = max(int(3000 * scale), 100)
    row: dict[str, float] = {}
    D = exc.limits.reference.copy()
    V, A = np.array([0.3, 0.05, -0.08, 0.1]), np.array([0.1, 0.02, 0.01, -0.03])
    packed = exc.packed
    row["excavator: plain numba pose"] = per_call_us(lambda: excavator_pose(packed, D), n)
    row["excavator: Excavator.state"] = per_call_us(lambda: exc.state(D, V, A), n)
    for name, model in models.items():
        machine_round(name, model, row, n, scale)
    rng = np.random.default_rng(6)
    for size in BATCHES:
        batch = rng.uniform(exc.limits.d_min, exc.limits.d_max, size=(size, 4))
        rates = rng.uniform(-1.0, 1.0, size=batch.shape) * exc.limits.max_rates
        repeat = max(int(2e4 * scale / size), 1)
        row[f"excavator: batch {size}"] = (
            per_call_us(lambda b=batch, r=rates: exc.state(b, r, r), repeat, 5) / size
        )
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5, help="rounds of every measurement")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    args = parser.parse_args()
    scale = 0.1 if args.quick else 1.0
    models = {name: HydraulicModel.from_file(config_path(f)) for name, f in MACHINES.items()}
    exc = Excavator.default()
    excavator_kernel(exc, wait=True)
    core.compiled_kernel(wait=True)
    rounds = [one_round(models, exc, scale) for _ in range(args.rounds)]

    def median(key: str) -> float:
        return statistics.median(r[key] for r in rounds)

    def ratio(key: str, over: str) -> float:
        """Median over the rounds of the ratio within each round."""
        return statistics.median(r[key] / r[over] for r in rounds)

    def spread(key: str) -> str:
        values = [r[key] for r in rounds]
        return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})"

    print(f"Hydraulic family benchmark, {args.rounds} rounds, load average {os.getloadavg()[0]:.1f}")
    print()
    print("One call (one state), us of CPU: median (min-max) over the rounds")
    print()
    peer = "excavator: plain numba pose"
    rows = [
        [
            "excavator (dedicated)",
            spread("excavator: Excavator.state"),
            "",
            "",
            "",
            "",
            spread(peer),
            f"{ratio('excavator: Excavator.state', peer):.2f}",
        ]
    ]
    for name in models:
        own = f"{name}: plain numba pose"
        rows.append(
            [
                name,
                spread(f"{name}: state"),
                spread(f"{name}: pose"),
                spread(f"{name}: jc0"),
                spread(f"{name}: cylinder_rates"),
                f"{median(f'{name}: state, numpy path'):.0f}",
                spread(own),
                f"{ratio(f'{name}: state', peer):.2f} / {ratio(f'{name}: state', own):.2f}",
            ]
        )
    print_table(
        [
            "machine",
            "state",
            "pose",
            "jc0",
            "cylinder_rates",
            "state, numpy path",
            "peer: plain numba pose",
            "state / peer (excavator's / own)",
        ],
        rows,
    )
    print()
    print("Batches through state: us per state (median over the rounds); x = batch / as many single calls")
    print()
    single = {"excavator": "excavator: Excavator.state", **{name: f"{name}: state" for name in models}}
    rows = []
    for name, one in single.items():
        cells = [name]
        for size in BATCHES:
            per_state = median(f"{name}: batch {size}")
            cells.append(f"{per_state:.2f} ({per_state / median(one):.2f}x)")
        rows.append(cells)
    print_table(["machine", *(f"{size}" for size in BATCHES)], rows)
    print()
    cet = "CET200 (family core)"
    target = ratio(f"{cet}: state", peer)
    excavator_ratio = ratio("excavator: Excavator.state", peer)
    print(f"CET200 family state / the excavator's plain numba pose: {target:.2f}")
    # On a loaded machine one preempted round moves a median ratio; the best rounds' ratio does not.
    best = min(r[f"{cet}: state"] for r in rounds) / min(r[peer] for r in rounds)
    print(f"(the same, fastest round of each: {best:.2f})")
    print(f"(the excavator's own state / that peer: {excavator_ratio:.2f})")
    worst = max(
        median(f"{name}: batch {size}") / median(one) for name, one in single.items() for size in BATCHES
    )
    targets = [
        ("CET200 family state one call <= 2x a plain numba pose (median ratio)", target <= 2.0),
        ("no batch slower per state than a single call (issue 32)", worst <= 1.0),
    ]
    for what, met in targets:
        print(f"target {what:<70} {'met' if met else 'MISSED'}")


if __name__ == "__main__":
    main()
