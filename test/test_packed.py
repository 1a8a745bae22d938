"""manipulator_kinematics.codec.packed: bytes written in place equal rclpy's own serialization of the same
message, for every layout our nodes publish (independent reference: rclpy's serializer)."""

from __future__ import annotations

import pytest
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header

from manipulator_kinematics.codec.packed import PackedMessage


def stamped(cls: type, values: list[float]) -> object:
    msg = cls(header=Header(frame_id="base_link"))
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 999_999_999
    body = getattr(msg, {PoseStamped: "pose", TwistStamped: "twist", AccelStamped: "accel"}[cls])
    if cls is PoseStamped:
        leaves = [(body.position, "xyz"), (body.orientation, "xyzw")]
    else:
        leaves = [(body.linear, "xyz"), (body.angular, "xyz")]
    it = iter(values)
    for owner, names in leaves:
        for name in names:
            setattr(owner, name, next(it))
    return msg


@pytest.mark.parametrize("cls, count", [(PoseStamped, 7), (TwistStamped, 6), (AccelStamped, 6)])
def test_stamped_geometry_bytes_equal_rclpy_serialization(cls: type, count: int) -> None:
    values = [0.1 * (i + 1) - 0.35 for i in range(count)]
    template = cls(header=Header(frame_id="base_link"))
    packed = PackedMessage(template, ("header.stamp", "pose", "twist", "accel"))
    assert packed.size == 2 + count
    raw = packed.pack([1_700_000_000, 999_999_999, *values])
    reference = serialize_message(stamped(cls, values))
    # The 2 alignment bytes after frame_id's NUL are not written by rclpy's serializer (they hold
    # whatever its buffer held, which changes with the CPU's code paths): every other byte counts.
    pad = slice(4 + 12 + len("base_link") + 1, 4 + 24)
    assert raw[pad.stop :] == reference[pad.stop : len(raw)] and raw[: pad.start] == reference[: pad.start]
    assert len(raw) > pad.stop and len(reference) - len(raw) < 8
    assert deserialize_message(raw, cls) == stamped(cls, values)


def test_joint_state_with_names_and_an_empty_effort_field() -> None:
    names = ["swing_joint", "boom_joint", "arm_joint", "bucket_joint"]
    packed = PackedMessage(
        JointState(name=names, position=[0.0] * 4, velocity=[0.0] * 4),
        ("header.stamp", "position", "velocity"),
    )
    raw = packed.pack([3, 4, 0.5, -0.25, 1.5, -2.0, 0.01, 0.02, -0.03, 0.04])
    msg = deserialize_message(raw, JointState)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (3, 4)
    assert msg.name == names and list(msg.effort) == []
    assert list(msg.position) == [0.5, -0.25, 1.5, -2.0] and list(msg.velocity) == [0.01, 0.02, -0.03, 0.04]
    # rclpy pads this message's end to 8 bytes; the packed bytes end where the values do.
    assert serialize_message(msg).startswith(raw)


def test_sequence_of_a_multi_array_and_a_prefix_with_no_numbers() -> None:
    packed = PackedMessage(Float64MultiArray(data=[0.0] * 4), ("data",))
    msg = deserialize_message(packed.pack([1.0, 2.0, 3.0, 4.0]), Float64MultiArray)
    assert list(msg.data) == [1.0, 2.0, 3.0, 4.0]
    with pytest.raises(ValueError, match="no numeric fields"):
        PackedMessage(Header(frame_id="x"), ("frame_id",))
