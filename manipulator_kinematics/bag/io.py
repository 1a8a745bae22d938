"""rosbag2 bags (mcap or sqlite3) written and read: the one module that knows bag formats and rosbags.

Writing goes through rosbags' writer, with a :meth:`BagWriter.flush` that makes everything written
so far survive a killed process: for mcap the open chunk is closed (a complete chunk record
followed by its message indexes) and the file buffer handed to the OS; for sqlite3 the open
transaction is committed. ``metadata.yaml`` is written when the bag is opened and rewritten on
every flush, so a bag cut short by SIGKILL is still a rosbag2 directory whose data file ends
after the last flushed chunk (mcap) or holds the last committed transaction (sqlite3).

Reading does not go message by message through rosbags (about 35 us per message with its
deserialiser): the mcap records are indexed with a short Python loop and the messages of a topic
are decoded together by :mod:`manipulator_kinematics.bag.cdr`. An mcap file without its footer
(the recorder did not finish) is an error unless ``recover=True``, which keeps every complete
record before the cut. Types come from the bag's own definitions, else from ROS 2 Jazzy.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import struct
import time
import zlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.lib.stride_tricks import sliding_window_view
from rosbags.interfaces import (
    Nodetype,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Writer, WriterError
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.rosbag2.metadata import dump_qos_v9, parse_qos
from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore

from manipulator_kinematics.bag import cdr

STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
_SUFFIX = {"mcap": ".mcap", "sqlite3": ".db3"}
_MCAP_MAGIC = b"\x89MCAP0\r\n"
# Files a bag directory may hold; --overwrite removes a directory only if it holds nothing else.
_BAG_FILES = (".mcap", ".db3", ".db3-journal", ".db3-wal", ".db3-shm", ".yaml", ".yaml.tmp")


class BagError(Exception):
    """A bag that cannot be written or read as asked; the message says what and where."""


@dataclass(frozen=True)
class TopicQos:
    """What a topic's publishers offered, reduced to what a subscriber or replayer must match."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10


@dataclass(frozen=True)
class TopicInfo:
    name: str
    msgtype: str
    count: int
    qos: TopicQos | None


class _Types:
    """Message types: ROS 2 Jazzy's plus definitions found in a bag or in the ament index."""

    def __init__(self) -> None:
        self.store = get_typestore(Stores.ROS2_JAZZY)
        self._schemas: dict[str, list[cdr.Field]] = {}

    def add_definition(self, msgtype: str, encoding: str, text: str) -> None:
        """Register a bag's definition of ``msgtype`` (and what it embeds) unless already known."""
        if msgtype in self.store.fielddefs or not text:
            return
        try:
            if encoding in ("ros2msg", "msg"):
                types = get_types_from_msg(text, msgtype)
            elif encoding in ("ros2idl", "idl", "omgidl"):
                types = get_types_from_idl(text)
            else:
                return
            self.store.register(types)
        except (TypesysError, ValueError, SyntaxError) as error:
            raise BagError(f"the bag's definition of {msgtype} does not parse: {error}") from None

    def require(self, msgtype: str, where: str) -> None:
        """Make ``msgtype`` known, looking for its .msg file in installed packages if needed."""
        if msgtype in self.store.fielddefs:
            return
        pending, found = [msgtype], {}
        while pending:
            name = pending.pop()
            if name in found or name in self.store.fielddefs:
                continue
            text = _installed_msg_file(name)
            if text is None:
                raise BagError(
                    f"{where}: unknown message type {name!r} (not a ROS 2 Jazzy type, no definition "
                    f"in the bag, no {name}.msg installed)"
                )
            try:
                found.update(get_types_from_msg(text, name))
            except (TypesysError, ValueError, SyntaxError) as error:
                raise BagError(f"{where}: the installed {name}.msg does not parse: {error}") from None
            pending.extend(sub for _, fields in found.values() for _, desc in fields for sub in _names(desc))
        self.store.register(found)

    def schemas(self, msgtype: str, where: str) -> dict[str, list[cdr.Field]]:
        """``msgtype`` and every type it embeds as :class:`cdr.Field` lists."""
        self.require(msgtype, where)
        out: dict[str, list[cdr.Field]] = {}
        pending = [msgtype]
        while pending:
            name = pending.pop()
            if name in out:
                continue
            if name not in self._schemas:
                self.require(name, where)
                self._schemas[name] = [_field(fname, desc) for fname, desc in self.store.fielddefs[name][1]]
            out[name] = self._schemas[name]
            pending.extend(f.type for f in out[name] if f.type not in cdr.PRIMITIVES and f.type != "string")
        return out


