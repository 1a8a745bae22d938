"""Benchmark (not a test): each machine's one call and batches against its peers at their fastest
documented call paths, and every batch API against single calls; Markdown tables on stdout.

Everything runs in one process, the peers' venv (``$MK_BENCH_PYTHON``, else
``/tmp/tool_changer_bench_venv``, created with pip on first use: Robotics Toolbox, Pinocchio and the
project's numba; the project itself is imported from this checkout), so ours and a peer's calls
alternate in the same process: per round, each case times ours and the peer in turn (the order
swapped every round), each side's time the median of several blocks of calls, in the thread's CPU
time (``time.thread_time_ns`` around a block; on the shared machine wall time counts the other
processes' turns). Figures are medians over ``--rounds`` rounds, ratios the median of the
per-round ratios with their range (min-max). The same robot is checked equal in both before any
timing (FK and Jacobian to 1e-12; the IK answers reach the target).

Peers, at their fastest documented call paths (printed with the tables):

* Pinocchio (``pin``): ``computeFrameJacobian(model, data, q, frame, LOCAL_WORLD_ALIGNED)``, which
  runs the forward pass itself and leaves the frame's placement in ``data.oMf[frame]`` (Pinocchio's
  frames.hpp), and, as its examples show, ``forwardKinematics`` + ``computeJointJacobians`` +
  ``updateFramePlacement`` + ``getFrameJacobian``; the faster of the two is the ratio's reference.
* Robotics Toolbox (``roboticstoolbox-python``): the C++ solvers of the robot's ETS, built once,
  ``ets.ik_LM(T, q0=seed, tol=IK_TOL, joint_limits=True)`` (SCARA: ``mask`` x, y, yaw), IK_TOL
  chosen so the answers reach the targets to about 1e-12 m (ours: 1e-15); the FK + Jacobian of the
  ETS, ``ets.fkine`` + ``ets.jacob0``. A peer has no batch call: its batch is N single calls.

``--readme`` prints only the README's table (each machine's one call and a batch of 1000 against
each peer, how it was measured); ``--readme --write`` puts it into README.md between its markers.

Run: .venv/bin/python benchmarks/bench_peers.py [--rounds 5] [--largest 100000] [--readme [--write]]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import textwrap
import time
from pathlib import Path

from peer_venv import run_worker

REPO = Path(__file__).resolve().parent.parent
VENV = Path(os.environ.get("MK_BENCH_VENV", "/tmp/tool_changer_bench_venv"))
PACKAGES = ("roboticstoolbox-python", "pin", "numba==0.68.1", "PyYAML")
SIZES = (1, 2, 5, 10, 30, 100, 1000, 10_000, 100_000)
IK_TOL = 1e-24  # ik_LM's E = e' We e / 2: 1e-24 gives errors of about 1e-12 m
BLOCK_US = 2000.0  # a timed block's length, about (several calls: thread_time_ns costs ~1 us)
README_BATCH = 1000  # the README table's batch: ours per state in one call of this many
README = REPO / "README.md"
MARKERS = ("<!-- bench_peers --readme: begin -->", "<!-- bench_peers --readme: end -->")
#: The README table's machine and call of each case.
README_ROWS = {
    "tool changer FK + Jacobian": ("tool changer (6R)", "FK + Jacobian"),
    "tool changer IK (all 8 + selection)": ("tool changer (6R)", "IK, all 8 + selection"),
    "SCARA solve_ik (the service's entry)": ("SCARA", "`solve_ik` (the service's entry)"),
    "SCARA ik()": ("SCARA", "`ik()`"),
}
#: The peers' calls in the README table (CALLS, shortened).
SHORT = {
    "pin_cfj": "Pinocchio `computeFrameJacobian`",
    "pin_doc": "Pinocchio `forwardKinematics` + `computeJointJacobians` + `getFrameJacobian`",
    "rtb_fkj": "RTB `ets.fkine` + `ets.jacob0`",
    "rtb_ik": "RTB C++ `ets.ik_LM`",
    "rtb_ik_mask": "RTB C++ `ets.ik_LM` (mask x, y, yaw)",
}
CALLS = {
    "pin_cfj": "pin.computeFrameJacobian(model, data, q, frame, LOCAL_WORLD_ALIGNED); data.oMf[frame]",
    "pin_doc": "pin.forwardKinematics; pin.computeJointJacobians; pin.updateFramePlacement; "
    "pin.getFrameJacobian(..., LOCAL_WORLD_ALIGNED)",
    "rtb_fkj": "ets = robot.ets() once; ets.fkine(q); ets.jacob0(q)",
    "rtb_ik": f"ets = robot.ets() once; ets.ik_LM(T, q0=seed, tol={IK_TOL:g}, joint_limits=True)",
    "rtb_ik_mask": f"ets.ik_LM(T, q0=seed, tol={IK_TOL:g}, mask=[1, 1, 0, 0, 0, 1], joint_limits=True)",
}


def cpu_us(function, items, calls: int) -> float:
    """Microseconds of CPU time per call of ``function(item)`` over ``calls`` calls (items in turn)."""
    start = time.thread_time_ns()
    for i in range(calls):
        function(items[i % len(items)])
    return (time.thread_time_ns() - start) / 1e3 / calls


def calibrated(function, items) -> int:
    """Calls per block: about BLOCK_US of CPU time, at least 1."""
    once = cpu_us(function, items, min(len(items), 20))
    return max(1, int(BLOCK_US / max(once, 0.05)))


class Case:
    """Sides timed in turn: {name: (function, items)}; per round, each side's median block."""

    def __init__(self, sides: dict) -> None:
        self.sides = sides
        self.calls = {name: calibrated(f, items) for name, (f, items) in sides.items()}
        self.rounds: list[dict[str, float]] = []

    def round(self, index: int, blocks: int = 3) -> None:
        names = list(self.sides) if index % 2 == 0 else list(self.sides)[::-1]
        times = {name: [] for name in names}
        for _ in range(blocks):
            for name in names:
                function, items = self.sides[name]
                times[name].append(cpu_us(function, items, self.calls[name]))
        self.rounds.append({name: sorted(t)[len(t) // 2] for name, t in times.items()})

    def median(self, name: str) -> float:
        values = sorted(r[name] for r in self.rounds)
        return values[len(values) // 2]

    def ratio(self, ours: str, theirs: str) -> tuple[float, float, float]:
        values = sorted(r[ours] / r[theirs] for r in self.rounds)
        return values[len(values) // 2], values[0], values[-1]


def shown(micro: float) -> str:
    return f"{micro:.3g} us" if micro < 1e4 else f"{micro / 1e3:.3g} ms"


def ratio_text(value: float) -> str:
    """A ratio to two decimals, or two significant digits below 0.1."""
    return f"{value:.2f}" if value >= 0.1 else f"{value:.2g}"


def spread(ratio: tuple[float, float, float]) -> str:
    return f"{ratio[0]:.2f} ({ratio[1]:.2f}-{ratio[2]:.2f})"


# ---- the worker: everything timed in one process, the peers' venv ------------------------------
def worker() -> None:
    import numpy as np
    import pinocchio as pin
    import roboticstoolbox as rtb
    from spatialmath import SE3

    job = json.load(sys.stdin)
    sys.path.insert(0, str(REPO))
    from bench_batch import apis as batch_apis

    from manipulator_kinematics import serial_chain
    from scara_kinematics.kinematics import Scara
    from scara_kinematics.kinematics import compiled_kernel as scara_kernel
    from tool_changer_kinematics.kinematics import ToolChanger

    largest = job["largest"]
    sizes = [n for n in SIZES if n <= largest]
    rng = np.random.default_rng(32)
    serial_chain.compiled_kernel(wait=True)

    # -- tool changer: the same arm in Pinocchio and RTB, checked equal
    arm = ToolChanger.default()
    arm.compiled_kernel(wait=True)
    chain = arm.chain
    lower, upper = arm.limits.lower, arm.limits.upper
    robot = rtb.DHRobot(
        [
            rtb.RevoluteDH(a=float(r.a), alpha=float(r.alpha), d=float(r.d), qlim=[lo, hi])
            for r, lo, hi in zip(chain.rows, lower, upper, strict=True)
        ],
        name="tool_changer",
    )
    ets = robot.ets()
    model, parent, placement = pin.Model(), 0, pin.SE3.Identity()
    for i, r in enumerate(chain.rows):  # joint i+1 at the fixed part Tz(d) Tx(a) Rx(alpha) of row i
        parent = model.addJoint(parent, pin.JointModelRZ(), placement, f"j{i + 1}")
        fixed = SE3.Tz(float(r.d)) * SE3.Tx(float(r.a)) * SE3.Rx(float(r.alpha))
        placement = pin.SE3(fixed.R, fixed.t)
    frame = model.addFrame(pin.Frame("tool", parent, placement, pin.FrameType.OP_FRAME))
    data, world = model.createData(), pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def pin_cfj(q):
        jacobian = pin.computeFrameJacobian(model, data, q, frame, world)
        return data.oMf[frame], jacobian

    def pin_doc(q):
        pin.forwardKinematics(model, data, q)
        pin.computeJointJacobians(model, data, q)
        return pin.updateFramePlacement(model, data, frame), pin.getFrameJacobian(model, data, frame, world)

    q = rng.uniform(lower, upper, (largest, 6))
    single = list(q[:500])
    equal = 0.0
    for sample in single[:100]:
        pose, jacobian = chain.fkine_jacob0(sample)
        for function in (pin_cfj, pin_doc):
            placement_, jac = function(sample)
            equal = max(equal, np.abs(placement_.homogeneous - pose).max(), np.abs(jac - jacobian).max())
        equal = max(
            equal, np.abs(ets.fkine(sample).A - pose).max(), np.abs(ets.jacob0(sample) - jacobian).max()
        )
    assert equal < 1e-12, equal
    count = min(2000, largest)  # IK targets timed one per call
    targets, seeds = arm.fkine(q[:count]), rng.uniform(lower, upper, (count, 6))
    ik_items = list(zip(targets, seeds, strict=True))
    errors, found, ours_errors = [], 0, []
    for target, seed in ik_items[:200]:
        solution = ets.ik_LM(target, q0=seed, tol=IK_TOL, joint_limits=True)
        found += bool(solution.success)
        if solution.success:
            errors.append(np.abs(ets.fkine(solution.q).A - target).max())
        ours = arm.solve_ik(target, seed=seed)
        if ours.selected >= 0:
            ours_errors.append(np.abs(arm.fkine(ours.q[ours.selected]) - target).max())
    tc_ik_note = (
        f"ik_LM found {found}/200, max error {max(errors):.1e}; ours {len(ours_errors)}/200, "
        f"max error {max(ours_errors):.1e}"
    )

    # -- SCARA: the same arm in RTB (mask x, y, yaw), checked equal
    scara = Scara.default()
    scara_kernel(scara, wait=True)
    sc = scara.chain
    links = []
    for r, lo, hi in zip(sc.rows, scara.limits.lower, scara.limits.upper, strict=True):
        common = {"a": float(r.a), "alpha": float(r.alpha), "offset": float(r.offset), "qlim": [lo, hi]}
        links.append(
            rtb.PrismaticDH(theta=float(r.theta), **common)
            if r.prismatic
            else rtb.RevoluteDH(d=float(r.d), **common)
        )
    scara_ets = rtb.DHRobot(links, base=SE3(sc.base), name="scara").ets()
    sq = rng.uniform(scara.limits.lower, scara.limits.upper, (largest, 3))
    assert max(np.abs(scara_ets.fkine(s).A - sc.fkine(s)).max() for s in sq[:100]) < 1e-12
    s_targets = scara.fkine(sq[:count])
    s_seeds = rng.uniform(scara.limits.lower, scara.limits.upper, (count, 3))
    s_items = list(zip(s_targets, s_seeds, strict=True))
    s_planar = [(np.array(T[:2, 3]), math.atan2(T[1, 0], T[0, 0]), s, T) for T, s in s_items]
    mask = np.array([1.0, 1.0, 0.0, 0.0, 0.0, 1.0])
    errors, found = [], 0
    for target, seed in s_items[:200]:
        solution = scara_ets.ik_LM(target, q0=seed, tol=IK_TOL, mask=mask, joint_limits=True)
        found += bool(solution.success)
        if solution.success:
            errors.append(np.abs(scara_ets.fkine(solution.q).A[:2, 3] - target[:2, 3]).max())
    scara_ik_note = f"ik_LM found {found}/200, max error {max(errors):.1e} m"

    nb = min(README_BATCH, count)  # ours as a batch, per state (README table)
    q_batch = np.ascontiguousarray(q[:nb])
    s_positions = np.ascontiguousarray(s_targets[:nb, :2, 3])
    s_phis = np.arctan2(s_targets[:nb, 1, 0], s_targets[:nb, 0, 0])
    peers = {
        "tool changer FK + Jacobian": Case(
            {
                "ours": (chain.fkine_jacob0, single),
                "batch": (lambda _: chain.fkine_jacob0(q_batch), [0]),
                "pin_cfj": (pin_cfj, single),
                "pin_doc": (pin_doc, single),
                "rtb_fkj": (lambda s: (ets.fkine(s), ets.jacob0(s)), single),
            }
        ),
        "tool changer IK (all 8 + selection)": Case(
            {
                "ours": (lambda item: arm.solve_ik(item[0], seed=item[1]), ik_items),
                "batch": (lambda _: arm.solve_ik(targets[:nb], seed=seeds[:nb]), [0]),
                "rtb_ik": (
                    lambda item: ets.ik_LM(item[0], q0=item[1], tol=IK_TOL, joint_limits=True),
                    ik_items,
                ),
            }
        ),
        "SCARA solve_ik (the service's entry)": Case(
            {
                "ours": (lambda item: scara.solve_ik(item[0], seed=item[1]), s_items),
                "batch": (lambda _: scara.solve_ik(s_targets[:nb], seed=s_seeds[:nb]), [0]),
                "rtb_ik_mask": (
                    lambda item: scara_ets.ik_LM(
                        item[0], q0=item[1], tol=IK_TOL, mask=mask, joint_limits=True
                    ),
                    s_items,
                ),
            }
        ),
        "SCARA ik()": Case(
            {
                "ours": (lambda item: scara.ik(item[0], phi=item[1], seed=item[2]), s_planar),
                "batch": (lambda _: scara.ik(s_positions, phi=s_phis, seed=s_seeds[:nb]), [0]),
                "rtb_ik_mask": (
                    lambda item: scara_ets.ik_LM(
                        item[3], q0=item[2], tol=IK_TOL, mask=mask, joint_limits=True
                    ),
                    s_planar,
                ),
            }
        ),
    }
    notes = {
        "tool changer IK (all 8 + selection)": tc_ik_note,
        "SCARA solve_ik (the service's entry)": scara_ik_note,
        "SCARA ik()": scara_ik_note,
        "tool changer FK + Jacobian": f"same arm: FK and Jacobian equal to {equal:.0e}",
    }

    # -- every batch API against N single calls (ours): bench_batch.py's list of them
    apis = {} if job.get("readme") else batch_apis(largest)
    for one, batch in apis.values():
        one(0), batch(2)
    batches = {}
    for name, (one, batch) in apis.items():
        items = list(range(min(500, largest)))
        sides = {"one": (one, items)}
        for n in sizes:
            sides[n] = (lambda _, n=n, batch=batch: batch(n), [0])
        batches[name] = Case(sides)
    for index in range(job["rounds"]):
        for case in (*peers.values(), *batches.values()):
            case.round(index)

    versions = {"roboticstoolbox": rtb.__version__, "pinocchio": pin.__version__, "numpy": np.__version__}
    out = {"versions": versions, "peers": [], "batches": [], "notes": notes, "readme": []}
    for what, case in peers.items():
        ours = case.median("ours")
        per_state = [r["batch"] / nb for r in case.rounds]  # ours as a batch of nb, per state
        for side in case.sides:
            if side in ("ours", "batch"):
                continue
            one_ratio = case.ratio("ours", side)
            out["peers"].append(
                [what, f"{ours:.3g} us", CALLS[side], f"{case.median(side):.3g} us", spread(one_ratio)]
            )
            batch_ratio = sorted(b / r[side] for b, r in zip(per_state, case.rounds, strict=True))
            out["readme"].append(
                [
                    *README_ROWS[what],
                    f"{ours:.3g} us",
                    SHORT[side],
                    f"{case.median(side):.3g} us",
                    f"**{ratio_text(one_ratio[0])}** ({ratio_text(one_ratio[1])}-{ratio_text(one_ratio[2])})",
                    f"{sorted(per_state)[len(per_state) // 2]:.3g} us",
                    f"**{ratio_text(batch_ratio[len(batch_ratio) // 2])}** "
                    f"({ratio_text(batch_ratio[0])}-{ratio_text(batch_ratio[-1])})",
                ]
            )
    for what, case in batches.items():
        one = case.median("one")
        row = [what, f"{one:.3g} us"]
        for n in sizes:
            per = [r[n] / (n * r["one"]) for r in case.rounds]
            row.append(f"{case.median(n) / n:.3g} ({sorted(per)[len(per) // 2]:.2f})")
        out["batches"].append(row)
    out["sizes"] = sizes
    json.dump(out, sys.stdout)


def readme_block(result: dict, rounds: int, load: str, versions: str) -> str:
    """The README's table (between MARKERS) and how it was measured."""
    from tables import table_text

    header = [
        "machine",
        "call",
        "ours, one call",
        "peer",
        "peer, one call",
        "ratio",
        f"ours, batch of {README_BATCH} (per state)",
        "ratio",
    ]
    return "\n".join(
        [
            MARKERS[0],
            *textwrap.wrap(
                f"Measured {time.strftime('%Y-%m-%d')} by "
                "`python benchmarks/bench_peers.py --readme --write`: "
                f"{os.cpu_count()} cores, load average (1, 5, 15 min) {load} (start-end); {versions}. "
                "Ours and the peer in one process, in turn; thread CPU time; medians of "
                f"{rounds} rounds; ratio = ours / peer, median (min-max) of the per-round ratios (< 1: "
                "ours is faster). The same robot in both, checked equal first; each peer at its fastest "
                "documented call (docs/benchmarks.md). A peer has no batch call: its batch of N costs N "
                "of its single calls, so the batch's ratio is ours per state / the peer's call.",
                width=100,
                break_on_hyphens=False,
            ),
            "",
            table_text(header, result["readme"]),
            MARKERS[1],
        ]
    )


def write_readme(block: str) -> None:
    """Replace what stands between the MARKERS in README.md with ``block``."""
    text = README.read_text(encoding="utf-8")
    begin, end = text.find(MARKERS[0]), text.find(MARKERS[1])
    if begin < 0 or end < begin:
        sys.exit(f"README.md has no {MARKERS[0]} ... {MARKERS[1]} block")
    README.write_text(text[:begin] + block + text[end + len(MARKERS[1]) :], encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--largest", type=int, default=100_000, help="the largest batch")
    parser.add_argument(
        "--readme", action="store_true", help="print only the README's table (one call and a batch per peer)"
    )
    parser.add_argument("--write", action="store_true", help="with --readme: put it into README.md")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker()
        return
    before = os.getloadavg()
    job = {"rounds": args.rounds, "largest": args.largest, "readme": args.readme}
    check = "import roboticstoolbox, pinocchio, numba"
    result, why = run_worker(__file__, "--worker", job, PACKAGES, check, VENV, "MK_BENCH_PYTHON", 7200)
    if result is None:
        sys.exit(why)
    from tables import print_table

    load = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in zip(before, os.getloadavg(), strict=True))
    versions = ", ".join(f"{k} {v}" for k, v in result["versions"].items())
    if args.readme:
        block = readme_block(result, args.rounds, load, versions)
        print(block)
        if args.write:
            write_readme(block)
        return
    print(
        f"Measured {time.strftime('%Y-%m-%d')}: {os.cpu_count()} cores, load average (1, 5, 15 min) {load} "
        f"(start-end); {versions}; one process, ours and the peer in turn, CPU time, medians of "
        f"{args.rounds} rounds; ratio = ours / peer, median (min-max) of the per-round ratios.\n"
    )
    print_table(["what", "ours", "peer called as", "peer", "ratio"], result["peers"])
    print()
    for what, note in result["notes"].items():
        print(f"* {what}: {note}")
    print(
        "\nEvery batch API against single calls: per state in us, (batch of N) / (N single calls) "
        "in brackets; <= 1 means the batch never costs more than single calls.\n"
    )
    print_table(["API", "one call", *[f"N={n}" for n in result["sizes"]]], result["batches"])


if __name__ == "__main__":
    main()
