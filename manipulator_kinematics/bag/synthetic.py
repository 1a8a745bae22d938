"""Bags made from the numpy cores alone: inputs along a smooth motion plus the outputs the nodes
must publish for them. Used for the golden test bags (scripts/make_golden_bags.py) and the
evaluate benchmark; no rclpy.

Timing mirrors a live system: at each sample the inputs are recorded first, outputs a little
later (``OUTPUT_DELAY``), all stamped with the sample time, so a replay delivers every input
before the output it causes and outputs match inputs by stamp.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from excavator_kinematics.kinematics import (
    CYLINDERS,
    JOINTS,
    Excavator,
    bucket_angular_acceleration,
    bucket_angular_velocity,
    bucket_quaternion,
)
from manipulator_kinematics.bag.io import BagWriter, encode_messages
from manipulator_kinematics.bag.topics import ACCEL, JOINT_STATE, POSE, TWIST
from manipulator_kinematics.planar import yaw_quaternion
from scara_kinematics.kinematics import Scara

#: Stamp of the first sample (a fixed instant, so regenerated bags are byte-identical).
START_NS = 1_700_000_000 * 1_000_000_000
#: Record-time offsets after the sample stamp: swing, then cylinders, then outputs.
CYLINDER_DELAY = 1_000_000
OUTPUT_DELAY = 3_000_000
FRAME = "base_link"
SWING_AMPLITUDE = 1.0  # rad
SWING_PERIOD = 20.0  # s


@dataclass
class Topic:
    """One topic's messages: type, record times (ns) and CDR bytes."""

    msgtype: str
    log_time: np.ndarray
    raw: list[bytes]


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


