"""Benchmark (not a test): SCARA closed-form IK against a numerical IK on the same model.

Prints one table: microseconds per IK in the library (one target per call: the compiled kernel
of every mode and the numpy path beside it, and ``solve_ik`` on a 4x4 pose; and per target in
one batched call), per SolveIK service call across processes (p50 / p99), and a numerical
baseline on the same D-H model: Robotics Toolbox for Python's ``ikine_LM`` (and its C++
``ik_LM``), or, when the toolbox cannot be had, a damped-least-squares Newton IK of our own on the
same chain. Speed-ups are against the library's one-target call in the same mode (``phi``: the
numerical solvers get the full planar pose x, y, yaw); the last line gives the library's one call
(mode phi, ``solve_ik``, mode position) as a fraction of ``ik_LM`` (target: <= 0.5). ``--rounds``
rounds: one-target timings the median of each round's median, batches the median of the rounds.

The Robotics Toolbox is not a dependency of the project: it is installed for this benchmark only,
into its own venv (``$MK_RTB_PYTHON`` names an interpreter that has it; otherwise
``~/.cache/manipulator_kinematics/bench-rtb-venv`` is created with pip on first use). If that
fails, the table says so and the damped-least-squares fallback is measured instead.

Run: .venv/bin/python benchmarks/bench_scara_ik.py [--calls 1000] [--targets 2000] [--rounds 3] [--no-rtb]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

from peer_venv import run_worker

REPO = Path(__file__).resolve().parent.parent
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
RTB_VENV = CACHE / "manipulator_kinematics" / "bench-rtb-venv"
RTB_PACKAGE = "roboticstoolbox-python"


# ---- numerical baseline in the Robotics Toolbox's interpreter (no project imports there) -------
def rtb_worker() -> None:
    """Reads the model, targets and seeds as JSON on stdin; prints timings and errors as JSON."""
    import numpy as np
    import roboticstoolbox as rtb
    from spatialmath import SE3

    job = json.load(sys.stdin)
    links = []
    for row, (lower, upper) in zip(job["rows"], job["qlim"], strict=True):
        common = {"a": row["a"], "alpha": row["alpha"], "offset": row["offset"], "qlim": [lower, upper]}
        if row["prismatic"]:
            links.append(rtb.PrismaticDH(theta=row["theta"], **common))
        else:
            links.append(rtb.RevoluteDH(d=row["d"], **common))
    robot = rtb.DHRobot(links, base=SE3(np.array(job["base"])), name="scara")
    mask = [1, 1, 0, 0, 0, 1]  # x, y, yaw: the planar pose
    poses = [SE3.Trans(x, y, 0.0) * SE3.Rz(phi) for x, y, phi in job["targets"]]
    out = {"version": rtb.__version__}
    for name in ("ikine_LM", "ik_LM"):
        solve = getattr(robot, name, None)
        if solve is None:
            continue
        micro, errors, found = [], [], 0
        for pose, seed in zip(poses, job["seeds"], strict=True):
            start = time.perf_counter_ns()
            solution = solve(pose, q0=np.array(seed), mask=np.array(mask, dtype=float), joint_limits=True)
            micro.append((time.perf_counter_ns() - start) / 1e3)
            found += bool(solution.success)
            if solution.success:
                errors.append(float(np.linalg.norm(robot.fkine(solution.q).t[:2] - pose.t[:2])))
        out[name] = {
            "micro": micro,
            "success": found / len(poses),
            "max_error": max(errors, default=math.nan),
        }
    json.dump(out, sys.stdout)


def run_rtb(job: dict) -> tuple[dict | None, str]:
    """Timings from the Robotics Toolbox, or None and the reason it is unavailable."""
    return run_worker(
        __file__,
        "--rtb-worker",
        job,
        (RTB_PACKAGE,),
        "import roboticstoolbox",
        RTB_VENV,
        "MK_RTB_PYTHON",
        timeout=1800,
    )


# ---- the project's side -------------------------------------------------------------------------
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=1000, help="service calls")
    parser.add_argument("--targets", type=int, default=2000, help="one-target library calls per mode")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the one-target calls")
    parser.add_argument("--baseline-targets", type=int, default=300, help="targets for the numerical IKs")
    parser.add_argument("--no-rtb", action="store_true", help="skip the Robotics Toolbox (no install)")
    parser.add_argument("--no-service", action="store_true", help="skip the cross-process service calls")
    args = parser.parse_args()

    import numpy as np

    sys.path.insert(0, str(REPO))
    from scara_kinematics.kinematics import MODES, Scara, compiled_kernel

    scara = Scara.default()
    compiled_kernel(scara, wait=True)  # loaded (or compiled once) before any timing
    rng = np.random.default_rng(2019)
    q = rng.uniform(scara.limits.lower, scara.limits.upper, (400_000, 3))
    q = q[scara.within_limits(q) & ~scara.singular(q)]
    fixed = q.copy()
    fixed[:, 2] = math.pi / 2 - fixed[:, 1]
    fixed = fixed[scara.within_limits(fixed) & ~scara.singular(fixed)]
    rows: list[tuple[str, str, str, str]] = []  # what, us per IK, p99 / note, speed-up

    def targets_for(mode: str, n: int) -> tuple[np.ndarray, np.ndarray]:
        x = scara.fk((fixed if mode == "fixed_phi" else q)[:n])
        return x[:, :2], x[:, 2]

    def solve(
        mode: str, p: np.ndarray, phi: np.ndarray, seed: np.ndarray | None = None, compiled: bool = True
    ):
        return scara.ik(p, mode=mode, phi=phi if mode == "phi" else None, seed=seed, compiled=compiled)

    def one_call(call, n: int) -> tuple[float, float]:
        """(median of the rounds' medians, p99 over every call) in microseconds."""
        for i in range(50):  # warm-up
            call(i)
        medians, timings = [], np.empty((args.rounds, n))
        for r in range(args.rounds):
            for i in range(n):
                start = time.perf_counter_ns()
                result = call(i)
                timings[r, i] = (time.perf_counter_ns() - start) / 1e3
                assert bool(result.ok), result.note() if hasattr(result, "note") else result.reason()
            medians.append(np.median(timings[r]))
        return float(np.median(medians)), float(np.percentile(timings, 99))

    scalar: dict[str, float] = {}
    for mode, compiled in (
        ("fixed_phi", True),
        ("phi", True),
        ("position", True),
        ("fixed_phi", False),
        ("phi", False),
        ("position", False),
    ):
        p, phi = targets_for(mode, args.targets)
        seeds = q[-args.targets :]
        median, p99 = one_call(
            lambda i, p=p, phi=phi, s=seeds, m=mode, c=compiled: solve(m, p[i], phi[i], s[i], c), len(p)
        )
        path = "compiled kernel" if compiled else "numpy path"
        scalar[mode if compiled else f"{mode}, numpy path"] = median
        rows.append(
            (f"library, one target per call, mode {mode} ({path})", f"{median:.1f}", f"p99 {p99:.1f}", "")
        )
    poses = scara.fkine(q[: args.targets])
    median, p99 = one_call(lambda i: scara.solve_ik(poses[i], seed=q[-1 - i]), len(poses))
    scalar["solve_ik"] = median
    rows.append(
        ("library, solve_ik(4x4 pose), one target per call, mode phi", f"{median:.1f}", f"p99 {p99:.1f}", "")
    )
    batch: dict[str, float] = {}
    for mode in MODES:
        p, phi = targets_for(mode, 100_000)
        seeds = q[-len(p) :]
        rounds = []
        for _ in range(args.rounds):
            start = time.perf_counter()
            result = solve(mode, p, phi, seeds)
            rounds.append((time.perf_counter() - start) / len(p) * 1e6)
        per_target = batch[mode] = float(np.median(rounds))
        error = np.abs(scara.fk(result.q)[:, :2] - p).max()
        rows.append(
            (
                f"library, batch of {len(p)}, mode {mode}",
                f"{per_target:.2f}",
                f"all solved: {bool(result.ok.all())}, max |FK(IK(p)) - p| {error:.1e} m",
                "",
            )
        )

    if not args.no_service:
        rows += service_rows(scara, targets_for("phi", args.calls), args.calls)

    # Numerical baselines on the same model, mode phi (target x, y, yaw), seeds random within limits.
    n = args.baseline_targets
    p, phi = targets_for("phi", n)
    seeds = rng.uniform(scara.limits.lower, scara.limits.upper, (n, 3))
    reference, batched = scalar["phi"], batch["phi"]
    chain = scara.chain
    ratio = ""
    if not args.no_rtb:
        job = {
            "rows": [
                {
                    "a": r.a,
                    "alpha": r.alpha,
                    "d": r.d,
                    "theta": r.theta,
                    "offset": r.offset,
                    "prismatic": r.prismatic,
                }
                for r in chain.rows
            ],
            "qlim": np.column_stack([scara.limits.lower, scara.limits.upper]).tolist(),
            "base": chain.base.tolist(),
            "targets": np.column_stack([p, phi]).tolist(),
            "seeds": seeds.tolist(),
        }
        measured, why = run_rtb(job)
        if measured is None:
            rows.append(("Robotics Toolbox ikine_LM", "-", why, "-"))
        else:
            for name, label in (("ikine_LM", "ikine_LM (Python)"), ("ik_LM", "ik_LM (C++)")):
                if name in measured:
                    m = measured[name]
                    median = float(np.median(m["micro"]))
                    rows.append(
                        (
                            f"Robotics Toolbox {measured['version']} {label}, same D-H model",
                            f"{median:.1f}",
                            f"solved {m['success']:.0%}, max error {m['max_error']:.1e} m",
                            f"{median / reference:.0f}x / {median / batched:.0f}x",
                        )
                    )
                    if name == "ik_LM":
                        ratio = (
                            f"library one call / ik_LM: ik {reference / median:.2f}, "
                            f"solve_ik {scalar['solve_ik'] / median:.2f}, mode position "
                            f"{scalar['position'] / median:.2f} (numpy path "
                            f"{scalar['position, numpy path'] / median:.2f}) (target <= 0.5)"
                        )
    if not any(row[0].startswith("Robotics Toolbox") and row[1] != "-" for row in rows):
        # Fallback baseline: a plain numerical IK of our own on the same D-H chain.
        dls = [dls_ik(chain, scara, np.array([p[i, 0], p[i, 1], phi[i]]), seeds[i]) for i in range(n)]
        micro = np.array([d[0] for d in dls])
        solved = np.array([d[1] for d in dls])
        median = float(np.median(micro))
        rows.append(
            (
                "fallback: own damped least squares Newton on the same D-H chain",
                f"{median:.1f}",
                f"solved {solved.mean():.0%} (tol 1e-10, 100 iterations, one start, no restarts)",
                f"{median / reference:.0f}x / {median / batched:.0f}x",
            )
        )

    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    python = sys.version.split()[0]
    print(
        f"\nSCARA IK benchmark: {os.cpu_count()} cores (load average {load}), Python {python}, "
        f"numpy {np.__version__}.\nTimes are medians in microseconds per IK. Speed-up of the library in "
        f"mode phi: one target per call ({reference:.1f} us) / batched ({batched:.2f} us per target).\n"
    )
    header = ("what", "us/IK", "notes", "library speed-up (one / batch)")
    widths = [max(len(r[i]) for r in [*rows, header]) for i in range(4)]
    print("| " + " | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for row in rows:
        print("| " + " | ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) + " |")
    if ratio:
        print(f"\n{ratio}")


def service_rows(scara, targets, calls: int) -> list[tuple[str, str, str, str]]:
    """SolveIK round trips against a real scara_ik_server process on an isolated ROS domain."""
    import numpy as np

    sys.path.insert(0, str(REPO / "test"))
    import conftest  # noqa: F401 - reserves an unused ROS_DOMAIN_ID and keeps discovery on localhost
    from ros_harness import NodeProcess, Probe

    from manipulator_kinematics.param_files import config_path
    from manipulator_kinematics.planar import yaw_quaternion
    from manipulator_kinematics_interfaces.srv import SolveIK

    probe = Probe("bench_scara_probe")
    process = NodeProcess("scara_ik_server", "--params-file", str(config_path("scara.yaml")))
    try:
        client = probe.node.create_client(SolveIK, "solve_ik")
        probe.wait_until(client.service_is_ready, 30.0, "solve_ik")
        p, phi = targets
        micro = np.empty(calls)
        worst = 0.0
        for i in range(-20, calls):  # 20 warm-up calls
            k = i % len(p)
            request = SolveIK.Request(mode="phi", use_orientation=True)
            request.target.pose.position.x, request.target.pose.position.y = float(p[k, 0]), float(p[k, 1])
            o = request.target.pose.orientation
            o.x, o.y, o.z, o.w = (float(v) for v in yaw_quaternion(phi[k]))
            start = time.perf_counter_ns()
            response = probe.call(client, request, 10.0, "SolveIK response")
            elapsed = (time.perf_counter_ns() - start) / 1e3
            assert response.success, response.message
            if i >= 0:
                micro[i] = elapsed
                expected = scara.ik(p[k], mode="phi", phi=phi[k]).q
                worst = max(worst, float(np.abs(np.array(response.solution.position) - expected).max()))
    finally:
        process.stop()
        probe.close()
    return [
        (
            f"SolveIK service across processes, {calls} calls, mode phi",
            f"{np.median(micro):.0f}",
            f"p99 {np.percentile(micro, 99):.0f}; max |service - library| {worst:.0e}",
            "",
        )
    ]


def dls_ik(chain, scara, target, seed, tol: float = 1e-10, iterations: int = 100) -> tuple[float, bool]:
    """Damped least squares Newton on the D-H chain for (x, y, yaw); (microseconds, solved)."""
    import numpy as np

    start = time.perf_counter_ns()
    q = seed.astype(float).copy()
    damping = 1e-3
    solved = False
    for _ in range(iterations):
        T = chain.fkine(q)
        error = np.array(
            [
                target[0] - T[0, 3],
                target[1] - T[1, 3],
                math.remainder(target[2] - math.atan2(T[1, 0], T[0, 0]), 2 * math.pi),
            ]
        )
        if np.abs(error).max() < tol:
            q[1:] = [math.remainder(v, 2 * math.pi) for v in q[1:]]
            solved = bool(scara.within_limits(q))
            break
        J = chain.jacob0(q)[[0, 1, 5]]
        q = q + J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(3), error)
    return (time.perf_counter_ns() - start) / 1e3, solved


if __name__ == "__main__":
    if "--rtb-worker" in sys.argv:
        rtb_worker()
    else:
        main()
