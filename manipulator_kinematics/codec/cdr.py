"""ROS 2 CDR (XCDR1, as rmw_fastrtps writes it) decoded and encoded with numpy, many messages at once.

Messages of one type whose strings and sequence lengths agree share one byte layout. The layout
is found by walking one message; every other message of the same size that has the same bytes at
the layout's *structural* positions (encapsulation header, length prefixes, string contents)
shares it, so its numbers are read for all of them with one slice of a 2-D byte array. Python
work is per layout, not per message: the 3-name JointState of a whole bag has one layout.

Paths name leaves: ``header.stamp.sec``, ``position``; elements of a sequence or array of
messages are indexed (``layout.dim[0].label``). Numeric leaves come out as ``(N,)`` arrays, arrays
and sequences of numbers as ``(N, k)``; strings as numpy unicode arrays of the same shapes.
Sequences whose length varies between messages are padded (numbers to float64 NaN, strings '').

The types are plain :class:`Field` lists, so this module knows no bag library.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: ROS 2 primitive type -> numpy dtype (byte order added per message).
PRIMITIVES: dict[str, str] = {
    "bool": "?",
    "byte": "u1",
    "char": "u1",
    "octet": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
}
SEQUENCE = -1
# Encapsulation kinds (second header byte): 0 plain CDR big endian, 1 little endian.
_LITTLE, _BIG = 1, 0
_HEADER = 4


class CdrError(ValueError):
    """Bytes that do not decode as the stated type; the message says where."""


@dataclass(frozen=True)
class Field:
    """One field of a message type: ``type`` is a PRIMITIVES key, ``string`` or a message type name;
    ``array`` is None for one value, n >= 0 for a fixed array of n, SEQUENCE for a sequence."""

    name: str
    type: str
    array: int | None = None


Schemas = Mapping[str, Sequence[Field]]


@dataclass
class Layout:
    """Where one message's values are: numbers (path, dtype, byte offset, count, is_array),
    strings (path, values, is_array), and the structural byte offsets that fix all of it."""

    numbers: list[tuple[str, np.dtype, int, int, bool]] = field(default_factory=list)
    strings: list[tuple[str, list[str], bool]] = field(default_factory=list)
    structural: list[int] = field(default_factory=lambda: [0, 1])
    end: int = 0  # where the message's last value ends (serializers may pad after it)


def byte_order(raw: bytes) -> str:
    """``<`` or ``>`` (struct/numpy notation) from the encapsulation header; CdrError unless the
    bytes start with plain CDR's."""
    if len(raw) < _HEADER or raw[0] != 0 or raw[1] not in (_LITTLE, _BIG):
        raise CdrError(f"not plain CDR: encapsulation header {raw[:_HEADER].hex() or 'missing'}")
    return "<" if raw[1] == _LITTLE else ">"


def aligned(pos: int, size: int) -> int:
    """``pos`` moved on to where a value of ``size`` bytes starts: alignment counts from the end of
    the encapsulation header and never exceeds 8."""
    size = min(size, 8)
    return _HEADER + ((pos - _HEADER + size - 1) & -size)


class _Walker:
    """Follows one message through its type, recording the layout."""

    def __init__(self, raw: bytes, schemas: Schemas) -> None:
        self.order = byte_order(raw)
        self.raw, self.schemas = raw, schemas
        self.layout = Layout()
        self.pos = _HEADER

    def _align(self, size: int) -> None:
        self.pos = aligned(self.pos, size)

    def _need(self, size: int, what: str) -> None:
        if self.pos + size > len(self.raw):
            raise CdrError(f"{what} at byte {self.pos} runs past the end of the {len(self.raw)}-byte message")

    def _count(self, what: str) -> int:
        self._align(4)
        self._need(4, what)
        value = int(np.frombuffer(self.raw, self.order + "u4", 1, self.pos)[0])
        self.layout.structural.extend(range(self.pos, self.pos + 4))
        self.pos += 4
        return value

    def _string(self, what: str) -> str:
        size = self._count(what)
        self._need(size, what)
        if size < 1 or self.raw[self.pos + size - 1] != 0:
            raise CdrError(f"{what} at byte {self.pos} is not a NUL-terminated string")
        text = self.raw[self.pos : self.pos + size - 1].decode("utf-8", errors="replace")
        self.layout.structural.extend(range(self.pos, self.pos + size))
        self.pos += size
        return text

    def message(self, msgtype: str, prefix: str = "") -> None:
        try:
            fields = self.schemas[msgtype]
        except KeyError:
            raise CdrError(f"no definition of message type {msgtype!r}") from None
        for f in fields:
            path = prefix + f.name
            count = 1 if f.array is None else f.array if f.array >= 0 else self._count(f"length of {path}")
            is_array = f.array is not None
            if f.type in PRIMITIVES:
                dtype = np.dtype(self.order + PRIMITIVES[f.type])
                if count:
                    self._align(dtype.itemsize)
                self._need(count * dtype.itemsize, path)
                self.layout.numbers.append((path, dtype, self.pos, count, is_array))
                self.pos += count * dtype.itemsize
            elif f.type == "string":
                values = [self._string(path) for _ in range(count)]
                self.layout.strings.append((path, values, is_array))
            elif is_array:
                for i in range(count):
                    self.message(f.type, f"{path}[{i}].")
            else:
                self.message(f.type, path + ".")


