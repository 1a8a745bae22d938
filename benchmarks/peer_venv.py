"""Run a benchmark's peer (Robotics Toolbox, Pinocchio) in a venv of its own, never the project's.

The peers are not dependencies of the project: on first use they are installed with pip into a
benchmark-only venv, and the benchmark script runs itself there as a worker that reads a JSON job
on stdin and prints JSON timings.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path


def run_worker(
    script: str,
    flag: str,
    job: dict,
    packages: tuple[str, ...],
    check: str,
    venv: Path,
    python_variable: str,
    timeout: float,
) -> tuple[dict | None, str]:
    """``<python> script flag`` with ``job`` on stdin in the peer venv: (timings, "") or (None, why).

    ``$python_variable`` names an interpreter that already has the peers (nothing is installed
    then); otherwise ``venv`` is created and ``packages`` installed unless ``check`` imports."""
    given = os.environ.get(python_variable)
    python = given or str(venv / "bin" / "python")
    ready = (
        Path(python).exists() and subprocess.run([python, "-c", check], capture_output=True).returncode == 0
    )
    if not ready and not given:
        print(f"installing {', '.join(packages)} into {venv} (benchmark only) ...", file=sys.stderr)
        try:
            subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, capture_output=True)
            subprocess.run(
                [str(venv / "bin" / "pip"), "install", "-q", *packages],
                check=True,
                capture_output=True,
                timeout=1800,
            )
            ready = True
        except (subprocess.SubprocessError, OSError) as error:
            return None, f"{', '.join(packages)} could not be installed: {error}"
    if not ready:
        return None, f"{', '.join(packages)} not available at {python}"
    done = subprocess.run(
        [python, script, flag], input=json.dumps(job), capture_output=True, text=True, timeout=timeout
    )
    if done.returncode != 0:
        return None, f"peer worker failed: {done.stderr.strip().splitlines()[-1:]}"
    return json.loads(done.stdout), ""
