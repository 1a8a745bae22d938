"""The kernel loader across processes (ros tier): exits during a compile or a load, the cold-cache
guess against numba in a child; the in-process block helper and loader are in
test_compiled_blocks.py."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from manipulator_kinematics.compiled import cache_is_cold

pytestmark = pytest.mark.ros

EXIT_DURING_THE_LOAD = """
import atexit, sys, time
import numpy as np
# registered before the loader's own exit hook (at the import of compiled), so called after it
atexit.register(lambda: print("loaded at exit:", kinematics.KERNEL.ready is not None))
if sys.argv[1] == "rclpy":
    import rclpy
from excavator_kinematics.core import kinematics
exc = kinematics.Excavator.default()
D = np.concatenate([[0.1], 0.5 * (exc.limits.stroke_min + exc.limits.stroke_max)[-3:]])
exc.state(D, np.zeros(4))  # starts the kernel's load, answered by numpy
assert kinematics.KERNEL.ready is None
deadline = time.monotonic() + 60
while "excavator_kinematics.core.state_kernel" not in sys.modules and time.monotonic() < deadline:
    time.sleep(0.001)  # until the loader is inside the import
"""


@pytest.mark.parametrize("imported", ["rclpy", "numpy only"])
def test_a_process_with_rclpy_ends_after_its_kernel_load_one_without_does_not_wait(imported: str) -> None:
    """A loader still running Python while the interpreter finalizes was ended inside rclpy's
    handle destructors (its garbage collection): a signalled node aborted (exit -6). Where rclpy
    is imported the process waits for the load at exit (a node leaves with os._exit instead,
    test_node_shutdown); without rclpy it does not. The cache is warm (the set-up compiles)."""
    done = subprocess.run(
        [sys.executable, "-c", EXIT_DURING_THE_LOAD, imported],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MK_COMPILED": "1"},
    )
    assert done.returncode == 0, done.stderr
    loaded = imported == "rclpy"
    assert f"loaded at exit: {loaded}" in done.stdout, (done.stdout, done.stderr)


EXIT_DURING_THE_COMPILE = """
import os, sys, time
from pathlib import Path
import numpy as np
from excavator_kinematics.core import kinematics

exc = kinematics.Excavator.default()
D = np.concatenate([[0.1], 0.5 * (exc.limits.stroke_min + exc.limits.stroke_max)[-3:]])
exc.state(D, np.zeros(4))  # starts the kernel's compile in a child, answered by numpy
children = set()
deadline = time.monotonic() + 60
while not children and time.monotonic() < deadline:
    for task in Path(f"/proc/{os.getpid()}/task").glob("*/children"):
        children |= {int(pid) for pid in task.read_text().split()}
    time.sleep(0.01)
print(*children, flush=True)
print(time.time(), flush=True)  # the main thread ends here
"""


def test_a_compile_on_a_cold_cache_is_abandoned_at_exit(tmp_path: Path) -> None:
    """With an empty cache the kernel compiles in a child process (seconds to tens of seconds);
    a process whose main thread ends kills it and ends at once, exit 0 (issue 28 item 2: 2 s)."""
    env = {**os.environ, "MK_COMPILED": "1", "NUMBA_CACHE_DIR": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-c", EXIT_DURING_THE_COMPILE], capture_output=True, text=True, timeout=120, env=env
    )
    ended = time.time()
    assert done.returncode == 0, done.stderr
    children, main_ended = done.stdout.splitlines()
    assert children, "no compile in a child"
    assert ended - float(main_ended) < 2.0, done.stdout
    for pid in map(int, children.split()):
        assert not Path(f"/proc/{pid}").exists() or " Z " in Path(f"/proc/{pid}/stat").read_text(), pid


def test_the_cold_cache_guess_follows_numba(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """cache_is_cold finds the index numba writes: cold in an empty NUMBA_CACHE_DIR, warm once a
    kernel module was compiled into it (a small module of this test)."""
    package = tmp_path / "mk_cold_guess"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "kernel.py").write_text(
        "import numba\n\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1\n"
    )
    cache = tmp_path / "cache"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    monkeypatch.syspath_prepend(str(tmp_path))
    source = package / "kernel.py"

    def compile_in_a_child(call: str) -> None:
        subprocess.run(
            [sys.executable, "-c", f"import mk_cold_guess.kernel as k; k.{call}(1.0)"],
            check=True,
            timeout=120,
            env={**os.environ, "PYTHONPATH": str(tmp_path)},
        )

    def edit(old: str, new: str, age: float) -> None:
        """The source edited ``age`` s ago, every index 10 s ago: clear of the file system's
        timestamp granularity."""
        now = time.time()
        for index in cache.rglob("*.nbi"):
            os.utime(index, (now - 10, now - 10))
        source.write_text(source.read_text().replace(old, new))
        os.utime(source, (now - age, now - age))

    assert cache_is_cold("mk_cold_guess.kernel")
    compile_in_a_child("f")
    assert not cache_is_cold("mk_cold_guess.kernel")
    # An edit above the function moves it: cold until compiled again, then warm although the
    # index under its old line number stays behind (a developer's tree after any edit).
    edit("import numba", "# moved\nimport numba", 5)
    assert cache_is_cold("mk_cold_guess.kernel")
    compile_in_a_child("f")
    assert len(list(cache.rglob("kernel.f-*.nbi"))) == 2
    assert not cache_is_cold("mk_cold_guess.kernel")
    # A function removed (renamed here) leaves its index behind: warm once the module's
    # functions are compiled, not cold for ever.
    edit("def f(", "def g(", 2)
    assert cache_is_cold("mk_cold_guess.kernel")
    compile_in_a_child("g")
    assert not cache_is_cold("mk_cold_guess.kernel")
    assert not cache_is_cold("math") and not cache_is_cold("no_such_module_anywhere")
