"""rosbag2 bags (mcap or sqlite3) read: messages indexed on open, decoded topic by topic.

A finished mcap file (its summary and chunk indexes in place) is read by rosbags' MCAP reader
(``rosbags.rosbag2.Reader``: 1.3 to 2.2 times faster than the ``mcap`` library's StreamReader,
benchmarks/bench_asbuilt_fleet.py), its message counts checked against the file's statistics.
Any other mcap file, or one that reader refuses, is read front to back by the ``mcap`` library's
StreamReader, so a file the recorder did not finish (no summary, no footer) reads up to its last
complete record: that is an error unless ``recover=True``. sqlite3 files are read with the
standard library. Messages are not deserialised one by one (rosbags takes about 35 us per
message): the messages of a topic are decoded together by
:mod:`manipulator_kinematics.codec.cdr`. Types come from the bag's own definitions, else from
ROS 2 Jazzy.

:class:`BagReader` holds a whole bag; :class:`BagStream` hands one out in windows of record time
(:meth:`BagStream.windows`), each decoded alone, for bags too long to hold at once.
"""

from __future__ import annotations

import heapq
import os
import sqlite3
from collections import Counter, deque
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from operator import attrgetter, itemgetter
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import InvalidMagic, RecordLengthLimitExceeded
from mcap.records import Channel, Chunk, Header, McapRecord, Message, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag2 import Reader as RosbagsReader

from manipulator_kinematics.bag.types import BagError, MessageTypes, TopicQos
from manipulator_kinematics.bag.writer import STORAGES
from manipulator_kinematics.codec import cdr
from manipulator_kinematics.param_files import ConfigError, read_document

_MCAP_MAGIC = b"\x89MCAP0\r\n"
# ROS 2 times are int64 nanoseconds; MCAP stores uint64, so anything above is a damaged record.
_MAX_TIME = np.iinfo(np.int64).max
#: Largest total size of a bag's data files (bytes), checked before :class:`BagReader` reads any:
#: it holds every message in memory (about the file's size again as arrays). :class:`BagStream`
#: holds one window at a time and takes any size.
MAX_BAG_BYTES = 2 << 30
# Messages gathered before they are turned into arrays: bounds the Python objects alive at once.
_BATCH = 1 << 16
_LOG_TIME, _CHANNEL, _DATA = attrgetter("log_time"), attrgetter("channel_id"), attrgetter("data")


@dataclass(frozen=True)
class TopicInfo:
    name: str
    msgtype: str
    count: int
    qos: TopicQos | None


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
        if not labels.size:  # no message (a window of a gap), or none names anything
            return out
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


class _Index:
    """Where each message is: its connection, record time and byte range in the joined ``buffers``."""

    def __init__(self) -> None:
        self.connections: dict[int, _Connection] = {}
        self.definitions: dict[str, tuple[str, str]] = {}
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.buffers: list[bytes] = []
        self.used = 0

    def add(self, conn: Any, log_time: Any, blobs: Sequence[bytes]) -> None:
        """Messages given as their connection ids, record times and CDR bytes."""
        sizes = np.fromiter(map(len, blobs), np.int64, len(blobs))
        self.buffers.append(b"".join(blobs))
        starts = self.used + np.cumsum(sizes) - sizes
        self.used += len(self.buffers[-1])
        self.parts.append((np.asarray(conn, np.int64), np.asarray(log_time, np.int64), starts, sizes))

    @property
    def count(self) -> int:
        return sum(len(part[0]) for part in self.parts)

    def absorb(self, other: _Index) -> None:
        """Everything ``other`` indexed, after what this one holds."""
        for cid, connection in other.connections.items():
            self.connections.setdefault(cid, connection)
        for msgtype, definition in other.definitions.items():
            self.definitions.setdefault(msgtype, definition)
        for conn, log_time, starts, sizes in other.parts:
            self.parts.append((conn, log_time, starts + self.used, sizes))
        self.buffers.extend(other.buffers)
        self.used += other.used


class _Corrupt(ValueError):
    """Records that are not what the format says must be there."""


