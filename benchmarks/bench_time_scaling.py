"""Benchmark (not a test): the shared time scaling (manipulator_kinematics.time_scaling) against
toppra (time-optimal path parameterisation by reachability analysis) on the same paths and limits.

Paths: pump boom pours solved by the region IK (the typical slanted line at 100 mm, and zig-zag
pours of 2,000 and 20,000 points, the planner's MAX_POINTS), with the boom's joint speed limits,
tip speed 0.2 m/s, tip acceleration along the path 0.1 m/s^2.

Fair comparison: toppra gets the same samples as its grid (``gridpoints = s``), the path as its
cubic spline through them, and our constraints in its terms: the joint speed limits as a
JointVelocityConstraint, the tip bounds through a virtual joint q_s = s (dq_s/ds = 1) with speed
limit v_tip and acceleration limit a (|d^2 q_s/dt^2| = |sdd|); the real joints' acceleration limits
are 1e3 rad/s^2 (never active: we bound none). Its constant-acceleration parametrizer times the
grid the way ours does (sdd constant between samples). Columns: the duration of both, the time to
compute (samples in, timed samples out; toppra: spline, constraints, solve and parametrizer; the
median of several rounds), and each one's worst joint speed / limit on the samples (toppra's with
its spline's derivative, ours with the central difference and the chords).

toppra is not a dependency of the project: it runs in a venv of its own (``$MK_TOPPRA_PYTHON``
names an interpreter that has it; otherwise ``~/.cache/manipulator_kinematics/bench-toppra-venv``
is created with pip on first use), through ``peer_venv.run_worker``.

Run: .venv/bin/python benchmarks/bench_time_scaling.py [--rounds 7] [--no-toppra]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from peer_venv import run_worker
from tables import print_table

REPO = Path(__file__).resolve().parent.parent
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
TOPPRA_VENV = CACHE / "manipulator_kinematics" / "bench-toppra-venv"
TOPPRA_PACKAGE = "toppra==0.6.10"
TIP_SPEED, ACCELERATION = 0.2, 0.1
FREE_JOINT_ACCELERATION = 1e3  # rad/s^2: no joint acceleration limit (toppra needs a number)


# ---- toppra in its own interpreter (no project imports there) ----------------------------------
def toppra_worker() -> None:
    """Reads paths and limits as JSON on stdin; prints durations, timings and speed ratios as JSON."""
    from importlib.metadata import version

    import numpy as np
    import toppra
    import toppra.algorithm
    import toppra.constraint

    toppra.setup_logging("ERROR")
    job = json.load(sys.stdin)
    out = {"version": version("toppra"), "paths": []}
    for path in job["paths"]:
        q, s = np.array(path["q"]), np.array(path["s"])
        vmax = np.array(path["vmax"])
        augmented = np.column_stack([q, s])  # the virtual joint q_s = s carries the tip bounds
        velocity = np.column_stack([-np.append(vmax, job["tip_speed"]), np.append(vmax, job["tip_speed"])])
        acceleration_limit = np.append(np.full(len(vmax), FREE_JOINT_ACCELERATION), job["acceleration"])
        acceleration = np.column_stack([-acceleration_limit, acceleration_limit])

        seconds = []
        for _ in range(job["rounds"]):
            start = time.perf_counter()
            spline, instance, trajectory = _toppra_solve(toppra, s, augmented, velocity, acceleration)
            seconds.append(time.perf_counter() - start)
        result = {"seconds": seconds}
        if trajectory is None:
            result["duration"] = None
        else:
            _, sd, _ = instance.compute_parameterization(0.0, 0.0)
            rates = np.abs(spline(s, 1)[:, :-1]) * sd[:, None]
            result |= {
                "duration": float(trajectory.duration),
                "joint_ratio": float(np.max(rates / vmax)),
                "tip_ratio": float(np.max(sd) / job["tip_speed"]),
            }
        out["paths"].append(result)
    json.dump(out, sys.stdout)


def _toppra_solve(toppra, s, augmented, velocity, acceleration):
    """Spline through the samples, constraints, TOPP-RA on the grid s, constant-acceleration timing."""
    spline = toppra.SplineInterpolator(s, augmented)
    constraints = [
        toppra.constraint.JointVelocityConstraint(velocity),
        toppra.constraint.JointAccelerationConstraint(acceleration),
    ]
    instance = toppra.algorithm.TOPPRA(
        constraints, spline, gridpoints=s, parametrizer="ParametrizeConstAccel"
    )
    return spline, instance, instance.compute_trajectory(0.0, 0.0)


def run_toppra(job: dict) -> tuple[dict | None, str]:
    return run_worker(
        __file__,
        "--toppra-worker",
        job,
        (TOPPRA_PACKAGE,),
        "import toppra",
        TOPPRA_VENV,
        "MK_TOPPRA_PYTHON",
        timeout=1800,
    )


# ---- the project's side -------------------------------------------------------------------------
def pump_boom_paths():
    """(name, q, s, joint speed limits) of pump boom pours of about 300, 2,000 and 20,000 points."""
    import numpy as np

    sys.path.insert(0, str(REPO))
    from pump_boom_kinematics.kinematics import PumpBoom
    from pump_boom_kinematics.pour import MAX_POINTS, TYPICAL_POURS, plan_path, pour_line

    boom = PumpBoom.default()
    paths = [("slanted line, 100 mm", pour_line(boom, *TYPICAL_POURS["slanted_line"][1:]))]
    # A raster over the boom's front: rows 2 m apart at z = 12.5 m, x 16-28 m.
    raster = np.array(
        [[x, y, 12.5] for y in np.arange(-6.0, 6.1, 2.0) for x in ((16.0, 28.0) if y % 4 else (28.0, 16.0))]
    )
    length = float(np.sum(np.linalg.norm(np.diff(raster, axis=0), axis=1)))
    for count in (2_000, MAX_POINTS):
        plan = plan_path(boom, raster, step=length / (count - len(raster)))
        assert plan.ok and not plan.truncated, plan.message
        paths.append((f"raster pour, {len(raster)} waypoints", plan))
    return [(name, plan.q, plan.s, boom.joint_speed) for name, plan in paths]


def main() -> None:
    if "--toppra-worker" in sys.argv:
        toppra_worker()
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7, help="timed rounds per path and method")
    parser.add_argument("--no-toppra", action="store_true", help="skip toppra (no install)")
    args = parser.parse_args()

    import numpy as np

    from manipulator_kinematics.time_scaling import time_scale

    paths = pump_boom_paths()
    ours = []
    for _, q, s, vmax in paths:
        seconds = []
        for _ in range(args.rounds):
            start = time.perf_counter()
            timed = time_scale(q, s, vmax, TIP_SPEED, ACCELERATION)
            seconds.append(time.perf_counter() - start)
        chord = np.abs(np.diff(q, axis=0) / np.diff(s)[:, None])
        rate = np.maximum.reduce(
            [
                np.abs(np.gradient(q, s, axis=0, edge_order=2)),
                np.vstack([chord[:1], chord]),
                np.vstack([chord, chord[-1:]]),
            ]
        )
        ours.append(
            {
                "seconds": seconds,
                "duration": timed.duration,
                "joint_ratio": float(np.max(rate * timed.speed[:, None] / vmax)),
                "tip_ratio": float(np.max(timed.speed) / TIP_SPEED),
            }
        )
    peer, why = (
        (None, "skipped (--no-toppra)")
        if args.no_toppra
        else run_toppra(
            {
                "paths": [
                    {"q": q.tolist(), "s": s.tolist(), "vmax": vmax.tolist()} for _, q, s, vmax in paths
                ],
                "tip_speed": TIP_SPEED,
                "acceleration": ACCELERATION,
                "rounds": args.rounds,
            }
        )
    )

    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"\nTime scaling benchmark: {os.cpu_count()} cores (load average {load}), Python "
        f"{sys.version.split()[0]}, numpy {np.__version__}, toppra {peer['version'] if peer else why}.\n"
        f"Tip speed {TIP_SPEED} m/s, tip acceleration {ACCELERATION} m/s^2, the boom's joint speed limits; "
        f"compute times are medians of {args.rounds} rounds.\n"
    )
    header = (
        "path",
        "N",
        "duration ours / toppra (s)",
        "ratio",
        "compute ours / toppra (ms)",
        "speed-up",
        "max joint speed/limit ours / toppra",
        "max tip speed/limit ours / toppra",
    )
    rows = []
    for k, (name, q, _, _) in enumerate(paths):
        mine = ours[k]
        other = peer["paths"][k] if peer else None
        ms = 1e3 * float(np.median(mine["seconds"]))
        if other is None or other["duration"] is None:
            note = why if other is None else "toppra found no parameterisation"
            rows.append(
                (
                    name,
                    str(len(q)),
                    f"{mine['duration']:.2f} / -",
                    "-",
                    f"{ms:.2f} / -",
                    note,
                    f"{mine['joint_ratio']:.6f} / -",
                    f"{mine['tip_ratio']:.6f} / -",
                )
            )
            continue
        theirs = 1e3 * float(np.median(other["seconds"]))
        rows.append(
            (
                name,
                str(len(q)),
                f"{mine['duration']:.2f} / {other['duration']:.2f}",
                f"{mine['duration'] / other['duration']:.4f}",
                f"{ms:.2f} / {theirs:.1f}",
                f"{theirs / ms:.0f}x",
                f"{mine['joint_ratio']:.6f} / {other['joint_ratio']:.6f}",
                f"{mine['tip_ratio']:.6f} / {other['tip_ratio']:.6f}",
            )
        )
    print_table(header, rows)


if __name__ == "__main__":
    main()
