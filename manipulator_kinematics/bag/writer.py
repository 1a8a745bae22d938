"""rosbag2 bags (mcap or sqlite3) written incrementally through rosbags' writer, safe against SIGKILL.

:meth:`BagWriter.flush` makes everything written so far survive a killed process: for mcap the
open chunk is closed (a complete chunk record followed by its message indexes) and the file
buffer handed to the OS; for sqlite3 the open transaction is committed. ``metadata.yaml`` is
written when the bag is opened and rewritten on every flush, so a bag cut short by SIGKILL is
still a rosbag2 directory whose data file ends after the last flushed chunk (mcap) or holds the
last committed transaction (sqlite3).
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Qos
from rosbags.rosbag2 import Writer, WriterError
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.rosbag2.metadata import dump_qos_v9

from manipulator_kinematics.bag.types import BagError, MessageTypes, TopicQos

STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
_SUFFIX = {"mcap": ".mcap", "sqlite3": ".db3"}
# Files a bag directory may hold; --overwrite removes a directory only if it holds nothing else.
_BAG_FILES = (".mcap", ".db3", ".db3-journal", ".db3-wal", ".db3-shm", ".yaml", ".yaml.tmp")


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
        self._types = MessageTypes()
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
        self._qos[name] = [qos.to_rosbags()] if qos else []
        self._connections[name] = self._writer.add_connection(
            name, msgtype, typestore=self._types.store, offered_qos_profiles=self._qos[name]
        )
        self._write_metadata()

    def set_custom_data(self, key: str, value: str) -> None:
        """One entry of rosbag2's metadata ``custom_data`` (text -> text), kept by rosbag2 and rosbags."""
        self._writer.set_custom_data(key, value)
        # A flush, not only the metadata: metadata.yaml's counts must not claim unflushed messages.
        self.flush()

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
            "custom_data": dict(w.custom_data) or None,
            "ros_distro": "rosbags",
        }
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(
            yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False), encoding="utf-8"
        )
        tmp.replace(self.path / "metadata.yaml")