class _McapRecords:
    """The records of one MCAP file, added to an :class:`_Index` as StreamReader hands them out."""

    def __init__(self, index: _Index) -> None:
        self.index = index
        self.schemas: dict[int, str] = {}
        self.messages: list[Message] = []

    def add(self, record: McapRecord, end: int) -> None:
        """``record``, which ends at byte ``end``, and the records of a chunk."""
        try:
            inner = breakup_chunk(record, validate_crc=True) if isinstance(record, Chunk) else (record,)
        except Exception as error:  # whatever the library's reads raise on bytes that make no sense
            raise _Corrupt(f"the chunk ending at byte {end}: {_describe(error)}") from None
        for r in inner:
            if isinstance(r, Message):
                self.messages.append(r)
            elif isinstance(r, Schema):
                self.schemas[r.id] = r.name
                self.index.definitions.setdefault(r.name, (r.encoding, r.data.decode("utf-8", "replace")))
            elif isinstance(r, Channel):
                if r.schema_id and r.schema_id not in self.schemas:
                    raise _Corrupt(f"channel {r.topic} refers to schema {r.schema_id}, not declared before")
                self.index.connections.setdefault(
                    r.id,
                    _Connection(
                        r.topic,
                        self.schemas.get(r.schema_id, ""),
                        r.message_encoding,
                        TopicQos.parse(r.metadata.get("offered_qos_profiles")),
                    ),
                )
            elif isinstance(r, Header) and r.profile != "ros2":
                raise _Corrupt(f"MCAP profile {r.profile!r}: not a ROS 2 bag")
        if len(self.messages) >= _BATCH:
            self.flush()

    def flush(self) -> None:
        messages, self.messages = self.messages, []
        log_time = np.fromiter(map(_LOG_TIME, messages), np.uint64, len(messages))
        late = np.flatnonzero(log_time > _MAX_TIME)
        if len(late):
            raise _Corrupt(f"a message's record time {log_time[late[0]]} ns is beyond int64 nanoseconds")
        self.index.add(list(map(_CHANNEL, messages)), log_time, list(map(_DATA, messages)))


def _describe(error: Exception) -> str:
    return str(error) or type(error).__name__


def _scan_mcap(path: Path, index: _Index) -> tuple[int, str | None]:
    """Index an MCAP file: (end of the last complete record, why the file ends early or None)."""
    size = path.stat().st_size
    records = _McapRecords(index)
    end = len(_MCAP_MAGIC)
    with path.open("rb") as stream:
        # A record longer than the file is cut off or damaged; without this limit a damaged length
        # has the reader allocate and read up to 4 GiB.
        reader = StreamReader(stream, emit_chunks=True, validate_crcs=True, record_size_limit=size).records
        while True:
            try:
                record = next(reader, None)
            # The reader raises whatever its struct and string reads raise where the bytes run out
            # or make no sense (EndOfFile, struct.error, UnicodeDecodeError, ...): the file was cut
            # off if the failed record reached its end, else it is damaged.
            except Exception as error:
                cut = stream.tell() >= size or isinstance(error, RecordLengthLimitExceeded)
                if not cut or isinstance(error, (InvalidMagic, CRCValidationError)):
                    raise _Corrupt(f"the record at byte {end}: {_describe(error)}") from None
                records.flush()
                if end == size:
                    return end, f"ends without its summary and footer at byte {size}"
                return end, f"truncated inside the record at byte {end} (file of {size} bytes)"
            if record is None:
                records.flush()
                return end, None
            end = stream.tell()
            records.add(record, end)


_FORMATS = {MessageDefinitionFormat.MSG: "ros2msg", MessageDefinitionFormat.IDL: "ros2idl"}


class _Indexed:
    """A finished mcap file read by rosbags' reader, which finds its chunks through the summary
    and hands out the messages in record-time order, a chunk in memory at a time. Opening reads
    the summary only (and closes the file); raises what rosbags raises on a file without a usable
    summary (then :func:`_scan_mcap` reads it). :meth:`messages` raises :class:`_Corrupt` where
    the messages do not add up to the file's statistics (a damaged index would otherwise leave
    messages out unnoticed)."""

    def __init__(self, path: Path) -> None:
        if path.suffix != ".mcap":
            raise _Corrupt("rosbags' reader takes .mcap files by their name")
        self.path = path
        with RosbagsReader(path) as reader:
            # Copied: rosbags empties its list on close.
            self.connections, self.count = list(reader.connections), reader.message_count

    def declare(self, index: _Index) -> None:
        """The file's channels and definitions into ``index``."""
        for c in self.connections:
            index.connections.setdefault(
                c.id,
                _Connection(
                    c.topic, c.msgtype, c.ext.serialization_format, TopicQos.of(c.ext.offered_qos_profiles)
                ),
            )
            if c.msgdef.format in _FORMATS:
                index.definitions.setdefault(c.msgtype, (_FORMATS[c.msgdef.format], c.msgdef.data))

    def messages(self) -> Iterator[tuple[int, int, bytes]]:
        """(channel id, record time ns, CDR bytes) in record-time order."""
        counts: Counter[int] = Counter()
        with RosbagsReader(self.path) as reader:
            for connection, log_time, data in reader.messages():
                # rosbags reads the uint64 as int64: a time beyond int64 nanoseconds comes out negative.
                if log_time < 0:
                    raise _Corrupt(f"a message's record time {log_time + 2**64} ns is beyond int64 ns")
                counts[connection.id] += 1
                yield connection.id, log_time, data
        expected = {c.id: c.msgcount for c in self.connections if c.msgcount}
        if counts != expected or sum(counts.values()) != self.count:
            raise _Corrupt(f"{sum(counts.values())} messages read where its statistics count {self.count}")


