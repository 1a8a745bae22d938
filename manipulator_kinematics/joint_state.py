"""sensor_msgs/JointState -> numpy by joint name, with reasons; shared by every machine's nodes.

Duck-typed on ``name``/``position``/``velocity`` so it needs no ROS import, and plain Python on
purpose: it runs for every message, at up to 1 kHz. :func:`decode_joint_state` reads the message
straight from its serialized bytes (a subscription created with ``raw=True``): rclpy's own
conversion builds a JointState, a Header and a Time object per message, three times the cost.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from manipulator_kinematics.codec import cdr
from manipulator_kinematics.param_files import shown


class InputError(ValueError):
    """An input message that cannot be used; the text says why (for a logged rejection)."""


#: An input this many times beyond what the machine can do (its speed limit; its joint range
#: beyond the limits; its reach) is refused as implausible where it enters a node: no machine
#: measures it, and refusing it keeps the arithmetic downstream far from overflow.
PLAUSIBILITY_FACTOR = 1000.0


def check_plausible_positions(
    q: np.ndarray, names: Sequence[str], lower: np.ndarray, upper: np.ndarray
) -> None:
    """InputError naming the first joint further outside [lower, upper] than PLAUSIBILITY_FACTOR
    times its range (at least one unit: a joint fixed by its limits still has a scale)."""
    margin = PLAUSIBILITY_FACTOR * np.maximum(upper - lower, 1.0)
    bad = ~((q >= lower - margin) & (q <= upper + margin))
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{names[i]} = {q[i]:.6g} is beyond {PLAUSIBILITY_FACTOR:g} x its range outside "
            f"[{lower[i]:.6g}, {upper[i]:.6g}]: implausible"
        )


def joint_values(
    msg: Any, names: Sequence[str], *, require_position: bool = False, require_velocity: bool = False
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Positions and velocities of ``names`` in that order, each None when the message's field
    is empty (a command may carry velocities only). Other joints in the message are ignored.

    Raises InputError naming what is missing, of the wrong length or not finite.
    """
    index = {name: i for i, name in enumerate(msg.name)}
    if len(index) != len(msg.name):
        raise InputError(f"joint names repeat in the message: {shown(msg.name)}")
    missing = [name for name in names if name not in index]
    if missing:
        raise InputError(f"joint names {missing} missing from the message (has {shown(msg.name)})")
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


class RawJointState(NamedTuple):
    """The fields of a sensor_msgs/JointState, as :func:`decode_joint_state` reads them."""

    sec: int
    nanosec: int
    frame_id: str
    name: list[str]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    effort: tuple[float, ...]

    @property
    def stamp_ns(self) -> int:
        """The header stamp in integer nanoseconds."""
        return self.sec * 1_000_000_000 + self.nanosec


def decode_joint_state(raw: bytes) -> RawJointState:
    """A sensor_msgs/JointState from its plain CDR bytes (as ROS 2 writes them; the layout rules are
    :mod:`manipulator_kinematics.codec.cdr`'s, read here with struct for one message at a time).

    Raises InputError when the bytes are not a JointState (truncated, bad lengths or strings).
    Bytes after the last field are ignored: serializers pad the end (rclpy's by up to 8 bytes).
    """
    try:
        order = cdr.byte_order(raw)
        u32 = _U32[order]
        sec, nanosec = _STAMP[order].unpack_from(raw, 4)
        frame_id, pos = _string(raw, 12, u32)
        count, pos = _count(raw, pos, u32)
        names = []
        for _ in range(count):
            name, pos = _string(raw, pos, u32)
            names.append(name)
        sequences = []
        for _ in range(3):
            count, pos = _count(raw, pos, u32)
            if count:
                pos = 4 + ((pos - 4 + 7) & -8)  # cdr.aligned(pos, 8), inlined: this runs per message
                sequences.append(struct.unpack_from(f"{order}{count}d", raw, pos))
                pos += 8 * count
            else:
                sequences.append(())
    except (struct.error, UnicodeDecodeError, ValueError) as error:
        raise InputError(f"not a sensor_msgs/JointState ({len(raw)} bytes): {error}") from None
    return RawJointState(sec, nanosec, frame_id, names, *sequences)


_U32 = {order: struct.Struct(order + "I") for order in "<>"}
_STAMP = {order: struct.Struct(order + "iI") for order in "<>"}


def _count(raw: bytes, pos: int, u32: struct.Struct) -> tuple[int, int]:
    """A length at ``pos`` (aligned to 4) and the position after it."""
    pos = 4 + ((pos - 4 + 3) & -4)  # cdr.aligned(pos, 4), inlined: this runs per message
    (n,) = u32.unpack_from(raw, pos)
    if n > len(raw):
        raise ValueError(f"a length of {n} in a message of {len(raw)} bytes")
    return n, pos + 4


def _string(raw: bytes, pos: int, u32: struct.Struct) -> tuple[str, int]:
    size, pos = _count(raw, pos, u32)
    end = pos + size
    if size < 1 or end > len(raw) or raw[end - 1] != 0:
        raise ValueError(f"the string at byte {pos} is not NUL-terminated within the message")
    return raw[pos : end - 1].decode("utf-8"), end
