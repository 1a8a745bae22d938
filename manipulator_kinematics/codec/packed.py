"""Publishing fixed-layout messages as bytes: serialized once, only their numbers rewritten.

rclpy's ``Publisher.publish(msg)`` converts the Python message to C field by field before
serializing it: on our machines 20 of the 30 us that a PoseStamped publish costs, more than the
kinematics behind it. Our nodes publish, at the input rate, messages whose strings (frame ids,
joint names) and sequence lengths never change, so their CDR bytes have a fixed layout: serialize
one message, find where its numbers sit (:func:`manipulator_kinematics.codec.cdr.walk`), and from
then on write new numbers into those bytes with :mod:`struct`. ``Publisher.publish`` takes the
bytes as a serialized message, which subscribers receive exactly as if the message had been
published (the tests receive such messages through DDS).
"""

from __future__ import annotations

import importlib
import re
import struct
from collections.abc import Sequence
from typing import Any

from rclpy.serialization import serialize_message

from manipulator_kinematics.codec import cdr

# IDL names of primitive types (as rclpy message classes report them) -> cdr.PRIMITIVES keys.
_IDL = {"double": "float64", "float": "float32", "boolean": "bool"}
_STRUCT = {
    "f8": "d",
    "f4": "f",
    "i8": "q",
    "u8": "Q",
    "i4": "i",
    "u4": "I",
    "i2": "h",
    "u2": "H",
    "i1": "b",
    "u1": "B",
    "b1": "?",
}
_TYPE = re.compile(r"^(?:sequence<(?P<seq>[^,>]+)(?:, *\d+)?>|(?P<elem>[^\[<]+)(?:\[(?P<size>\d+)\])?)")


def _field(name: str, idl: str) -> cdr.Field:
    match = _TYPE.match(idl)
    if match is None:
        raise ValueError(f"field {name}: type {idl!r} is not supported")
    element = match["seq"] or match["elem"]
    element = "string" if element.startswith("string") else _IDL.get(element, element)
    array = cdr.SEQUENCE if match["seq"] else None if match["size"] is None else int(match["size"])
    return cdr.Field(name, element, array)


def _schemas(msg_class: type) -> dict[str, list[cdr.Field]]:
    """``msg_class`` and every type it embeds as cdr.Field lists, keyed ``pkg/Name``."""
    out: dict[str, list[cdr.Field]] = {}
    pending = [msg_class]
    while pending:
        cls = pending.pop()
        key = _type_name(cls)
        if key in out:
            continue
        out[key] = [_field(name, idl) for name, idl in cls.get_fields_and_field_types().items()]
        for f in out[key]:
            if f.type not in cdr.PRIMITIVES and f.type != "string":
                package, name = f.type.split("/")
                pending.append(getattr(importlib.import_module(f"{package}.msg"), name))
    return out


def _type_name(cls: type) -> str:
    return f"{cls.__module__.split('.')[0]}/{cls.__name__}"


def serialize_unpadded(message: Any) -> bytes:
    """rclpy's CDR bytes of ``message`` up to its last value: rclpy's serializer leaves bytes
    after some messages (empty sequences of doubles at the end: 4 bytes after a JointState with
    an empty effort, 8 with empty velocity and effort), rmw's writer does not, and a bag reader
    (:func:`cdr.walk`) takes at most 3 bytes of padding. The walk of the known type finds the end."""
    raw = serialize_message(message)
    return raw[: cdr.walk(raw, _type_name(type(message)), _schemas(type(message)), max_padding=64).end]


class PackedMessage:
    """``template`` serialized once; :meth:`pack` returns its bytes with new values for the
    numeric fields under ``prefixes`` (``"header.stamp"``, ``"pose"``, ``"position"``), given in
    the order of the message definition. Strings and sequence lengths stay the template's."""

    def __init__(self, template: Any, prefixes: Sequence[str]) -> None:
        raw = serialize_unpadded(template)
        layout = cdr.walk(raw, _type_name(type(template)), _schemas(type(template)))
        wanted = [
            (offset, dtype, count)
            for path, dtype, offset, count, _ in layout.numbers
            if count and any(path == p or path.startswith(p + ".") for p in prefixes)
        ]
        if not wanted:
            raise ValueError(f"no numeric fields under {list(prefixes)} in {_type_name(type(template))}")
        # Fields that follow each other in the bytes are packed by one Struct.
        runs: list[list[Any]] = []  # [offset, format, number of values]
        for offset, dtype, count in wanted:
            code = _STRUCT[dtype.str[1:]] * count
            if runs and runs[-1][0] + struct.calcsize("<" + runs[-1][1]) == offset:
                runs[-1][1] += code
                runs[-1][2] += count
            else:
                runs.append([offset, code, count])
        order = cdr.byte_order(raw)
        self._buffer = bytearray(raw)
        self._runs = []
        start = 0
        for offset, codes, count in runs:
            self._runs.append((struct.Struct(order + codes), offset, start, start + count))
            start += count
        self.size = start

    def pack(self, values: Sequence[Any]) -> bytes:
        """The message's bytes with ``values`` (``size`` numbers) written in."""
        buffer = self._buffer
        for run, offset, start, stop in self._runs:
            run.pack_into(buffer, offset, *values[start:stop])
        return bytes(buffer)