def _read_indexed(path: Path) -> _Index:
    """Index a finished mcap file through :class:`_Indexed` (raises as it does)."""
    index = _Index()
    source = _Indexed(path)
    source.declare(index)
    batch: list[tuple[int, int, bytes]] = []
    for message in source.messages():
        batch.append(message)
        if len(batch) >= _BATCH:
            index.add(*zip(*batch))
            batch = []
    if batch:
        index.add(*zip(*batch))
    return index


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
                index.connections[tid] = _Connection(name, msgtype, encoding, TopicQos.parse(qos))
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
        # SQLite columns take any type: a damaged file can hold text or NULL where numbers and bytes belong.
        try:
            index.add(*zip(*rows))
        except (TypeError, ValueError, OverflowError) as error:
            raise BagError(f"{path}: corrupt: a row of its messages table: {error}") from None
    return f"{path}: rolled back the transaction the recorder left unfinished" if interrupted else None


def _bag_files(path: Path) -> tuple[list[Path], str, dict[str, str]]:
    """A bag's data files, their storage and rosbag2's ``custom_data`` of metadata.yaml (key ->
    text; empty for a bag without one)."""
    if not path.exists():
        raise BagError(f"{path}: no such bag")
    if path.is_file():
        return [path], _storage_of(path), {}
    meta = path / "metadata.yaml"
    if meta.is_file():
        try:
            info = read_document(meta)["rosbag2_bagfile_information"]
            storage = str(info.get("storage_identifier") or "")
            files = [_inside(path, meta, name) for name in info["relative_file_paths"]]
        except ConfigError as error:  # not YAML, or what no YAML file may hold: the line says it
            raise BagError(f"not rosbag2 metadata: {error}") from None
        # Whatever the YAML holds: a damaged file parses to other types as easily as it fails.
        except (KeyError, TypeError, AttributeError) as error:
            raise BagError(f"{meta}: not rosbag2 metadata ({type(error).__name__}: {error})") from None
        custom = info.get("custom_data") or {}
        if not isinstance(custom, dict) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in custom.items()
        ):
            raise BagError(f"{meta}: custom_data: not a mapping of text to text")
        if info.get("compression_mode"):
            raise BagError(
                f"{path}: compressed bags ({info['compression_mode']} "
                f"{info.get('compression_format')}) are not supported"
            )
        if storage not in STORAGES:
            raise BagError(f"{meta}: storage {storage!r} is not mcap or sqlite3")
        missing = [f.name for f in files if not f.is_file()]
        if missing:
            raise BagError(f"{path}: data file(s) {', '.join(missing)} named in metadata.yaml are missing")
        for file in files:
            if _storage_of(file) != storage:
                raise BagError(f"{file}: is not an {storage} file as metadata.yaml says")
        return files, storage, custom
    files = sorted(p for p in path.iterdir() if p.suffix in (".mcap", ".db3") and p.is_file())
    if not files:
        raise BagError(f"{path}: not a bag (no metadata.yaml, no .mcap or .db3 file)")
    storages = {_storage_of(f) for f in files}
    if len(storages) > 1:
        raise BagError(f"{path}: holds both mcap and sqlite3 files and no metadata.yaml")
    return files, storages.pop(), {}


def _types(index: _Index) -> MessageTypes:
    types = MessageTypes()
    for msgtype, (encoding, text) in index.definitions.items():
        types.add_definition(msgtype, encoding, text)
    return types


class BagData:
    """Indexed messages of a bag, decoded topic by topic: a whole bag (:class:`BagReader`) or a
    window of one (:class:`BagWindow`)."""

    path: Path
    storage: str
    recovered: str | None = None
    #: rosbag2's ``custom_data`` of metadata.yaml (key -> text); empty for a bag without one.
    custom_data: dict[str, str]

    def _load(self, index: _Index, types: MessageTypes) -> None:
        self._types = types
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
        for topic, ids in _topic_channels(index.connections).items():
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


def _topic_channels(connections: dict[int, _Connection]) -> dict[str, list[int]]:
    """Topic -> its channel ids, topics in the order they are declared."""
    out: dict[str, list[int]] = {}
    for cid, connection in connections.items():
        out.setdefault(connection.topic, []).append(cid)
    return out


