"""What the three bag commands share: expected errors end in one line on stderr, not a traceback."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

from manipulator_kinematics.bag.types import BagError

#: Exit status of an expected failure (bad bag, bad arguments, existing output).
FAILED = 1


def guarded(name: str, body: Callable[[Sequence[str]], int], argv: Sequence[str] | None) -> int:
    """Run ``body(argv)``; a :class:`BagError` becomes ``name: error: ...`` and exit status 1."""
    try:
        return body(sys.argv[1:] if argv is None else list(argv))
    except BagError as error:
        # One line even when the message quotes a multi-line text (a type definition's parse error).
        print(f"{name}: error: {' '.join(str(error).split())}", file=sys.stderr)
        return FAILED
    except KeyboardInterrupt:
        return 130


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(our arguments, the ``--ros-args ... [--]`` sections for rclpy.init).

    Done here rather than with rclpy's remove_ros_args, which also takes our ``FROM:=TO`` items
    for (deprecated) remapping rules.
    """
    ours, ros, inside = [], [], False
    for item in argv:
        if item == "--ros-args":
            inside = True
            ros.append(item)
        elif inside and item == "--":
            inside = False
        else:
            (ros if inside else ours).append(item)
    return ours, ros


def parse_assignments(items: Sequence[str], what: str) -> dict[str, str]:
    """``["a:=b", ...]`` -> ``{"a": "b"}``; BagError for an item without ``:=``."""
    out = {}
    for item in items:
        left, sep, right = item.partition(":=")
        if not sep or not left or not right:
            raise BagError(f"{what} {item!r} is not of the form NAME:=VALUE")
        out[left] = right
    return out
