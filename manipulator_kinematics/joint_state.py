"""sensor_msgs/JointState -> numpy by joint name, with reasons; shared by every machine's nodes.

Duck-typed on ``name``/``position``/``velocity`` so it needs no ROS import, and plain Python on
purpose: it runs for every message, at up to 1 kHz.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np


class InputError(ValueError):
    """An input message that cannot be used; the text says why (for a logged rejection)."""


def joint_values(
    msg: Any, names: Sequence[str], *, require_position: bool = False, require_velocity: bool = False
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Positions and velocities of ``names`` in that order, each None when the message's field
    is empty (a command may carry velocities only). Other joints in the message are ignored.

    Raises InputError naming what is missing, of the wrong length or not finite.
    """
    index = {name: i for i, name in enumerate(msg.name)}
    missing = [name for name in names if name not in index]
    if missing:
        raise InputError(f"joint names {missing} missing from the message (has {list(msg.name)})")
    rows = [index[name] for name in names]
    out = []
    for label, field, required in (
        ("position", msg.position, require_position),
        ("velocity", msg.velocity, require_velocity),
    ):
        if len(field) == 0:
            if required:
                raise InputError(f"no {label} values for {list(names)}")
            out.append(None)
            continue
        if len(field) != len(index):
            raise InputError(f"{len(index)} names but {len(field)} {label} values")
        values = [field[i] for i in rows]
        if not all(map(math.isfinite, values)):
            raise InputError(f"non-finite {label} {values} for {list(names)}")
        out.append(np.array(values))
    return out[0], out[1]
