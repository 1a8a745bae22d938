"""The README and docs/machines.md (the README's machine sections) run as written: every code
block marked ``<!-- runnable -->`` is run, Python blocks
in-process and shell blocks with the venv's executables; blocks marked ``<!-- runnable: nodes -->``
start their nodes together, which must come up, log a start-up line and exit 0 on SIGINT."""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ros_harness import REPO, NodeProcess

README = REPO / "README.md"
PAGES = (README, REPO / "docs" / "machines.md")
BLOCK = re.compile(r"<!-- runnable(?::\s*(?P<kind>\w+))? -->\n```(?P<lang>\w+)\n(?P<code>.*?)\n```", re.S)
STARTUP_TIMEOUT = 30.0


def blocks(kind: str | None, lang: str) -> list[str]:
    found = [
        (m["kind"], m["lang"], m["code"])
        for page in PAGES
        for m in BLOCK.finditer(page.read_text(encoding="utf-8"))
    ]
    return [code for k, language, code in found if k == kind and language == lang]


def test_the_readme_marks_its_blocks() -> None:
    assert len(blocks(None, "python")) >= 6 and blocks(None, "bash") and blocks("nodes", "bash")


@pytest.mark.parametrize("code", blocks(None, "python"), ids=lambda c: c.splitlines()[0][:60])
def test_python_block_runs(code: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(code, str(README), "exec"), {"__name__": "readme"})


@pytest.mark.ros
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


@pytest.mark.ros
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
