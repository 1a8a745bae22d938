"""Benchmark (not a test): tool changer closed-form IK and the shared chain's FK + Jacobian, against
Robotics Toolbox for Python and Pinocchio on the same standard D-H model, in one run.

Rows (medians over ``--rounds`` rounds; each round times the peers, then ours, so machine drift hits
both alike, and the ratios are medians of per-round ratios):
* IK: ours (all 8 solutions + selection) one target per call (the compiled kernel, and the numpy
  path with ``compiled=False``) and batched (10^5 targets), against RTB's ``ikine_LM`` (Python)
  and ``ik_LM`` (C++), one answer each from a random in-limit seed;
* FK + Jacobian: ours (``SerialChain.fkine_jacob0``, both from one walk, its compiled kernel loaded
  first) one configuration per call and one batched call of 10^5; RTB ``DHRobot.fkine``/``jacob0``
  and its C-backed ETS; Pinocchio ``forwardKinematics`` + ``computeJointJacobians`` + frame
  Jacobian in a Python loop; FK alone, ours (``fkine``) against Pinocchio's ``forwardKinematics``
  + ``updateFramePlacement``.

RTB and Pinocchio are not dependencies of the project: they run in their own venv, as in
bench_scara_ik.py (``$MK_BENCH_PYTHON`` names an interpreter that has ``roboticstoolbox`` and
``pinocchio``; otherwise ``/tmp/tool_changer_bench_venv`` is created with pip on first use).

Run: .venv/bin/python benchmarks/bench_tool_changer_ik.py [--rounds 3] [--batch 100000]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from peer_venv import run_worker

REPO = Path(__file__).resolve().parent.parent
VENV = Path(os.environ.get("MK_BENCH_VENV", "/tmp/tool_changer_bench_venv"))
PACKAGES = ("roboticstoolbox-python", "pin")


def per_call(function, items, repeat: int = 1) -> float:
    """Median microseconds of ``function(item)`` over the items."""
    import numpy as np

    times = np.empty(len(items))
    for i, item in enumerate(items):
        start = time.perf_counter_ns()
        for _ in range(repeat):
            function(item)
        times[i] = (time.perf_counter_ns() - start) / 1e3 / repeat
    return float(np.median(times))


# ---- peers, in their own interpreter (no project imports there) -----------------------------------
def peer_worker() -> None:
    """Reads the D-H rows, targets, seeds and joint samples as JSON; prints timings as JSON."""
    import numpy as np
    import pinocchio as pin
    import roboticstoolbox as rtb
    from spatialmath import SE3

    job = json.load(sys.stdin)
    rows = job["rows"]
    robot = rtb.DHRobot(
        [
            rtb.RevoluteDH(a=r["a"], alpha=r["alpha"], d=r["d"], qlim=lim)
            for r, lim in zip(rows, job["qlim"], strict=True)
        ],
        name="tool_changer",
    )
    ets = robot.ets()
    # Pinocchio: joint i+1 sits at the fixed part Tz(d_i) Tx(a_i) Rx(alpha_i) of row i; the tool frame
    # at that of the last row.
    model = pin.Model()
    parent = 0
    placement = pin.SE3.Identity()
    for i, r in enumerate(rows):
        parent = model.addJoint(parent, pin.JointModelRZ(), placement, f"j{i + 1}")
        fixed = SE3.Tz(r["d"]) * SE3.Tx(r["a"]) * SE3.Rx(r["alpha"])
        placement = pin.SE3(fixed.R, fixed.t)
    tool = model.addFrame(pin.Frame("tool", parent, placement, pin.FrameType.OP_FRAME))
    data = model.createData()
    world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def pin_fk_jacobian(q):
        pin.forwardKinematics(model, data, q)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacement(model, data, tool)
        return data.oMf[tool], pin.getFrameJacobian(model, data, tool, world)

    def pin_fk(q):
        pin.forwardKinematics(model, data, q)
        return pin.updateFramePlacement(model, data, tool)

    q_all = np.array(job["q"])
    single = q_all[: job["single"]]
    out = {"rtb": rtb.__version__, "pin": pin.__version__, "rounds": []}
    check_q = single[0]
    oMf, jac = pin_fk_jacobian(check_q)
    pose_ref, jacobian_ref = (np.array(m) for m in job["check"])
    out["check"] = {
        "pinocchio": float(max(np.abs(oMf.homogeneous - pose_ref).max(), np.abs(jac - jacobian_ref).max())),
        "rtb_ets": float(
            max(
                np.abs(ets.fkine(check_q).A - pose_ref).max(),
                np.abs(ets.jacob0(check_q) - jacobian_ref).max(),
            )
        ),
    }
    poses = [SE3(np.array(T), check=False) for T in job["targets"]]
    seeds = np.array(job["seeds"])
    for _ in range(job["rounds"]):
        result = {}
        result["rtb_dh"] = per_call(lambda q: (robot.fkine(q), robot.jacob0(q)), single[:300])
        result["rtb_ets"] = per_call(lambda q: (ets.fkine(q), ets.jacob0(q)), single)
        result["pin"] = per_call(pin_fk_jacobian, single)
        result["pin_fk"] = per_call(pin_fk, single)
        start = time.perf_counter()
        for q in q_all:
            ets.fkine(q)
            ets.jacob0(q)
        result["rtb_ets_batch"] = time.perf_counter() - start
        start = time.perf_counter()
        for q in q_all:
            pin_fk_jacobian(q)
        result["pin_batch"] = time.perf_counter() - start
        for name in ("ikine_LM", "ik_LM"):
            solve = getattr(robot, name)
            micro, found, errors = [], 0, []
            for pose, seed in zip(poses, seeds, strict=True):
                start = time.perf_counter_ns()
                solution = solve(pose, q0=seed, joint_limits=True)
                micro.append((time.perf_counter_ns() - start) / 1e3)
                found += bool(solution.success)
                if solution.success:
                    errors.append(float(np.abs(robot.fkine(solution.q).A - pose.A).max()))
            result[name] = {
                "micro": float(np.median(micro)),
                "success": found / len(poses),
                "max_error": max(errors, default=float("nan")),
            }
        out["rounds"].append(result)
    json.dump(out, sys.stdout)


def run_peers(job: dict) -> tuple[dict | None, str]:
    return run_worker(
        __file__,
        "--peer-worker",
        job,
        PACKAGES,
        "import roboticstoolbox, pinocchio",
        VENV,
        "MK_BENCH_PYTHON",
        timeout=3600,
    )


# ---- the project's side ----------------------------------------------------------------------------
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--batch", type=int, default=100_000, help="targets / configurations per batch")
    parser.add_argument("--single", type=int, default=2000, help="one-call samples per row")
    parser.add_argument("--ik-targets", type=int, default=200, help="targets for the numerical IKs")
    args = parser.parse_args()

    import numpy as np

    sys.path.insert(0, str(REPO))
    from manipulator_kinematics.serial_chain import compiled_kernel
    from tool_changer_kinematics.kinematics import ToolChanger

    arm = ToolChanger.default()
    chain = arm.chain
    compiled_kernel(wait=True)  # the chain's compiled kernel, as it runs once loaded
    rng = np.random.default_rng(2023)
    q = rng.uniform(arm.limits.lower, arm.limits.upper, (args.batch, 6))
    T = arm.fkine(q)
    seeds = rng.uniform(arm.limits.lower, arm.limits.upper, (args.batch, 6))
    single = q[: args.single]
    job = {
        "rows": [{"a": r.a, "alpha": r.alpha, "d": r.d} for r in chain.rows],
        "qlim": np.column_stack([arm.limits.lower, arm.limits.upper]).tolist(),
        "q": q.tolist(),
        "single": args.single,
        "rounds": 1,
        "targets": T[: args.ik_targets].tolist(),
        "seeds": seeds[: args.ik_targets].tolist(),
        "check": [m.tolist() for m in chain.fkine_jacob0(single[0])],
    }
    arm.compiled_kernel(wait=True)  # numba loads (or compiles) the single-call kernel before timing
    ours, rounds, peers, why = [], [], None, ""
    for _ in range(args.rounds):
        # Peers and ours alternate round by round, so the ratios compare times measured minutes,
        # not a quarter of an hour, apart on a shared machine; the tables quote medians of them.
        if why == "":
            peers, why = run_peers(job)
            if peers is not None:
                rounds += peers["rounds"]
        r = {}
        r["ik_one"] = per_call(lambda i: arm.solve_ik(T[i], seed=seeds[i]), range(args.single))
        r["ik_one_numpy"] = per_call(
            lambda i: arm.solve_ik(T[i], seed=seeds[i], compiled=False), range(args.single // 4)
        )
        start = time.perf_counter()
        batch = arm.solve_ik(T, seed=seeds)
        r["ik_batch"] = time.perf_counter() - start
        found = np.isfinite(batch.q).all(axis=-1)
        reached = arm.fkine(np.where(found[..., None], batch.q, 0.0))
        r["ik_error"] = float(np.where(found, np.abs(reached - T[:, None]).max(axis=(-2, -1)), 0.0).max())
        r["fkj_one"] = per_call(chain.fkine_jacob0, single)
        r["fk_one"] = per_call(chain.fkine, single)
        start = time.perf_counter()
        chain.fkine_jacob0(q)
        r["fkj_batch"] = time.perf_counter() - start
        ours.append(r)

    def med(values) -> float:
        return float(np.median(list(values)))

    n = args.batch
    ik_one, ik_batch = med(r["ik_one"] for r in ours), med(r["ik_batch"] for r in ours)
    rows = [
        (
            "IK, ours: all 8 solutions + selection, one target per call",
            f"{ik_one:.1f} us",
            f"max FK(IK) error {max(r['ik_error'] for r in ours):.1e}",
        ),
        (
            "IK, ours: one target per call, numpy path (compiled=False)",
            f"{med(r['ik_one_numpy'] for r in ours):.1f} us",
            "the reference the kernel is tested against",
        ),
        (f"IK, ours: batch of {n}", f"{ik_batch:.3f} s", f"{n / ik_batch:,.0f} poses/s (target >= 200,000)"),
    ]
    fkj_one, fkj_batch = med(r["fkj_one"] for r in ours), med(r["fkj_batch"] for r in ours)
    rows += [
        (
            "FK + Jacobian, ours (SerialChain.fkine_jacob0), one call",
            f"{fkj_one:.2f} us",
            "target <= Pinocchio's",
        ),
        ("FK, ours (SerialChain.fkine), one call", f"{med(r['fk_one'] for r in ours):.2f} us", ""),
        (f"FK + Jacobian, ours, one batched call of {n}", f"{fkj_batch:.3f} s", ""),
    ]
    if peers is None:
        rows.append(("Robotics Toolbox / Pinocchio", "-", why))
    else:
        pairs = list(zip(rounds, ours, strict=True))
        for name, label in (("ikine_LM", "ikine_LM (Python)"), ("ik_LM", "ik_LM (C++)")):
            micro = med(p[name]["micro"] for p in rounds)
            per_call_ratio = med(p[name]["micro"] / o["ik_one"] for p, o in pairs)
            batch_ratio = med(p[name]["micro"] / (o["ik_batch"] / n * 1e6) for p, o in pairs)
            target = " (target >= 50x)" if name == "ikine_LM" else ""
            if name == "ik_LM":
                share = med(o["ik_one"] / p[name]["micro"] for p, o in pairs)
                target = f"; ours / this = {share:.3f} (target <= 0.5)"
            rows.append(
                (
                    f"IK, RTB {peers['rtb']} {label}, one answer",
                    f"{micro:.1f} us",
                    f"ours {per_call_ratio:.0f}x faster per call{target}, {batch_ratio:.0f}x batched; "
                    f"solved {rounds[0][name]['success']:.0%}",
                )
            )
        rows += [
            ("FK + Jacobian, RTB DHRobot fkine + jacob0", f"{med(p['rtb_dh'] for p in rounds):.1f} us", ""),
            (
                "FK + Jacobian, RTB ETS (C) fkine + jacob0",
                f"{med(p['rtb_ets'] for p in rounds):.1f} us",
                f"max |difference| to ours {peers['check']['rtb_ets']:.0e}",
            ),
            (f"FK + Jacobian, RTB ETS, loop of {n}", f"{med(p['rtb_ets_batch'] for p in rounds):.3f} s", ""),
            (
                f"FK + Jacobian, Pinocchio {peers['pin']}",
                f"{med(p['pin'] for p in rounds):.2f} us",
                f"max |difference| to ours {peers['check']['pinocchio']:.0e}; ours one call / this = "
                f"{med(o['fkj_one'] / p['pin'] for p, o in pairs):.2f} (target <= 1)",
            ),
            (
                "FK, Pinocchio forwardKinematics + updateFramePlacement",
                f"{med(p['pin_fk'] for p in rounds):.2f} us",
                f"ours one call / this = {med(o['fk_one'] / p['pin_fk'] for p, o in pairs):.2f}",
            ),
            (
                f"FK + Jacobian, Pinocchio, loop of {n}",
                f"{med(p['pin_batch'] for p in rounds):.3f} s",
                "ours batched / Pinocchio loop = "
                f"{med(o['fkj_batch'] / p['pin_batch'] for p, o in pairs):.2f} "
                "(target <= 1)",
            ),
        ]
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"\nTool changer benchmark: {os.cpu_count()} cores (load {load}), Python {sys.version.split()[0]}, "
        f"numpy {np.__version__}; medians over {args.rounds} rounds.\n"
    )
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    header = ("what", "time", "notes")
    print("| " + " | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for row in rows:
        print("| " + " | ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) + " |")


if __name__ == "__main__":
    if "--peer-worker" in sys.argv:
        peer_worker()
    else:
        main()