def _names(desc: Any) -> list[str]:
    kind, detail = desc
    if kind == Nodetype.NAME:
        return [detail]
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return _names(detail[0])
    return []


def _field(name: str, desc: Any) -> cdr.Field:
    kind, detail = desc
    if kind == Nodetype.BASE:
        if detail[0] not in cdr.PRIMITIVES and detail[0] != "string":
            raise BagError(f"field {name}: type {detail[0]} is not supported")
        return cdr.Field(name, detail[0])
    if kind == Nodetype.NAME:
        return cdr.Field(name, detail)
    sub, size = detail
    element = _field(name, sub)
    return cdr.Field(name, element.type, size if kind == Nodetype.ARRAY else cdr.SEQUENCE)


def _installed_msg_file(msgtype: str) -> str | None:
    parts = msgtype.split("/")
    if len(parts) != 3:
        return None
    package, _, name = parts
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:
        return None
    try:
        path = Path(get_package_share_directory(package)) / "msg" / f"{name}.msg"
    except (PackageNotFoundError, OSError):  # OSError: no ament index in this environment at all
        return None
    return path.read_text(encoding="utf-8") if path.is_file() else None


def encode_messages(msgtype: str, count: int, values: Mapping[str, Any]) -> list[bytes]:
    """CDR bytes of ``count`` messages of ``msgtype`` from leaf values by path (see :func:`cdr.encode`),
    e.g. ``encode_messages("sensor_msgs/msg/JointState", n, {"header.stamp.sec": s, "name": [...],
    "position": p})``: what a bag written without rclpy stores."""
    return cdr.encode(msgtype, _Types().schemas(msgtype, msgtype), count, values)


def decode_messages(msgtype: str, raws: Sequence[bytes]) -> dict[str, np.ndarray]:
    """Leaf values by path of CDR messages of ``msgtype`` (the inverse of :func:`encode_messages`)."""
    sizes = np.fromiter(map(len, raws), np.int64, len(raws))
    data = np.frombuffer(b"".join(raws), np.uint8)
    try:
        return cdr.decode(data, np.cumsum(sizes) - sizes, sizes, msgtype, _Types().schemas(msgtype, msgtype))
    except cdr.CdrError as error:
        raise BagError(str(error)) from None


# ------------------------------------------------------------------------------------------------ writing


def _qos_to_rosbags(qos: TopicQos) -> Qos:
    zero = QosTime(0, 0)
    return Qos(
        QosHistory.KEEP_LAST,
        qos.depth,
        QosReliability.RELIABLE if qos.reliable else QosReliability.BEST_EFFORT,
        QosDurability.TRANSIENT_LOCAL if qos.transient_local else QosDurability.VOLATILE,
        zero,
        zero,
        QosLiveliness.AUTOMATIC,
        zero,
        False,
    )


def _qos_from_rosbags(profiles: list[Qos]) -> TopicQos | None:
    if not profiles:
        return None
    return TopicQos(
        reliable=all(p.reliability == QosReliability.RELIABLE for p in profiles),
        transient_local=all(p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles),
        depth=max(p.depth for p in profiles),
    )


def _remove_bag(path: Path) -> None:
    """Delete an existing bag for --overwrite, refusing anything that does not look like one."""
    if path.is_dir():
        strangers = [p.name for p in path.iterdir() if p.is_dir() or not p.name.endswith(_BAG_FILES)]
        if strangers:
            raise BagError(
                f"{path} exists and holds more than a bag ({', '.join(sorted(strangers)[:5])}); "
                f"not removing it"
            )
        shutil.rmtree(path)
    else:
        raise BagError(f"{path} exists and is not a bag directory; not removing it")


