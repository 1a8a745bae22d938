"""The excavator's synthetic bag (its ``synthesize`` hook): the forward node's inputs along a
smooth dig-like motion and the outputs it must publish for them, from the numpy core alone. Used
for the golden bag test/data/excavator_forward_golden (scripts/make_golden_bags.py), the evaluate
tests and benchmark. Timing as in :mod:`manipulator_kinematics.bag.synthetic`: swing first, the
cylinders ``CYLINDER_DELAY`` later, outputs after ``OUTPUT_DELAY``, all stamped with the sample time.
"""

from __future__ import annotations

import numpy as np

from excavator_kinematics.core.kinematics import (
    CYLINDERS,
    JOINTS,
    Excavator,
    bucket_angular_acceleration,
    bucket_angular_velocity,
    bucket_quaternion,
)
from manipulator_kinematics.bag.synthetic import (
    OUTPUT_DELAY,
    Topic,
    joint_messages,
    pose_messages,
    timeline,
    twist_messages,
)
from manipulator_kinematics.bag.topics import ACCEL, JOINT_STATE, POSE, TWIST

#: Record-time offset of the cylinder message after the swing message of the same sample.
CYLINDER_DELAY = 1_000_000
SWING_AMPLITUDE = 1.0  # rad
SWING_PERIOD = 20.0  # s


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
    t, stamp = timeline(samples, rate_hz)
    D, D_dot = excavator_motion(exc, t)
    # The node's accelerations: raw differences of successive rates (none for the first message).
    D_ddot = np.vstack([np.zeros((1, 4)), np.diff(D_dot, axis=0) * rate_hz])
    s = exc.state(D, D_dot, D_ddot)
    reading = exc.readings(D)  # what the sensors read: true - zero_offset
    topics = {
        "/joint_states": Topic(
            JOINT_STATE, stamp, joint_messages(stamp, ["swing_joint"], reading[:, :1], D_dot[:, :1])
        ),
        "/cylinder_lengths": Topic(
            JOINT_STATE,
            stamp + CYLINDER_DELAY,
            joint_messages(stamp, list(CYLINDERS), reading[:, 1:], D_dot[:, 1:]),
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
