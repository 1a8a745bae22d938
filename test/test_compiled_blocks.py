"""The shared block helper and kernel loader (manipulator_kinematics.row_blocks / .compiled)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from manipulator_kinematics.compiled import Kernel, cache_is_cold
from manipulator_kinematics.row_blocks import in_blocks


def _work(a: np.ndarray, b: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    return np.cumsum(a, axis=-1), (a[:, 0] > 0) if b is None else b.astype(np.int8)


@pytest.mark.parametrize("n", [1, 7, 64, 65, 1000])
def test_in_blocks_is_one_call(n: int) -> None:
    a = np.random.default_rng(n).normal(size=(n, 3))
    whole = _work(a, None)
    blocked = in_blocks(_work, a, None, block=8)
    for expected, got in zip(whole, blocked, strict=True):
        assert got.dtype == expected.dtype and got.shape == expected.shape
        np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(in_blocks(np.sin, a, block=5), np.sin(a))


def test_a_kernel_that_fails_to_load_leaves_the_numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    kernel = Kernel("manipulator_kinematics.no_such_kernel", lambda module: None)
    with pytest.raises(RuntimeError, match="no_such_kernel"):
        kernel.get(wait=True)
    assert kernel.get() is None and isinstance(kernel.error, ImportError)
    monkeypatch.setenv("MK_COMPILED", "0")
    assert Kernel("math", lambda module: None).get(wait=True) is None


def test_a_kernel_warms_with_the_first_sample() -> None:
    seen = []
    kernel = Kernel("math", lambda module, x: seen.append(module.sqrt(x)))
    assert kernel.get(4.0, wait=True).sqrt(9.0) == 3.0
    assert seen == [2.0]


def test_the_compiled_selection_is_the_numpy_rule() -> None:
    """select_kernel.select_one against model.select over random candidate sets, with ties,
    requested branches, weights and seeds that are NaN or infinite."""
    from manipulator_kinematics.model import TIE_TOLERANCE, IKStatus, select
    from manipulator_kinematics.select_kernel import select_one

    rng = np.random.default_rng(22)
    for trial in range(4000):
        m, n = int(rng.integers(1, 9)), int(rng.integers(1, 7))
        q = rng.integers(-2, 3, size=(m, n)).astype(float)  # small integers: exact ties happen
        status = rng.choice(
            [int(IKStatus.SUCCESS), int(IKStatus.JOINT_LIMITS), int(IKStatus.SINGULAR)],
            size=m,
            p=[0.6, 0.3, 0.1],
        ).astype(np.int8)
        seed = rng.integers(-2, 3, size=n).astype(float)
        if trial % 10 == 0:
            seed[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        weights = rng.choice([1.0, 0.5, 2.0], size=n)
        seeded = trial % 7 != 0
        branch = int(rng.integers(m)) if trial % 5 == 0 else None
        expected, expected_tie = select(
            q, status, seed=seed if seeded else None, branch=branch, weights=weights
        )
        allowed = np.full(m, branch is None)
        if branch is not None:
            allowed[branch] = True
        got, tie = select_one(q, status, seed, seeded, allowed, weights, TIE_TOLERANCE)
        assert (got, tie) == (int(expected), bool(expected_tie)), (trial, q, status, seed, branch)


@pytest.mark.parametrize("n", [1, 7, 8, 9, 100])
def test_in_blocks_rows_is_the_table_of_entries(n: int) -> None:
    a = np.random.default_rng(n).normal(size=(n, 2))

    def entries(x: np.ndarray) -> tuple:
        return x[:, 0] * 2.0, 1.5, np.hypot(x[:, 0], x[:, 1])

    table = in_blocks(entries, a, block=8, rows=True)
    assert table.shape == (3, n)
    np.testing.assert_array_equal(table, [a[:, 0] * 2.0, np.full(n, 1.5), np.hypot(a[:, 0], a[:, 1])])


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


@pytest.mark.ros
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


@pytest.mark.ros
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


@pytest.mark.ros
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
    assert cache_is_cold("mk_cold_guess.kernel")
    subprocess.run(
        [sys.executable, "-c", "import mk_cold_guess.kernel as k; k.f(1.0)"],
        check=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(tmp_path)},
    )
    assert not cache_is_cold("mk_cold_guess.kernel")
    # An edit above the function moves it: cold until compiled again, then warm although the
    # index under its old line number stays behind (a developer's tree after any edit).
    source = package / "kernel.py"
    now = time.time()
    for index in cache.rglob("*.nbi"):  # clear of the file system's timestamp granularity
        os.utime(index, (now - 10, now - 10))
    source.write_text("# moved\n" + source.read_text())
    os.utime(source, (now - 5, now - 5))
    assert cache_is_cold("mk_cold_guess.kernel")
    subprocess.run(
        [sys.executable, "-c", "import mk_cold_guess.kernel as k; k.f(1.0)"],
        check=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(tmp_path)},
    )
    assert len(list(cache.rglob("kernel.f-*.nbi"))) == 2
    assert not cache_is_cold("mk_cold_guess.kernel")
    assert not cache_is_cold("math") and not cache_is_cold("no_such_module_anywhere")