class BagWriter:
    """A rosbag2 bag written incrementally from raw CDR messages.

    ``flush()`` (also done by ``write`` every ``flush_interval`` seconds) makes what was written
    survive SIGKILL; ``close()`` adds the mcap summary and the final metadata. Use as a context
    manager, or call ``close()``.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        storage: str = "mcap",
        overwrite: bool = False,
        flush_interval: float = 0.5,
    ) -> None:
        if storage not in STORAGES:
            raise BagError(f"unknown storage {storage!r}; choose one of {sorted(STORAGES)}")
        self.path = Path(path)
        if self.path.exists() or self.path.is_symlink():
            if not overwrite:
                raise BagError(f"{self.path} exists; not overwriting it (use --overwrite / overwrite=True)")
            _remove_bag(self.path)
        self.storage = storage
        self.flush_interval = flush_interval
        self._types = _Types()
        self._writer = Writer(self.path, version=Writer.VERSION_LATEST, storage_plugin=STORAGES[storage])
        try:
            self._writer.open()
        except (WriterError, OSError) as error:
            raise BagError(f"cannot create bag {self.path}: {error}") from None
        if storage == "sqlite3":
            # A commit hands the data to the OS without waiting for the disk: that survives a
            # killed process, and an fsync every flush stalled the recorder for up to a second.
            self._writer.storage.conn.execute("PRAGMA synchronous=OFF")
        self._connections: dict[str, Any] = {}
        self._qos: dict[str, list[Qos]] = {}
        self._last_flush = time.monotonic()
        self._write_metadata()

    @property
    def data_file(self) -> Path:
        return self.path / f"{self.path.name}{_SUFFIX[self.storage]}"

    def add_topic(self, name: str, msgtype: str, qos: TopicQos | None = None) -> None:
        """Declare a topic with its full type definition (found for any ROS 2 Jazzy or installed type)."""
        if name in self._connections:
            raise BagError(f"topic {name} added twice")
        self._types.require(msgtype, f"topic {name}")
        self._qos[name] = [_qos_to_rosbags(qos)] if qos else []
        self._connections[name] = self._writer.add_connection(
            name, msgtype, typestore=self._types.store, offered_qos_profiles=self._qos[name]
        )
        self._write_metadata()

    def write(self, topic: str, stamp_ns: int, raw: bytes | memoryview) -> None:
        """Store one serialised message (CDR bytes exactly as received) at record time ``stamp_ns``."""
        try:
            connection = self._connections[topic]
        except KeyError:
            raise BagError(f"topic {topic} was not added to the bag") from None
        self._writer.write(connection, stamp_ns, raw)
        self.flush_if_due()

    def flush_if_due(self) -> None:
        """Flush if ``flush_interval`` has passed since the last flush."""
        if time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()

    def flush(self) -> None:
        """Make every message written so far readable after the process dies."""
        storage = self._writer.storage
        if storage is None:
            return
        if self.storage == "mcap":
            if storage.chunk.bio.tell():
                storage.close_chunk()
            storage.bio.flush()
        else:
            storage.conn.commit()
        self._last_flush = time.monotonic()
        self._write_metadata()

    def close(self) -> None:
        if self._writer.storage is not None:
            self._writer.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _write_metadata(self) -> None:
        """The metadata rosbags writes at close, with the counts so far; replaced atomically."""
        w = self._writer
        count = sum(w.counts.values())
        start = w.min_timestamp if count else 0
        duration = max(0, w.max_timestamp - w.min_timestamp) if count else 0
        info = {
            "version": w.version,
            "storage_identifier": self.storage,
            "relative_file_paths": [self.data_file.name],
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": c.topic,
                        "type": c.msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": dump_qos_v9(self._qos[c.topic]),
                        "type_description_hash": c.digest,
                    },
                    "message_count": w.counts[c.id],
                }
                for c in self._connections.values()
            ],
            "compression_format": "",
            "compression_mode": "",
            "files": [
                {
                    "path": self.data_file.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": count,
                }
            ],
            "custom_data": None,
            "ros_distro": "rosbags",
        }
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(
            yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False), encoding="utf-8"
        )
        tmp.replace(self.path / "metadata.yaml")


# ------------------------------------------------------------------------------------------------ reading


@dataclass
class TopicArrays:
    """Every message of one topic, decoded: ``fields[path]`` has one row per message, in record order."""

    topic: str
    msgtype: str
    log_time: np.ndarray
    fields: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.log_time)

    def __getitem__(self, path: str) -> np.ndarray:
        try:
            return self.fields[path]
        except KeyError:
            raise KeyError(f"{self.topic} ({self.msgtype}) has no field {path!r}") from None

    def stamp_ns(self, header: str = "header") -> np.ndarray:
        """Header stamps as int64 nanoseconds."""
        return self[f"{header}.stamp.sec"].astype(np.int64) * 1_000_000_000 + self[f"{header}.stamp.nanosec"]

    def by_name(self, path: str, names: Sequence[str], name_path: str = "name") -> np.ndarray:
        """``(N, len(names))`` values of a JointState-like field in the order of ``names``;
        NaN where a message lacks the name or the value."""
        labels, values = self[name_path], self[path]
        out = np.full((len(self), len(names)), np.nan)
        rows = np.arange(len(self))
        for j, name in enumerate(names):
            match = labels == name
            column = np.argmax(match, axis=1)
            have = match.any(axis=1) & (column < values.shape[1])
            out[have, j] = values[rows[have], column[have]]
        return out


@dataclass(frozen=True)
class _Connection:
    topic: str
    msgtype: str
    encoding: str
    qos: TopicQos | None


class _Corrupt(ValueError):
    """Bytes inside a data file that are not what the format says must be there."""


class _Index:
    """Where each message is: its connection, record time and byte range in the joined ``buffers``."""

    def __init__(self) -> None:
        self.connections: dict[int, _Connection] = {}
        self.definitions: dict[str, tuple[str, str]] = {}
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.buffers: list[bytes] = []
        self.used = 0

    def add_buffer(self, data: bytes) -> int:
        """Keep ``data``; return the offset its byte 0 has in the joined buffers."""
        base = self.used
        self.buffers.append(data)
        self.used += len(data)
        return base

    def add_messages(self, conn: Any, log_time: Any, start: Any, size: Any) -> None:
        self.parts.append(tuple(np.asarray(x, dtype=np.int64) for x in (conn, log_time, start, size)))

    @property
    def count(self) -> int:
        return sum(len(part[0]) for part in self.parts)


def _gather(data: np.ndarray, positions: np.ndarray, dtype: str) -> np.ndarray:
    """The ``dtype`` value at each byte position of ``data``."""
    width = np.dtype(dtype).itemsize
    return sliding_window_view(data, width)[positions].view(dtype)[:, 0].astype(np.int64)


class _McapIndexer:
    """Indexes the records of MCAP files (chunks opened) into an :class:`_Index`.

    A chunk whose message index records account for every byte of it (all it holds are messages)
    is indexed from them with numpy; any other chunk, and records outside chunks, are walked.
    """

    _RECORD = struct.Struct("<BQ")
    _MESSAGE = struct.Struct("<HIQ")

    def __init__(self, index: _Index) -> None:
        self.index = index
        self.schemas: dict[int, str] = {}

    def file(self, raw: bytes) -> tuple[int, str | None]:
        """Index a whole file: (end of the last complete record, why the file ends early or None)."""
        if not raw.startswith(_MCAP_MAGIC):
            raise _Corrupt("not an MCAP file (wrong magic bytes)")
        base = self.index.add_buffer(raw)
        pos, size = len(_MCAP_MAGIC), len(raw)
        chunk: tuple[bytes, int, int, int] | None = None  # the last chunk, until its message indexes are read
        offsets: list[np.ndarray] = []
        while True:
            problem = None
            if pos == size:
                problem = f"ends without its summary and footer at byte {size}"
            elif pos + 9 > size:
                problem = f"ends inside a record at byte {size} (truncated)"
            else:
                op, length = self._RECORD.unpack_from(raw, pos)
                body, end = pos + 9, pos + 9 + length
                if pos == len(_MCAP_MAGIC) and op != 0x01:
                    raise _Corrupt("no MCAP header record after the magic bytes")
                if end > size:
                    problem = (
                        f"the record at byte {pos} runs past the end of the file ({size} bytes): truncated"
                    )
                elif op == 0x07 and chunk is not None:
                    (n,) = struct.unpack_from("<I", raw, body + 2)
                    if 6 + n > length or n % 16:
                        raise _Corrupt(f"message index at byte {pos} has a bad length")
                    offsets.append(np.frombuffer(raw, "<u8", n // 8, body + 6)[1::2])
                    pos = end
                    continue
            if chunk is not None:
                self._chunk_messages(*chunk, offsets)
                chunk, offsets = None, []
            if problem is not None:
                return pos, problem
            if op == 0x02:
                if raw[end : end + 8] != _MCAP_MAGIC:
                    raise _Corrupt(f"the footer at byte {pos} is not followed by the closing magic bytes")
                return end, None
            if op == 0x06:
                chunk = self._open_chunk(raw, body, end, base)
            else:
                self._walk(raw, pos, end, base)
            pos = end

    def _open_chunk(self, raw: bytes, body: int, end: int, base: int) -> tuple[bytes, int, int, int]:
        """(buffer, first byte, end, base offset of the buffer) of a chunk's records, decompressed."""
        _, _, uncompressed_size, crc = struct.unpack_from("<QQQI", raw, body)
        compression, pos = _string(raw, body + 28, end)
        (length,) = struct.unpack_from("<Q", raw, pos)
        pos += 8
        if pos + length > end:
            raise _Corrupt(f"chunk data at byte {pos} runs past its record")
        if compression == "":
            records, first, stop = raw, pos, pos + length
        else:
            records = _decompress(compression, raw[pos : pos + length])
            first, stop, base = 0, len(records), self.index.add_buffer(records)
        if stop - first != uncompressed_size:
            raise _Corrupt(f"chunk holds {stop - first} bytes, its header says {uncompressed_size}")
        if crc and zlib.crc32(memoryview(records)[first:stop]) != crc:
            raise _Corrupt("chunk checksum mismatch")
        return records, first, stop, base

    def _chunk_messages(
        self, records: bytes, first: int, stop: int, base: int, offsets: list[np.ndarray]
    ) -> None:
        if offsets:
            data = np.frombuffer(records, np.uint8)
            at = first + np.sort(np.concatenate(offsets)).astype(np.int64)
            if at[0] == first and at[-1] + 31 <= stop and np.all(data[at] == 0x05):
                length = _gather(data, at + 1, "<u8")
                ends = at + 9 + length
                if ends[-1] == stop and np.array_equal(ends[:-1], at[1:]) and np.all(length >= 22):
                    self.index.add_messages(
                        _gather(data, at + 9, "<u2"),
                        _gather(data, at + 15, "<u8"),
                        base + at + 31,
                        length - 22,
                    )
                    return
        self._walk(records, first, stop, base)

    def _walk(self, buf: bytes, pos: int, stop: int, base: int) -> None:
        """Index the records in ``buf[pos:stop]`` one by one."""
        index, record, message = self.index, self._RECORD.unpack_from, self._MESSAGE.unpack_from
        conn, times, starts, sizes = [], [], [], []
        while pos < stop:
            if pos + 9 > stop:
                raise _Corrupt(f"record header at byte {pos} cut off")
            op, length = record(buf, pos)
            body, end = pos + 9, pos + 9 + length
            if end > stop:
                raise _Corrupt(f"record at byte {pos} runs past its chunk or file")
            if op == 0x05:
                if length < 22:
                    raise _Corrupt(f"message record at byte {pos} is too short")
                channel, _, log_time = message(buf, body)
                conn.append(channel)
                times.append(log_time)
                starts.append(base + body + 22)
                sizes.append(length - 22)
            elif op == 0x01:
                profile, _ = _string(buf, body, end)
                if profile != "ros2":
                    raise _Corrupt(f"MCAP profile {profile!r}: not a ROS 2 bag")
            elif op == 0x03:
                (sid,) = struct.unpack_from("<H", buf, body)
                name, at = _string(buf, body + 2, end)
                encoding, at = _string(buf, at, end)
                text, _ = _string(buf, at, end)
                self.schemas[sid] = name
                index.definitions.setdefault(name, (encoding, text))
            elif op == 0x04:
                cid, sid = struct.unpack_from("<HH", buf, body)
                topic, at = _string(buf, body + 4, end)
                encoding, at = _string(buf, at, end)
                qos = _parse_qos(_string_map(buf, at, end).get("offered_qos_profiles"))
                if sid and sid not in self.schemas:
                    raise _Corrupt(f"channel {topic} refers to schema {sid}, not declared before it")
                index.connections.setdefault(
                    cid, _Connection(topic, self.schemas.get(sid, ""), encoding, qos)
                )
            elif op == 0x00:
                raise _Corrupt(f"invalid record (opcode 0) at byte {pos}")
            elif op == 0x06:
                raise _Corrupt(f"chunk inside a chunk at byte {pos}")
            pos = end
        if conn:
            index.add_messages(conn, times, starts, sizes)


