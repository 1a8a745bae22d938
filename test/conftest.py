"""Test isolation for ROS: every test run gets its own ROS_DOMAIN_ID, discovery stays local; and
a test run leaves nothing in the system's temporary directory.

The domain is reserved with an exclusive lock on a file per domain id, so parallel test runs
on one machine (two checkouts, CI beside a developer) never hear each other. Subprocesses
started by tests inherit the environment set here.

Temporary files: tests use pytest's ``tmp_path``; the harness (ros_harness.py) keeps each node's
log and params file in a directory of this run (``MK_TEST_SCRATCH``) and deletes them when the
node is stopped. At the end of the run, :func:`no_files_left_behind` stops any node a test left
running, removes that directory, and fails the run if the system's temporary directory holds a
new file named like ours (``<console script>-*``). Only our own names are compared: other
programs use that directory too.
"""

from __future__ import annotations

import fcntl
import fnmatch
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Generator, Iterator
from importlib.metadata import distribution
from pathlib import Path

import pytest

_TMP = Path(tempfile.gettempdir())
_LOCK_DIR = _TMP / "manipulator_kinematics_ros_domains"
_held_lock = None


def _reserve_domain() -> int:
    global _held_lock
    _LOCK_DIR.mkdir(exist_ok=True)
    # 0 is everybody's default; 101 is the highest id whose ports (7400 + 250 per domain) stay
    # below Linux's ephemeral port range, which starts at 32768.
    for domain in range(1, 102):
        handle = open(_LOCK_DIR / f"{domain}.lock", "w")  # noqa: SIM115 - held for the run
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _held_lock = handle
        return domain
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..101 for this test run")


if "MK_TEST_ROS_DOMAIN_ID" in os.environ:
    os.environ["ROS_DOMAIN_ID"] = os.environ["MK_TEST_ROS_DOMAIN_ID"]
else:
    os.environ["ROS_DOMAIN_ID"] = str(_reserve_domain())
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)


def our_patterns() -> list[str]:
    """Names of temporary files our tests could leave: ``<console script>-*`` (node logs, params
    files)."""
    entries = distribution("manipulator_kinematics").entry_points
    return sorted(f"{e.name}-*" for e in entries if e.group == "console_scripts")


def ours(patterns: list[str]) -> set[str]:
    return {p.name for p in _TMP.iterdir() if any(fnmatch.fnmatchcase(p.name, q) for q in patterns)}


@pytest.fixture(scope="module")
def probe(request: pytest.FixtureRequest) -> Iterator[object]:
    """The ROS test module's own node and executor (ros_harness.Probe), named after the module."""
    from ros_harness import Probe  # ROS is imported by the ROS tests only

    probe = Probe(f"{request.module.__name__.rsplit('.', 1)[-1]}_probe")
    yield probe
    probe.close()


@pytest.fixture(scope="session", autouse=True)
def no_files_left_behind() -> Iterator[None]:
    patterns = our_patterns()
    before = ours(patterns)
    scratch = Path(tempfile.mkdtemp(prefix="manipulator_kinematics_test-"))
    os.environ["MK_TEST_SCRATCH"] = str(scratch)
    try:
        yield
    finally:
        harness = sys.modules.get("ros_harness")  # imported by the ROS tests only
        left_running = harness.stop_all() if harness else []
        left_files = sorted(p.name for p in scratch.iterdir())
        shutil.rmtree(scratch, ignore_errors=True)
        os.environ.pop("MK_TEST_SCRATCH", None)
    new = sorted(ours(patterns) - before)
    assert not new, f"the tests left these in {_TMP}: {', '.join(new)} (use tmp_path, or delete in a finally)"
    assert not left_running, f"tests left these processes running (now stopped): {left_running}"
    assert not left_files, f"tests left these in the harness's directory (now removed): {left_files}"


class _NotInFastTier(RuntimeError):
    pass


def _refuse(what: str, nodeid: str):  # type: ignore[no-untyped-def]
    def refuse(*_args: object, **_kwargs: object) -> None:
        raise _NotInFastTier(
            f"{nodeid} {what} but is not marked 'ros': add pytest.mark.ros (or pytestmark = "
            "pytest.mark.ros for a file of such tests) so `scripts/test.sh --fast` stays fast"
        )

    return refuse


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None]:
    """Keep the tiers honest: a test not marked ``ros`` that starts a process (subprocess.Popen,
    which the harness and subprocess.run use) or a ROS context (rclpy.init, Context.init) fails
    with a message saying so, in set-up, call and tear-down (module fixtures included)."""
    if item.get_closest_marker("ros") is not None:
        yield
        return
    patches: list[tuple[object, str, object]] = [
        (subprocess, "Popen", _refuse("starts a process", item.nodeid))
    ]
    try:
        import rclpy
        import rclpy.context
    except ImportError:
        pass
    else:
        patches.append((rclpy, "init", _refuse("starts ROS (rclpy.init)", item.nodeid)))
        patches.append((rclpy.context.Context, "init", _refuse("starts ROS (Context.init)", item.nodeid)))
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in patches]
    for owner, name, replacement in patches:
        setattr(owner, name, replacement)
    try:
        yield
    finally:
        for owner, name, original in saved:
            setattr(owner, name, original)
