"""Test isolation for ROS: every test run gets its own ROS_DOMAIN_ID, discovery stays local.

The domain is reserved with an exclusive lock on a file per domain id, so parallel test runs
on one machine (two checkouts, CI beside a developer) never hear each other. Subprocesses
started by tests inherit the environment set here.
"""
from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path

_LOCK_DIR = Path(tempfile.gettempdir()) / "manipulator_kinematics_ros_domains"
_held_lock = None


def _reserve_domain() -> int:
    global _held_lock
    _LOCK_DIR.mkdir(exist_ok=True)
    # 0 is everybody's default; 101 is the highest id whose ports fit (platform notes).
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