def _string(buf: bytes, pos: int, end: int) -> tuple[str, int]:
    if pos + 4 > end:
        raise _Corrupt(f"string length at byte {pos} runs past its record")
    (n,) = struct.unpack_from("<I", buf, pos)
    if pos + 4 + n > end:
        raise _Corrupt(f"string at byte {pos} runs past its record")
    return bytes(buf[pos + 4 : pos + 4 + n]).decode("utf-8", errors="replace"), pos + 4 + n


def _string_map(buf: bytes, pos: int, end: int) -> dict[str, str]:
    (n,) = struct.unpack_from("<I", buf, pos)
    pos, stop, out = pos + 4, pos + 4 + n, {}
    if stop > end:
        raise _Corrupt(f"map at byte {pos - 4} runs past its record")
    while pos < stop:
        key, pos = _string(buf, pos, stop)
        out[key], pos = _string(buf, pos, stop)
    return out


def _decompress(compression: str, data: bytes) -> bytes:
    if compression == "zstd":
        try:
            from compression import zstd  # Python 3.14
        except ImportError:
            from backports import zstd
        return zstd.decompress(data)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise _Corrupt(f"unknown chunk compression {compression!r}")


def _parse_qos(text: str | None) -> TopicQos | None:
    if not text:
        return None
    try:
        return _qos_from_rosbags(parse_qos(text))
    except Exception:
        return None


