"""The README's shell and node blocks run as written (ros tier: they start processes); the other
blocks are checked in test_readme.py."""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ros_harness import REPO, NodeProcess
from test_readme import blocks

pytestmark = pytest.mark.ros


STARTUP_TIMEOUT = 30.0


@pytest.mark.parametrize("code", blocks(None, "bash"), ids=lambda c: c.splitlines()[0][:60])
def test_shell_block_runs(code: str) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    out = REPO / "out" / "readme_eval"
    try:
        result = subprocess.run(
            ["bash", "-e", "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=300
        )
        assert result.returncode == 0, result.stdout + result.stderr
        assert "Traceback" not in result.stderr
    finally:
        shutil.rmtree(out, ignore_errors=True)


@pytest.mark.parametrize("code", blocks("nodes", "bash"), ids=lambda c: c.splitlines()[0][:60])
def test_node_block_starts_and_stops_cleanly(code: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)  # the README's paths are relative to the repository
    commands = [shlex.split(line) for line in code.splitlines() if line.strip()]
    processes = []
    try:
        for exe, *args in commands:
            assert args[0] == "--ros-args", "node blocks hold: <exe> --ros-args ..."
            processes.append(NodeProcess(exe, *args[1:]))
        deadline = time.monotonic() + STARTUP_TIMEOUT
        while not all("[INFO]" in p.log() for p in processes):
            assert all(p.alive() for p in processes), [p.log() for p in processes]
            assert time.monotonic() < deadline, [p.log() for p in processes]
            time.sleep(0.1)  # polling the logs of other processes: there is nothing to wait on
    finally:
        logs = [p.stop() for p in processes]
    for process, log in zip(processes, logs):
        assert process.process.returncode == 0 and "Traceback" not in log, log
