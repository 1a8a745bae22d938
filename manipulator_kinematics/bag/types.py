"""What a bag's topics carry: message types, topic QoS, and the error every bag module raises.

Types are ROS 2 Jazzy's (rosbags' type store), plus the definitions a bag holds and the ``.msg``
files of installed packages (the package's own interfaces). They are handed to
:mod:`manipulator_kinematics.codec.cdr` as plain field lists.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import (
    Nodetype,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore

from manipulator_kinematics.codec import cdr


class BagError(Exception):
    """A bag that cannot be written or read as asked; the message says what and where."""


@dataclass(frozen=True)
class TopicQos:
    """What a topic's publishers offered, reduced to what a subscriber or replayer must match."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10

    def to_rosbags(self) -> Qos:
        zero = QosTime(0, 0)
        return Qos(
            QosHistory.KEEP_LAST,
            self.depth,
            QosReliability.RELIABLE if self.reliable else QosReliability.BEST_EFFORT,
            QosDurability.TRANSIENT_LOCAL if self.transient_local else QosDurability.VOLATILE,
            zero,
            zero,
            QosLiveliness.AUTOMATIC,
            zero,
            False,
        )

    @staticmethod
    def parse(text: str | None) -> TopicQos | None:
        """The QoS a bag stores as rosbag2's ``offered_qos_profiles`` text; None if absent or unreadable
        (it only matters for replay, which then uses the defaults)."""
        if not text:
            return None
        try:
            profiles = parse_qos(text)
        except Exception:  # rosbags' parser raises whatever the YAML inside makes it raise
            return None
        return TopicQos.of(profiles)

    @staticmethod
    def of(profiles: Sequence[Qos]) -> TopicQos | None:
        """The same of rosbags' parsed profiles (a connection's ``offered_qos_profiles``)."""
        if not profiles:
            return None
        return TopicQos(
            reliable=all(p.reliability == QosReliability.RELIABLE for p in profiles),
            transient_local=all(p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles),
            depth=max(p.depth for p in profiles),
        )


class MessageTypes:
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
        return path.read_text(encoding="utf-8") if path.is_file() else None
    # OSError: no ament index in this environment at all; ValueError: not a valid package name.
    except (PackageNotFoundError, OSError, ValueError):
        return None


def encode_messages(msgtype: str, count: int, values: Mapping[str, Any]) -> list[bytes]:
    """CDR bytes of ``count`` messages of ``msgtype`` from leaf values by path (see :func:`cdr.encode`),
    e.g. ``encode_messages("sensor_msgs/msg/JointState", n, {"header.stamp.sec": s, "name": [...],
    "position": p})``: what a bag written without rclpy stores."""
    return cdr.encode(msgtype, MessageTypes().schemas(msgtype, msgtype), count, values)


def decode_messages(msgtype: str, raws: Sequence[bytes]) -> dict[str, np.ndarray]:
    """Leaf values by path of CDR messages of ``msgtype`` (the inverse of :func:`encode_messages`)."""
    sizes = np.fromiter(map(len, raws), np.int64, len(raws))
    data = np.frombuffer(b"".join(raws), np.uint8)
    schemas = MessageTypes().schemas(msgtype, msgtype)
    try:
        return cdr.decode(data, np.cumsum(sizes) - sizes, sizes, msgtype, schemas)
    except cdr.CdrError as error:
        raise BagError(str(error)) from None
