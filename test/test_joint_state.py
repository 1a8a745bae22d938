"""manipulator_kinematics.joint_state: the raw JointState decoder against rclpy's own serializer (the
independent reference), and joint_values' reasons."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from manipulator_kinematics.joint_state import InputError, decode_joint_state, joint_values


def message(**fields: object) -> JointState:
    msg = JointState(header=Header(frame_id="base_link"), **fields)
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_123, 456_789
    return msg


@pytest.mark.parametrize(
    "fields",
    [
        {
            "name": ["boom_cylinder", "arm_cylinder", "bucket_cylinder"],
            "position": [2.9, 3.3, 2.3],
            "velocity": [0.01, -0.02, 0.015],
        },
        {"name": ["swing_joint"], "velocity": [0.25]},  # an empty sequence before a full one
        {
            "name": ["a", "bb", "ccc", "dddd", "eeeee"],
            "position": [1.0, 2.0, 3.0, 4.0, 5.0],
            "effort": [-1.0, 0.5, 0.0, 1e300, -1e-300],
        },
        {},
    ],
)
def test_decoded_fields_equal_what_was_serialized(fields: dict) -> None:
    msg = message(**fields)
    decoded = decode_joint_state(serialize_message(msg))
    assert decoded.stamp_ns == 1_700_000_123 * 1_000_000_000 + 456_789
    assert decoded.frame_id == "base_link" and decoded.name == list(msg.name)
    assert decoded.position == tuple(msg.position)
    assert decoded.velocity == tuple(msg.velocity)
    assert decoded.effort == tuple(msg.effort)


@pytest.mark.parametrize("cut", [0, 3, 11, 30, 60, 80])
def test_truncated_or_corrupt_bytes_are_an_input_error(cut: int) -> None:
    raw = serialize_message(message(name=["boom_cylinder"], position=[2.9], velocity=[0.1]))
    assert len(raw) >= 88  # the velocity value ends at byte 84
    with pytest.raises(InputError, match="not a sensor_msgs/JointState"):
        decode_joint_state(raw[:cut])
    corrupt = bytearray(raw)
    corrupt[12:16] = (10_000).to_bytes(4, "little")  # frame_id length past the end
    with pytest.raises(InputError, match="not a sensor_msgs/JointState"):
        decode_joint_state(bytes(corrupt))


def test_joint_values_picks_names_in_order_and_names_what_is_wrong() -> None:
    msg = decode_joint_state(serialize_message(message(name=["b", "a"], position=[2.0, 1.0], velocity=[])))
    position, velocity = joint_values(msg, ["a", "b"], require_position=True)
    np.testing.assert_array_equal(position, [1.0, 2.0])
    assert velocity is None
    with pytest.raises(InputError, match="no velocity values"):
        joint_values(msg, ["a"], require_velocity=True)
    with pytest.raises(InputError, match=r"joint names \['c'\] missing"):
        joint_values(msg, ["c"])
    with pytest.raises(InputError, match="non-finite position"):
        joint_values(message(name=["a"], position=[math.nan]), ["a"])