def excavator_motion(exc: Excavator, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """D (N, 4) and D_dot along a smooth dig-like motion inside the strokes, at times t (s).

    Each cylinder swings sinusoidally over 60 % of its stroke below 60 % of its speed limit. The
    swing goes back and forth over +-1 rad at a constant rate (a triangle wave of period
    ``SWING_PERIOD``), so between its turns, 5 s apart, the forward node's first-order hold of the
    swing between messages is exact whichever swing message it holds.
    """
    lim = exc.limits
    middle = 0.5 * (lim.stroke_min + lim.stroke_max)
    amplitude = 0.3 * (lim.stroke_max - lim.stroke_min)
    omega = np.minimum(0.6 * lim.max_cylinder_speed / amplitude, 2 * np.pi / np.array([7.0, 5.0, 3.0]))
    phase = np.array([0.3, 1.1, 2.0])
    lengths = middle + amplitude * np.sin(omega * t[:, None] + phase)
    rates = amplitude * omega * np.cos(omega * t[:, None] + phase)
    phase = 2 * np.pi * t / SWING_PERIOD
    swing = SWING_AMPLITUDE * (2 / np.pi) * np.arcsin(np.sin(phase))
    swing_rate = 4 * SWING_AMPLITUDE / SWING_PERIOD * np.sign(np.cos(phase))
    D = np.column_stack([swing, lengths])
    D_dot = np.column_stack([swing_rate, rates])
    return D, D_dot


def excavator_bag(
    exc: Excavator,
    samples: int,
    rate_hz: float,
    *,
    outputs: tuple[str, ...] = ("bucket_pose", "bucket_twist", "bucket_accel", "open_chain_joint_states"),
    target_every: int = 0,
    target_lead: float = 0.05,
) -> dict[str, Topic]:
    """Topics of an excavator run: inputs, the forward node's expected outputs (``outputs``) and,
    if ``target_every`` > 0, a ``target_bucket_twist`` every that many samples commanding the
    motion ``target_lead`` s ahead (so tracking is good but not perfect)."""
    t = np.arange(samples) / rate_hz
    stamp = START_NS + np.round(t * 1e9).astype(np.int64)
    D, D_dot = excavator_motion(exc, t)
    # The node's accelerations: raw differences of successive rates (none for the first message).
    D_ddot = np.vstack([np.zeros((1, 4)), np.diff(D_dot, axis=0) * rate_hz])
    s = exc.state(D, D_dot, D_ddot)
    topics = {
        "/joint_states": Topic(
            JOINT_STATE, stamp, joint_messages(stamp, ["swing_joint"], D[:, :1], D_dot[:, :1])
        ),
        "/cylinder_lengths": Topic(
            JOINT_STATE,
            stamp + CYLINDER_DELAY,
            joint_messages(stamp, list(CYLINDERS), D[:, 1:], D_dot[:, 1:]),
        ),
    }
    out = stamp + OUTPUT_DELAY
    if "bucket_pose" in outputs:
        topics["/bucket_pose"] = Topic(
            POSE, out, pose_messages(stamp, s.Q[:, :3], bucket_quaternion(D[:, 0], s.Q[:, 3]))
        )
    if "bucket_twist" in outputs:
        omega = bucket_angular_velocity(D[:, 0], D_dot[:, 0], s.Q_dot[:, 3])
        topics["/bucket_twist"] = Topic(TWIST, out, twist_messages(stamp, s.Q_dot[:, :3], omega))
    if "bucket_accel" in outputs:
        alpha = bucket_angular_acceleration(D[:, 0], D_dot[:, 0], D_ddot[:, 0], s.Q_dot[:, 3], s.Q_ddot[:, 3])
        topics["/bucket_accel"] = Topic(
            ACCEL, out[1:], twist_messages(stamp[1:], s.Q_ddot[1:, :3], alpha[1:], ACCEL)
        )
    if "open_chain_joint_states" in outputs:
        topics["/open_chain_joint_states"] = Topic(
            JOINT_STATE, out, joint_messages(stamp, list(JOINTS), s.theta, s.theta_dot)
        )
    if target_every:
        rows = np.arange(0, samples, target_every)
        ahead = exc.state(*excavator_motion(exc, t[rows] + target_lead))
        omega = bucket_angular_velocity(ahead.theta[:, 0], ahead.theta_dot[:, 0], ahead.Q_dot[:, 3])
        topics["/target_bucket_twist"] = Topic(
            TWIST, stamp[rows], twist_messages(stamp[rows], ahead.Q_dot[:, :3], omega)
        )
    return topics


def scara_bag(arm: Scara, samples: int, rate_hz: float) -> dict[str, Topic]:
    """joint_states of a SCARA motion inside its limits and away from the elbow singularity, with
    the expected tool_pose and tool_twist."""
    t = np.arange(samples) / rate_hz
    stamp = START_NS + np.round(t * 1e9).astype(np.int64)
    lo, hi = arm.limits.lower, arm.limits.upper
    # theta1 stays within +-45 deg, far from the singular +-90 deg.
    middle = np.array([0.5 * (lo[0] + hi[0]), 0.0, 0.5 * (lo[2] + hi[2])])
    amplitude = np.array([0.4 * (hi[0] - lo[0]), np.pi / 4, 0.4 * (hi[2] - lo[2])])
    omega = 2 * np.pi / np.array([4.0, 3.0, 2.5])
    q = middle + amplitude * np.sin(omega * t[:, None])
    qd = amplitude * omega * np.cos(omega * t[:, None])
    x, xd = arm.fk(q), arm.velocity_fk(q, qd)
    zeros = np.zeros((samples, 1))
    out = stamp + OUTPUT_DELAY
    return {
        "/joint_states": Topic(JOINT_STATE, stamp, joint_messages(stamp, list(arm.joint_names), q, qd)),
        "/tool_pose": Topic(
            POSE, out, pose_messages(stamp, np.column_stack([x[:, :2], zeros]), yaw_quaternion(x[:, 2]))
        ),
        "/tool_twist": Topic(
            TWIST,
            out,
            twist_messages(
                stamp, np.column_stack([xd[:, :2], zeros]), np.column_stack([zeros, zeros, xd[:, 2]])
            ),
        ),
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