def _load_sqlite(path: Path, index: _Index, recover: bool) -> str | None:
    """Index an SQLite bag. A journal left by a killed writer holds an interrupted transaction:
    with ``recover`` SQLite rolls it back (this writes the file), otherwise that is an error."""
    journal = path.with_name(path.name + "-journal")
    interrupted = journal.is_file() and journal.stat().st_size > 0
    if interrupted and not recover:
        raise BagError(
            f"{path}: an interrupted transaction is left in {journal.name} (the recorder did not "
            f"finish); --recover rolls it back and reads the committed messages"
        )
    try:
        db = sqlite3.connect(f"file:{path}?mode={'rw' if recover else 'ro'}", uri=True)
        try:
            topics = db.execute(
                "SELECT id, name, type, serialization_format, offered_qos_profiles FROM topics"
            )
            for tid, name, msgtype, encoding, qos in topics.fetchall():
                index.connections[tid] = _Connection(name, msgtype, encoding, _parse_qos(qos))
            has_definitions = db.execute(
                "SELECT 1 FROM sqlite_master WHERE type='table' AND name='message_definitions'"
            ).fetchone()
            if has_definitions:
                for msgtype, encoding, text in db.execute(
                    "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
                ):
                    index.definitions.setdefault(msgtype, (encoding, text))
            rows = db.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY id").fetchall()
        finally:
            db.close()
    except sqlite3.Error as error:
        raise BagError(f"{path}: not a readable rosbag2 SQLite file ({error})") from None
    if rows:
        ids, stamps, blobs = zip(*rows)
        sizes = np.fromiter(map(len, blobs), np.int64, len(blobs))
        base = index.add_buffer(b"".join(blobs))
        index.add_messages(ids, stamps, base + np.cumsum(sizes) - sizes, sizes)
    return f"{path}: rolled back the transaction the recorder left unfinished" if interrupted else None