def walk(raw: bytes, msgtype: str, schemas: Schemas, max_padding: int = 3) -> Layout:
    """Where the values of one serialized ``msgtype`` message are; CdrError when it is not one."""
    walker = _Walker(raw, schemas)
    walker.message(msgtype)
    # Serializers may pad the end, to a multiple of 4 bytes on the wire; anything longer is not this type.
    if len(raw) - walker.pos > max_padding:
        raise CdrError(f"{len(raw) - walker.pos} bytes left over after the message ends at byte {walker.pos}")
    walker.layout.end = walker.pos
    return walker.layout


def decode(
    data: np.ndarray, starts: np.ndarray, sizes: np.ndarray, msgtype: str, schemas: Schemas
) -> dict[str, np.ndarray]:
    """Decode N messages of ``msgtype``: message i is ``data[starts[i]:starts[i] + sizes[i]]``.

    Raises CdrError naming the first message (by its index) that does not decode.
    """
    data = np.asarray(data, dtype=np.uint8)
    starts = np.asarray(starts, dtype=np.int64)
    sizes = np.asarray(sizes, dtype=np.int64)
    n = len(starts)
    if n == 0:
        # No message to walk: the leaves of a default message, with no rows.
        template = np.frombuffer(encode(msgtype, schemas, 1, {})[0], np.uint8)
        one = decode(template, np.zeros(1, np.int64), np.array([len(template)]), msgtype, schemas)
        return {path: values[:0] for path, values in one.items()}
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    order: list[str] = []
    arrays: set[str] = set()

    def add(path: str, rows: np.ndarray, values: np.ndarray, is_array: bool) -> None:
        if path not in pieces:
            pieces[path] = []
            order.append(path)
        if is_array:
            arrays.add(path)
        pieces[path].append((rows, values))

    for size in np.unique(sizes):
        rows = np.flatnonzero(sizes == size)
        # A (rows, size) copy of every message of this size: one memcpy per row, no index array.
        block = (
            sliding_window_view(data, int(size))[starts[rows]] if size else np.empty((len(rows), 0), np.uint8)
        )
        while len(rows):
            first = int(rows[0])
            try:
                layout = walk(block[0].tobytes(), msgtype, schemas)
            except CdrError as error:
                raise CdrError(f"message {first} ({size} bytes) is not a valid {msgtype}: {error}") from None
            same = np.ones(len(rows), dtype=bool)
            for begin, stop in _runs(layout.structural):
                # Each run compared as one opaque value per row (a memcmp), not byte by byte.
                run = np.ascontiguousarray(block[:, begin:stop]).view(np.dtype((np.void, stop - begin)))[:, 0]
                same &= run == run[0]
            everything = bool(same.all())
            mine, part = (rows, block) if everything else (rows[same], block[same])
            for path, dtype, offset, count, is_array in layout.numbers:
                raw = np.ascontiguousarray(part[:, offset : offset + count * dtype.itemsize])
                values = raw.view(dtype).reshape(len(mine), count).astype(dtype.newbyteorder("="))
                add(path, mine, values, is_array)
            for path, texts, is_array in layout.strings:
                add(path, mine, np.array(texts, dtype=str).reshape(1, len(texts)), is_array)
            if everything:
                break
            rows, block = rows[~same], block[~same]
    return {path: _assemble(pieces[path], n, path in arrays) for path in order}


def _runs(positions: list[int]) -> list[tuple[int, int]]:
    """Sorted byte positions as (begin, end) runs, so they compare as slices rather than gathers."""
    runs: list[tuple[int, int]] = []
    for p in sorted(positions):
        if runs and runs[-1][1] == p:
            runs[-1] = (runs[-1][0], p + 1)
        else:
            runs.append((p, p + 1))
    return runs


