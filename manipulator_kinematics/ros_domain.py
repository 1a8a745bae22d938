"""Keep a run to itself on the network: localhost discovery in a ROS domain of its own.

ROS 2 talks to every participant of its ROS_DOMAIN_ID that discovery reaches (Jazzy: the whole
subnet by default). A demo or an example must not join whatever ROS graph is around, so, unless
the user set them:

* ``ROS_AUTOMATIC_DISCOVERY_RANGE`` becomes ``LOCALHOST``;
* ``ROS_DOMAIN_ID`` becomes a domain nobody else on this machine holds (:func:`reserved_domain`:
  an exclusive lock on ``<tmp>/manipulator_kinematics_ros_domains/<id>.lock``, the lock files the
  test suite uses too), for as long as the run lasts; :data:`EXAMPLES_DOMAIN` for commands started
  by hand (``scripts/env.sh``), which must share one domain to hear each other, and which
  :func:`reserved_domain` never hands out.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

LOCK_DIR = Path(tempfile.gettempdir()) / "manipulator_kinematics_ros_domains"
#: The domain of the README's examples (scripts/env.sh); 1..101 keep every port below Linux's
#: ephemeral range (7400 + 250 per domain < 32768).
EXAMPLES_DOMAIN = 101


@contextmanager
def reserved_domain() -> Iterator[int]:
    """A ROS_DOMAIN_ID in 1..100 that no other process on this machine holds, for the block."""
    LOCK_DIR.mkdir(exist_ok=True)
    for domain in range(1, EXAMPLES_DOMAIN):
        with open(LOCK_DIR / f"{domain}.lock", "w") as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue
            yield domain
            return
    raise RuntimeError(f"no free ROS_DOMAIN_ID in 1..{EXAMPLES_DOMAIN - 1}")


@contextmanager
def isolated() -> Iterator[str]:
    """``os.environ`` with localhost discovery and a reserved domain, where the user set neither
    (module docstring), restored afterwards; yields a line saying what was chosen."""
    saved = {key: os.environ.get(key) for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    try:
        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        if saved["ROS_DOMAIN_ID"] is not None:
            yield _note("set by you")
            return
        with reserved_domain() as domain:
            os.environ["ROS_DOMAIN_ID"] = str(domain)
            yield _note("free on this machine; set ROS_DOMAIN_ID to choose")
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def _note(domain_source: str) -> str:
    return (
        f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']} ({domain_source}), "
        f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}"
    )


__all__ = ["EXAMPLES_DOMAIN", "LOCK_DIR", "isolated", "reserved_domain"]