class BagReader(BagData):
    """A rosbag2 bag (directory with metadata.yaml, or a single .mcap / .db3 file), indexed on open.

    ``recover=True`` reads an mcap file that lacks its summary and footer (a recorder that was
    killed, or a truncated copy) up to its last complete record instead of refusing it;
    ``recovered`` then says what was cut. For sqlite3 it lets SQLite roll back the transaction a
    killed recorder left open (in the ``-journal`` file), which rewrites the database file.
    """

    def __init__(self, path: str | os.PathLike[str], recover: bool = False) -> None:
        self.path = Path(path)
        index = _Index()
        try:
            files, self.storage, self.custom_data = _bag_files(self.path)
            total = sum(file.stat().st_size for file in files)
            if total > MAX_BAG_BYTES:
                raise BagError(
                    f"{self.path}: {total / 2**30:.1f} GiB of data files, more than the "
                    f"{MAX_BAG_BYTES >> 30} GiB a bag may have (it is read into memory; "
                    f"mk_asbuilt reads it in windows)"
                )
            for file in files:
                if self.storage == "mcap":
                    self._read_mcap(file, index, recover)
                else:
                    self.recovered = _load_sqlite(file, index, recover) or self.recovered
        except OSError as error:
            raise BagError(f"{self.path}: cannot read it ({error})") from None
        self._load(index, _types(index))

    def window(self, lo: int, hi: int, start: int | None, end: int | None) -> BagWindow:
        """The messages with record times in ``[lo, hi)`` (ns), as a window owning ``[start, end)``."""
        view = BagWindow(self.path, self.storage, start, end)
        view._types, view._data, view._encodings = self._types, self._data, self._encodings
        view._topics, view._messages = {}, {}
        for topic, (log_time, first, size) in self._messages.items():
            rows = slice(*np.searchsorted(log_time, [lo, hi]).tolist())
            view._messages[topic] = (log_time[rows], first[rows], size[rows])
            info = self._topics[topic]
            view._topics[topic] = TopicInfo(topic, info.msgtype, len(log_time[rows]), info.qos)
        return view

    def _read_mcap(self, path: Path, index: _Index, recover: bool) -> None:
        try:
            index.absorb(_read_indexed(path))
            return
        except Exception:  # rosbags refused it or it does not add up: the careful scan below judges
            pass
        before = index.count
        try:
            end, problem = _scan_mcap(path, index)
        except _Corrupt as error:
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


class BagWindow(BagData):
    """The messages of a bag with record times in a window ``[lo, hi)``, for the samples whose
    stamps fall in ``[start, end)`` (None: open): the window reaches past both ends by the margin
    that the samples of its own span need (:meth:`BagStream.windows`)."""

    def __init__(self, path: Path, storage: str, start: int | None, end: int | None) -> None:
        self.path, self.storage, self.custom_data = path, storage, {}
        self.start, self.end = start, end

    def owns(self, stamp_ns: np.ndarray) -> np.ndarray:
        """Which stamps (ns) belong to this window: each stamp belongs to one window of a bag."""
        stamp_ns = np.asarray(stamp_ns)
        mine = np.ones(stamp_ns.shape, bool)
        if self.start is not None:
            mine &= stamp_ns >= self.start
        if self.end is not None:
            mine &= stamp_ns < self.end
        return mine


