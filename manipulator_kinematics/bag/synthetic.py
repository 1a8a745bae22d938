"""Bags made from the numpy cores alone: inputs along a smooth motion plus the outputs the nodes
must publish for them. Used for the golden test bags (scripts/make_golden_bags.py, through each
machine's ``synthesize`` hook) and the evaluate benchmark; no rclpy, no machine package: serial
machines share :func:`serial_bag`, the excavator has its own (excavator_kinematics.tools.synthetic).

Timing mirrors a live system: at each sample the inputs are recorded first, outputs a little
later (``OUTPUT_DELAY``), all stamped with the sample time, so a replay delivers every input
before the output it causes and outputs match inputs by stamp.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manipulator_kinematics.bag.topics import JOINT_STATE, POSE, TWIST
from manipulator_kinematics.bag.types import encode_messages
from manipulator_kinematics.bag.writer import BagWriter
from manipulator_kinematics.model import SerialModel, matrix_quaternion

#: Stamp of the first sample (a fixed instant, so regenerated bags are byte-identical).
START_NS = 1_700_000_000 * 1_000_000_000
#: Record-time offset of the outputs after the sample stamp (inputs are recorded at it or earlier).
OUTPUT_DELAY = 3_000_000
FRAME = "base_link"
#: The golden bags (test/data/<machine>_forward_golden): 2 s at 50 Hz of each machine's forward node.
GOLDEN_SAMPLES = 100
GOLDEN_RATE_HZ = 50.0


def golden_name(machine: str) -> str:
    """Directory name of a machine's golden bag."""
    return f"{machine}_forward_golden"


@dataclass
class Topic:
    """One topic's messages: type, record times (ns) and CDR bytes."""

    msgtype: str
    log_time: np.ndarray
    raw: list[bytes]


def timeline(samples: int, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample times t (s) from 0 and their stamps (ns from :data:`START_NS`)."""
    t = np.arange(samples) / rate_hz
    return t, START_NS + np.round(t * 1e9).astype(np.int64)


def stamp_fields(stamp_ns: np.ndarray, frame_id: str = "") -> dict[str, object]:
    return {
        "header.stamp.sec": stamp_ns // 1_000_000_000,
        "header.stamp.nanosec": stamp_ns % 1_000_000_000,
        "header.frame_id": frame_id,
    }


def _vector(prefix: str, values: np.ndarray) -> dict[str, np.ndarray]:
    return {f"{prefix}.{axis}": values[:, i] for i, axis in enumerate("xyz")}


def pose_messages(stamp: np.ndarray, position: np.ndarray, quaternion: np.ndarray) -> list[bytes]:
    values = {
        **stamp_fields(stamp, FRAME),
        **_vector("pose.position", position),
        **{f"pose.orientation.{a}": quaternion[:, i] for i, a in enumerate("xyzw")},
    }
    return encode_messages(POSE, len(stamp), values)


def twist_messages(
    stamp: np.ndarray, linear: np.ndarray, angular: np.ndarray, kind: str = TWIST
) -> list[bytes]:
    field = "twist" if kind == TWIST else "accel"
    values = {
        **stamp_fields(stamp, FRAME),
        **_vector(f"{field}.linear", linear),
        **_vector(f"{field}.angular", angular),
    }
    return encode_messages(kind, len(stamp), values)


def joint_messages(
    stamp: np.ndarray, names: list[str], position: np.ndarray, velocity: np.ndarray
) -> list[bytes]:
    return encode_messages(
        JOINT_STATE,
        len(stamp),
        {**stamp_fields(stamp), "name": names, "position": position, "velocity": velocity},
    )


def serial_motion(model: SerialModel, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """q (N, n) and qd of a smooth motion inside the joint limits at times t (s): each joint swings
    sinusoidally about the middle of its range over 80 % of it, with its own period (4 s, then
    0.8 times the previous joint's) and phase, so every joint moves and no two move alike."""
    lo, hi = model.limits.lower, model.limits.upper
    n = len(lo)
    middle, amplitude = 0.5 * (lo + hi), 0.4 * (hi - lo)
    omega = 2 * np.pi / (4.0 * 0.8 ** np.arange(n))
    phase = 0.7 * np.arange(n)
    q = middle + amplitude * np.sin(omega * t[:, None] + phase)
    qd = amplitude * omega * np.cos(omega * t[:, None] + phase)
    return q, qd


def serial_bag(model: SerialModel, samples: int, rate_hz: float) -> dict[str, Topic]:
    """The ``synthesize`` hook of a serial machine: :func:`serial_topics` along
    :func:`serial_motion`."""
    t, stamp = timeline(samples, rate_hz)
    return serial_topics(model, stamp, *serial_motion(model, t))


def serial_topics(model: SerialModel, stamp: np.ndarray, q: np.ndarray, qd: np.ndarray) -> dict[str, Topic]:
    """A serial machine's ``joint_states`` (q, qd (N, n) at header stamps (N,) ns) and what the
    generic forward node publishes for them: ``tool_pose`` (``fkine``) and ``tool_twist``
    (``jacob0 @ qd``), recorded :data:`OUTPUT_DELAY` later. Any joint trajectory (a planned
    path, a measured run) becomes a bag that ``mk_evaluate`` and the replay tests read."""
    pose = model.fkine(q)
    twist = np.einsum("nij,nj->ni", model.jacob0(q), qd)
    out = stamp + OUTPUT_DELAY
    return {
        "/joint_states": Topic(JOINT_STATE, stamp, joint_messages(stamp, list(model.joint_names), q, qd)),
        "/tool_pose": Topic(
            POSE, out, pose_messages(stamp, pose[:, :3, 3], matrix_quaternion(pose[:, :3, :3]))
        ),
        "/tool_twist": Topic(TWIST, out, twist_messages(stamp, twist[:, :3], twist[:, 3:])),
    }


def write_bag(
    path: str | Path, topics: Mapping[str, Topic], storage: str = "mcap", overwrite: bool = False
) -> int:
    """Write ``topics`` in record-time order; returns the message count."""
    names = list(topics)
    which = np.concatenate([np.full(len(topics[n].raw), i) for i, n in enumerate(names)])
    log_time = np.concatenate([topics[n].log_time for n in names])
    raws = [raw for n in names for raw in topics[n].raw]
    order = np.argsort(log_time, kind="stable")
    with BagWriter(path, storage, overwrite=overwrite) as writer:
        for name in names:
            writer.add_topic(name, topics[name].msgtype)
        for i in order.tolist():
            writer.write(names[which[i]], int(log_time[i]), raws[i])
    return len(raws)
