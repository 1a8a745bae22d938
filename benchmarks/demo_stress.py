"""The demo under load: ``excavator_demo`` N times with a CPU hog pinned on one core.

    python benchmarks/demo_stress.py [--runs 20] [--output out/demo_stress] [--hog-core 0 | --no-hog]

Each run gets its own output directory (``<output>/run_NN``, with the demo's console output in
``demo.out``) and its own ROS_DOMAIN_ID, reserved with the same lock files as the test suite
(test/conftest.py) so a test run on the machine at the same time is never heard. The hog is a busy
Python loop pinned to one core with ``os.sched_setaffinity``, started before the first run and
killed after the last. Prints a line per run and a table: exit code, the bucket's distance from
the reference path (RMS / max, as the demo's summary), the driver's pose delay p99, poses not acted
on, cycle clock held, wall time, load average at the start; then the pass count. Exit status 0
only if every run passed. Not part of the test suite (about 70 s a run).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.ros_domain import reserved_domain

PATTERNS = {
    "rms": r"distance from the reference path: RMS ([\d.]+) mm",
    "max": r"distance from the reference path: RMS [\d.]+ mm, max ([\d.]+) mm",
    "p99": r"/ ([\d.]+) ms \(p99\)",
    "skipped": r"; (\d+) of \d+ older than",
    "held": r"cycle clock held ([\d.]+) s",
}


def start_hog(core: int) -> subprocess.Popen:
    code = f"import os\nos.sched_setaffinity(0, {{{core}}})\nwhile True:\n    pass\n"
    return subprocess.Popen([sys.executable, "-c", code])


def run_once(output: Path) -> dict[str, object]:
    output.mkdir(parents=True, exist_ok=True)
    load = os.getloadavg()[0]
    with reserved_domain() as domain:
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        began = time.monotonic()
        with open(output / "demo.out", "w", encoding="utf-8") as log:
            demo = subprocess.Popen(
                [console_script("excavator_demo"), "--output", str(output)],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=env,
            )
            try:
                code = demo.wait()
            except BaseException:  # stopped: the demo stops its own processes on SIGINT
                demo.send_signal(signal.SIGINT)
                demo.wait(150.0)
                raise
        wall = time.monotonic() - began
    text = (output / "demo.out").read_text(encoding="utf-8")
    row: dict[str, object] = {"code": code, "wall": wall, "load": load, "domain": domain}
    for key, pattern in PATTERNS.items():
        found = re.search(pattern, text)
        row[key] = found.group(1) if found else "-"
    failed = [line for line in text.splitlines() if "FAILED" in line]
    row["why"] = failed[0].split("FAILED: ", 1)[1][:70] if failed else ""
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20, help="number of demo runs (default 20)")
    parser.add_argument(
        "--output", type=Path, default=Path("out/demo_stress"), help="directory of the runs (out/demo_stress)"
    )
    parser.add_argument("--hog-core", type=int, default=0, help="core the busy loop is pinned to (default 0)")
    parser.add_argument("--no-hog", action="store_true", help="no busy loop (the unloaded reference)")
    args = parser.parse_args()
    # SIGTERM (and SIGINT, also when started in the background) end the loop through the finally.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    hog = None if args.no_hog else start_hog(args.hog_core)
    load = "no load" if hog is None else f"a busy loop pinned to core {args.hog_core}"
    print(f"demo_stress: {args.runs} runs of excavator_demo, {os.cpu_count()} cores, {load}", flush=True)
    header = (
        f"{'run':>3}  {'exit':>4}  {'RMS mm':>6}  {'max mm':>6}  {'p99 ms':>6}  {'skip':>4}  {'held s':>6}  "
        f"{'wall s':>6}  {'load1':>5}  why"
    )
    lines = []
    try:
        for k in range(1, args.runs + 1):
            r = run_once(args.output / f"run_{k:02d}")
            lines.append(
                f"{k:>3}  {r['code']:>4}  {r['rms']:>6}  {r['max']:>6}  {r['p99']:>6}  {r['skipped']:>4}  "
                f"{r['held']:>6}  {r['wall']:>6.1f}  {r['load']:>5.2f}  {r['why']}"
            )
            print(lines[-1], flush=True)
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
    passed = sum(line.split()[1] == "0" for line in lines)
    print("\n".join(["", header, *lines, "", f"demo_stress: {passed} of {len(lines)} runs passed ({load})"]))
    return 0 if passed == len(lines) == args.runs else 1


if __name__ == "__main__":
    raise SystemExit(main())