class BagStream:
    """A rosbag2 bag read window by window (:meth:`windows`), for bags too long to hold at once.

    Opening reads only the metadata: ``topics`` (with their message counts), ``custom_data``. A
    finished mcap bag streams through rosbags' reader (a chunk and one window in memory). Any
    other bag (sqlite3, an mcap file without its summary, one the fast reader refuses) is read
    whole by :class:`BagReader` and cut into the same windows, so the corrupt-bag checks and
    ``recover`` are the same; ``recovered`` then says what was cut.
    """

    def __init__(self, path: str | os.PathLike[str], recover: bool = False) -> None:
        self.path = Path(path)
        self.recovered: str | None = None
        self._whole: BagReader | None = None
        self._sources: list[_Indexed] = []
        index = _Index()
        try:
            files, self.storage, self.custom_data = _bag_files(self.path)
            if self.storage == "mcap":
                try:
                    self._sources = [_Indexed(file) for file in files]
                except Exception:  # as BagReader: the careful scan judges a file rosbags refuses
                    self._sources = []
        except OSError as error:
            raise BagError(f"{self.path}: cannot read it ({error})") from None
        if not self._sources:
            self._whole = BagReader(self.path, recover)
            self.recovered = self._whole.recovered
            self.topics = self._whole.topics
            return
        for source in self._sources:
            source.declare(index)
        self._connections = index.connections
        self._types = _types(index)
        self.topics: dict[str, TopicInfo] = {}
        for topic, ids in _topic_channels(index.connections).items():
            kinds = sorted({(index.connections[cid].msgtype, index.connections[cid].encoding) for cid in ids})
            if len(kinds) > 1:
                raise BagError(f"{self.path}: topic {topic} is recorded with several types {kinds}")
            count = sum(c.msgcount for s in self._sources for c in s.connections if c.id in ids)
            qos = next((index.connections[cid].qos for cid in ids if index.connections[cid].qos), None)
            self.topics[topic] = TopicInfo(topic, kinds[0][0], count, qos)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    def windows(self, seconds: float | None, margin: float = 0.0) -> Iterator[BagWindow]:
        """The bag in windows of ``seconds`` of record time from its first message (None: one
        window, the whole bag), each holding the messages from ``margin`` seconds before it to
        ``margin`` after it, and owning the stamps in its span (the first window also those
        before, the last those after): processing each window's owned samples gives those of the
        whole bag where a sample depends on messages at most ``margin`` away in record time."""
        if seconds is not None and not (np.isfinite(seconds) and seconds > 0.0):
            raise ValueError(f"window length must be positive seconds, got {seconds}")
        if not (np.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"window margin must be zero or positive seconds, got {margin}")
        step = None if seconds is None else max(1, round(seconds * 1e9))
        pad = round(margin * 1e9)
        if self._whole is not None:
            yield from self._cut(self._whole, step, pad)
            return
        if step is None:  # read in batches, not message by message into one window
            yield BagReader(self.path).window(-(2**63), 2**63 - 1, None, None)
            return
        streams = [source.messages() for source in self._sources]
        messages = streams[0] if len(streams) == 1 else heapq.merge(*streams, key=itemgetter(1))
        try:
            yield from self._stream(messages, step, pad)
        except _Corrupt as error:
            raise BagError(f"{self.path}: corrupt: {error}") from None
        except BagError:
            raise
        except Exception as error:  # whatever rosbags' reader raises on a damaged chunk
            raise BagError(f"{self.path}: corrupt: {_describe(error)}") from None

    def _cut(self, whole: BagReader, step: int | None, pad: int) -> Iterator[BagWindow]:
        times = [whole.log_times(t) for t, info in whole.topics.items() if info.count]
        if step is None or not times:
            yield whole.window(-(2**63), 2**63 - 1, None, None)
            return
        first = min(int(t[0]) for t in times)
        last = max(int(t[-1]) for t in times)
        count = (last - first) // step + 1
        for k in range(count):
            start, end = first + k * step, first + (k + 1) * step
            yield whole.window(start - pad, end + pad, start if k else None, end if k < count - 1 else None)

    def _stream(self, messages: Iterator[tuple[int, int, bytes]], step: int, pad: int) -> Iterator[BagWindow]:
        """Windows of ``messages`` (in record-time order): a deque holds the messages from
        ``pad`` before the current window to ``pad`` after it."""
        pending = next(messages, None)
        if pending is None:
            yield self._window([], None, None)
            return
        first = pending[1]
        buffer: deque[tuple[int, int, bytes]] = deque()
        k = 0
        while True:
            start, end = first + k * step, first + (k + 1) * step
            while pending is not None and pending[1] < end + pad:
                buffer.append(pending)
                pending = next(messages, None)
            while buffer and buffer[0][1] < start - pad:
                buffer.popleft()
            last = pending is None and (not buffer or buffer[-1][1] < end)
            yield self._window(list(buffer), start if k else None, None if last else end)
            if last:
                return
            k += 1

    def _window(
        self, messages: list[tuple[int, int, bytes]], start: int | None, end: int | None
    ) -> BagWindow:
        index = _Index()
        index.connections = self._connections
        if messages:
            index.add(*zip(*messages))
        window = BagWindow(self.path, self.storage, start, end)
        window._load(index, self._types)
        return window


def _inside(bag: Path, meta: Path, name: object) -> Path:
    """A data file named in ``relative_file_paths``: a path below the bag directory only, so a
    damaged or crafted metadata.yaml cannot make a reader open a file elsewhere (an absolute path,
    ``../../x``)."""
    relative = Path(name) if isinstance(name, str) else None
    if relative is None or relative.is_absolute() or ".." in relative.parts or not relative.parts:
        raise BagError(f"{meta}: relative_file_paths: {name!r} is not a path inside the bag directory")
    return bag / relative


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