class BagReader:
    """A rosbag2 bag (directory with metadata.yaml, or a single .mcap / .db3 file), indexed on open.

    ``recover=True`` reads an mcap file that lacks its summary and footer (a recorder that was
    killed, or a truncated copy) up to its last complete record instead of refusing it;
    ``recovered`` then says what was cut. For sqlite3 it lets SQLite roll back the transaction a
    killed recorder left open (in the ``-journal`` file), which rewrites the database file.
    """

    def __init__(self, path: str | os.PathLike[str], recover: bool = False) -> None:
        self.path = Path(path)
        self.recovered: str | None = None
        files, self.storage = self._files()
        index = _Index()
        for file in files:
            if self.storage == "mcap":
                self._scan_mcap(file, index, recover)
            else:
                self.recovered = _load_sqlite(file, index, recover) or self.recovered
        self._types = _Types()
        for msgtype, (encoding, text) in index.definitions.items():
            self._types.add_definition(msgtype, encoding, text)
        self._data = np.frombuffer(
            index.buffers[0] if len(index.buffers) == 1 else b"".join(index.buffers), np.uint8
        )
        conn, log_time, start, size = (
            np.concatenate([part[k] for part in index.parts]) if index.parts else np.empty(0, np.int64)
            for k in range(4)
        )
        undeclared = set(np.unique(conn).tolist()) - set(index.connections)
        if undeclared:
            raise BagError(
                f"{self.path}: corrupt: messages on channels {sorted(undeclared)} that are never declared"
            )
        self._topics: dict[str, TopicInfo] = {}
        self._encodings: dict[str, str] = {}
        self._messages: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for topic in dict.fromkeys(c.topic for c in index.connections.values()):
            ids = [cid for cid, c in index.connections.items() if c.topic == topic]
            kinds = sorted({(index.connections[cid].msgtype, index.connections[cid].encoding) for cid in ids})
            if len(kinds) > 1:
                raise BagError(f"{self.path}: topic {topic} is recorded with several types {kinds}")
            msgtype, self._encodings[topic] = kinds[0]
            rows = np.flatnonzero(np.isin(conn, ids))
            rows = rows[np.argsort(log_time[rows], kind="stable")]
            self._messages[topic] = (log_time[rows], start[rows], size[rows])
            qos = next((index.connections[cid].qos for cid in ids if index.connections[cid].qos), None)
            self._topics[topic] = TopicInfo(topic, msgtype, len(rows), qos)

    @property
    def topics(self) -> dict[str, TopicInfo]:
        return dict(self._topics)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    def arrays(self, topics: Iterable[str] | None = None) -> dict[str, TopicArrays]:
        """Decoded messages of ``topics`` (default: all), each topic in record-time order."""
        out = {}
        for topic in self.select(topics):
            info = self._topics[topic]
            if self._encodings[topic] != "cdr":
                raise BagError(f"topic {topic}: message encoding {self._encodings[topic]!r} is not CDR")
            log_time, start, size = self._messages[topic]
            schemas = self._types.schemas(info.msgtype, f"topic {topic}")
            try:
                fields = cdr.decode(self._data, start, size, info.msgtype, schemas)
            except cdr.CdrError as error:
                raise BagError(f"{self.path}: topic {topic}: {error}") from None
            out[topic] = TopicArrays(topic, info.msgtype, log_time, fields)
        return out

    def log_times(self, topic: str) -> np.ndarray:
        """Record times (ns) of ``topic``'s messages, in order, without decoding them."""
        return self._messages[self.select([topic])[0]][0]

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, bytes]]:
        """(topic, record time ns, CDR bytes) of ``topics`` (default: all) in record-time order."""
        selected = self.select(topics)
        if not selected:
            return
        parts = [self._messages[t] for t in selected]
        which = np.concatenate([np.full(len(p[0]), i) for i, p in enumerate(parts)])
        log_time, start, size = (np.concatenate([p[k] for p in parts]) for k in range(3))
        order = np.argsort(log_time, kind="stable")
        data = self._data
        for i in order.tolist():
            yield selected[which[i]], int(log_time[i]), data[start[i] : start[i] + size[i]].tobytes()

    def select(self, topics: Iterable[str] | None) -> list[str]:
        """``topics`` checked against the bag (all topics for None); BagError names missing ones."""
        if topics is None:
            return list(self._topics)
        selected = list(dict.fromkeys(topics))
        missing = [t for t in selected if t not in self._topics]
        if missing:
            raise BagError(
                f"{self.path}: no topic {', '.join(missing)} in the bag (it has "
                f"{', '.join(self._topics) or 'no topics'})"
            )
        return selected

    def _files(self) -> tuple[list[Path], str]:
        path = self.path
        if not path.exists():
            raise BagError(f"{path}: no such bag")
        if path.is_file():
            return [path], _storage_of(path)
        meta = path / "metadata.yaml"
        if meta.is_file():
            try:
                info = yaml.safe_load(meta.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
                storage = info.get("storage_identifier") or ""
                files = [path / name for name in info["relative_file_paths"]]
            except (yaml.YAMLError, KeyError, TypeError, UnicodeDecodeError) as error:
                raise BagError(f"{meta}: not rosbag2 metadata ({error})") from None
            if info.get("compression_mode"):
                raise BagError(
                    f"{path}: compressed bags ({info['compression_mode']} "
                    f"{info.get('compression_format')}) are not supported"
                )
            if storage not in STORAGES:
                raise BagError(f"{meta}: storage {storage!r} is not mcap or sqlite3")
            missing = [f.name for f in files if not f.is_file()]
            if missing:
                raise BagError(
                    f"{path}: data file(s) {', '.join(missing)} named in metadata.yaml are missing"
                )
            for file in files:
                if _storage_of(file) != storage:
                    raise BagError(f"{file}: is not an {storage} file as metadata.yaml says")
            return files, storage
        files = sorted(p for p in path.iterdir() if p.suffix in (".mcap", ".db3"))
        if not files:
            raise BagError(f"{path}: not a bag (no metadata.yaml, no .mcap or .db3 file)")
        storages = {_storage_of(f) for f in files}
        if len(storages) > 1:
            raise BagError(f"{path}: holds both mcap and sqlite3 files and no metadata.yaml")
        return files, storages.pop()

    def _scan_mcap(self, path: Path, index: _Index, recover: bool) -> None:
        before = index.count
        try:
            end, problem = _McapIndexer(index).file(path.read_bytes())
        except (_Corrupt, struct.error) as error:
            raise BagError(f"{path}: corrupt: {error}") from None
        if problem is None:
            return
        found = index.count - before
        if not recover:
            raise BagError(
                f"{path}: {problem}: the recorder did not finish it or the file was cut; "
                f"--recover reads the {found} messages before byte {end}"
            )
        self.recovered = f"{path}: {problem}; read the {found} messages before byte {end}"


def _storage_of(path: Path) -> str:
    with path.open("rb") as stream:
        head = stream.read(16)
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    if head.startswith(b"SQLite format 3\x00"):
        return "sqlite3"
    if not head:
        raise BagError(f"{path}: the file is empty")
    raise BagError(f"{path}: neither an MCAP nor an SQLite file")