def _assemble(pieces: list[tuple[np.ndarray, np.ndarray]], n: int, is_array: bool) -> np.ndarray:
    """One array for all messages from the per-layout pieces, padding where layouts differ."""
    if len(pieces) == 1 and len(pieces[0][0]) == n:
        # One layout for every message (the usual case): rows are already 0..n-1 in order.
        # Strings are one row for the whole layout: a read-only broadcast, not n copies.
        values = np.broadcast_to(pieces[0][1], (n, pieces[0][1].shape[1]))
        return values if is_array else values[:, 0]
    width = max(values.shape[1] for _, values in pieces)
    covered = sum(len(rows) for rows, _ in pieces)
    text = pieces[0][1].dtype.kind == "U"
    uniform = covered == n and all(values.shape[1] == width for _, values in pieces)
    if text:
        out = np.full((n, width), "", dtype=np.result_type(*(values.dtype for _, values in pieces)))
    elif uniform:
        out = np.empty((n, width), dtype=np.result_type(*(values.dtype for _, values in pieces)))
    else:
        out = np.full((n, width), np.nan)
    for rows, values in pieces:
        out[rows, : values.shape[1]] = values
    return out if is_array else out[:, 0]


def encode(msgtype: str, schemas: Schemas, count: int, values: Mapping[str, Any]) -> list[bytes]:
    """CDR (little endian) of ``count`` messages of ``msgtype`` from leaf values by path.

    A single-number leaf takes a scalar (same in every message) or shape ``(count,)``; an array or
    sequence of numbers takes ``(k,)`` (same in every message) or ``(count, k)``. Strings are
    ``str`` and string sequences lists of ``str``, the same in every message. Missing leaves are
    zero, empty or, for a sequence of messages, no elements.
    """
    template = bytearray(b"\x00\x01\x00\x00")
    slots: list[tuple[int, np.ndarray]] = []
    _encode_message(template, msgtype, "", schemas, values, count, slots)
    template.extend(b"\x00" * (-len(template) % 4))
    block = np.tile(np.frombuffer(bytes(template), np.uint8), (count, 1))
    for offset, column in slots:
        block[:, offset : offset + column.shape[1]] = column
    return [row.tobytes() for row in block]


def _numbers(given: Any, f: Field, dtype: np.dtype, count: int) -> np.ndarray:
    """``given`` as a (count, k) array of ``dtype`` for field ``f``."""
    array = np.asarray(given, dtype=dtype)
    if f.array is None:
        return np.broadcast_to(array, (count,)).reshape(count, 1)
    if array.ndim == 2:
        if array.shape[0] != count:
            raise ValueError(f"{f.name}: {array.shape[0]} rows for {count} messages")
        return array
    width = f.array if f.array >= 0 and array.ndim == 0 else array.size
    return np.broadcast_to(array, (count, width))


def _encode_message(
    out: bytearray,
    msgtype: str,
    prefix: str,
    schemas: Schemas,
    values: Mapping[str, Any],
    count: int,
    slots: list[tuple[int, np.ndarray]],
) -> None:
    def align(size: int) -> None:
        out.extend(b"\x00" * (-(len(out) - _HEADER) % min(size, 8)))

    def u32(value: int) -> None:
        align(4)
        out.extend(int(value).to_bytes(4, "little"))

    def string(text: str) -> None:
        data = text.encode() + b"\x00"
        u32(len(data))
        out.extend(data)

    for f in schemas[msgtype]:
        path = prefix + f.name
        given = values.get(path)
        if f.type in PRIMITIVES:
            dtype = np.dtype("<" + PRIMITIVES[f.type])
            empty = given is None and f.array == SEQUENCE
            column = (
                np.zeros((count, 0), dtype)
                if empty
                else _numbers(0 if given is None else given, f, dtype, count)
            )
            if f.array is not None and f.array >= 0 and column.shape[1] != f.array:
                raise ValueError(f"{path}: {column.shape[1]} values for an array of {f.array}")
            if f.array == SEQUENCE:
                u32(column.shape[1])
            if column.shape[1]:
                align(dtype.itemsize)
                slots.append((len(out), np.ascontiguousarray(column).view(np.uint8)))
                out.extend(b"\x00" * (column.shape[1] * dtype.itemsize))
        elif f.type == "string":
            texts = [given or ""] if f.array is None else list(given or [])
            if f.array == SEQUENCE:
                u32(len(texts))
            for text in texts:
                string(text)
        elif f.array is None:
            _encode_message(out, f.type, path + ".", schemas, values, count, slots)
        else:
            given_elements = {
                key[len(path) + 1 :].split("]")[0] for key in values if key.startswith(path + "[")
            }
            elements = f.array if f.array >= 0 else len(given_elements)
            if f.array == SEQUENCE:
                u32(elements)
            for i in range(elements):
                _encode_message(out, f.type, f"{path}[{i}].", schemas, values, count, slots)
