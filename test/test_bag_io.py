"""Bag I/O without ROS: the numpy CDR codec against rosbags' own (de)serialiser, the writer against
rosbags' and mcap's readers, kill safety of flushed data, and readable errors for bad bags."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_typestore

from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.types import BagError, TopicQos, decode_messages, encode_messages
from manipulator_kinematics.bag.writer import BagWriter

STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types
JOINT_STATE = "sensor_msgs/msg/JointState"
NAMES = ["boom_cylinder", "arm_cylinder", "bucket_cylinder"]


def header(i: int, frame: str = "") -> object:
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=100 + i, nanosec=7 * i), frame_id=frame
    )


def joint_state(i: int, names: list[str], frame: str = "", efforts: int = 0) -> object:
    n = len(names)
    return T[JOINT_STATE](
        header=header(i, frame),
        name=names,
        position=np.arange(n) + 0.5 * i,
        velocity=-np.arange(n) * 0.25 * i,
        effort=np.full(efforts, 1e-3 * i),
    )


def rosbags_raw(messages: list[object], msgtype: str, little_endian: bool = True) -> list[bytes]:
    return [bytes(STORE.serialize_cdr(m, msgtype, little_endian=little_endian)) for m in messages]


# ------------------------------------------------------------------------------------------ CDR codec


@pytest.mark.parametrize("little_endian", [True, False])
def test_decode_joint_states_of_several_layouts_like_rosbags(little_endian: bool) -> None:
    # Names of different lengths and counts, frame ids, empty and full efforts: several layouts mixed.
    messages = []
    for i in range(60):
        names = NAMES if i % 3 else ["swing_joint"]
        messages.append(
            joint_state(
                i,
                names,
                frame="base_link" if i % 4 == 0 else "",
                efforts=3 if i % 5 == 0 and len(names) == 3 else 0,
            )
        )
    fields = decode_messages(JOINT_STATE, rosbags_raw(messages, JOINT_STATE, little_endian))
    for i, m in enumerate(messages):
        back = STORE.deserialize_cdr(rosbags_raw([m], JOINT_STATE, little_endian)[0], JOINT_STATE)
        n = len(back.name)
        assert fields["header.stamp.sec"][i] == back.header.stamp.sec
        assert fields["header.stamp.nanosec"][i] == back.header.stamp.nanosec
        assert fields["header.frame_id"][i] == back.header.frame_id
        assert list(fields["name"][i, :n]) == back.name and set(fields["name"][i, n:]) <= {""}
        np.testing.assert_array_equal(fields["position"][i, :n], back.position)
        assert np.all(np.isnan(fields["position"][i, n:]))
        np.testing.assert_array_equal(fields["effort"][i, : len(back.effort)], back.effort)


def test_decode_fixed_arrays_nested_sequences_and_unicode_like_rosbags() -> None:
    imu_type, array_type = "sensor_msgs/msg/Imu", "std_msgs/msg/Float64MultiArray"
    vec, quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    imus = [
        T[imu_type](
            header=header(i, "imü_链"),
            orientation=quat(x=0.1 * i, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.arange(9.0) * i,
            angular_velocity=vec(x=i, y=2.0, z=3.0),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec(x=0.0, y=0.0, z=-9.81),
            linear_acceleration_covariance=np.ones(9),
        )
        for i in range(5)
    ]
    fields = decode_messages(imu_type, rosbags_raw(imus, imu_type))
    np.testing.assert_array_equal(
        fields["orientation_covariance"], np.stack([m.orientation_covariance for m in imus])
    )
    np.testing.assert_array_equal(fields["angular_velocity.x"], [m.angular_velocity.x for m in imus])
    assert set(fields["header.frame_id"]) == {"imü_链"}

    dim = T["std_msgs/msg/MultiArrayDimension"]
    arrays = [
        T[array_type](
            layout=T["std_msgs/msg/MultiArrayLayout"](
                dim=[dim(label="rows", size=2, stride=4), dim(label="cols", size=2, stride=2)][: 1 + i % 2],
                data_offset=i,
            ),
            data=np.linspace(0, 1, 4) * i,
        )
        for i in range(6)
    ]
    fields = decode_messages(array_type, rosbags_raw(arrays, array_type))
    np.testing.assert_array_equal(fields["layout.data_offset"], np.arange(6))
    np.testing.assert_array_equal(fields["data"], np.stack([m.data for m in arrays]))
    assert list(fields["layout.dim[0].label"]) == ["rows"] * 6
    assert list(fields["layout.dim[1].label"]) == ["", "cols"] * 3
    np.testing.assert_array_equal(fields["layout.dim[1].size"][1::2], 2)
    assert np.all(np.isnan(fields["layout.dim[1].size"][0::2]))


def test_encoded_messages_deserialise_with_rosbags() -> None:
    n = 7
    position = np.random.default_rng(1).normal(size=(n, 3))
    raws = encode_messages(
        JOINT_STATE,
        n,
        {
            "header.stamp.sec": np.arange(n),
            "header.stamp.nanosec": 5,
            "header.frame_id": "odom",
            "name": NAMES,
            "position": position,
            "velocity": [1.0, 2.0, 3.0],
        },
    )
    for i, raw in enumerate(raws):
        m = STORE.deserialize_cdr(raw, JOINT_STATE)
        assert (m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id) == (i, 5, "odom")
        assert m.name == NAMES and len(m.effort) == 0
        np.testing.assert_array_equal(m.position, position[i])
        np.testing.assert_array_equal(m.velocity, [1.0, 2.0, 3.0])


def test_decode_rejects_bytes_of_another_type() -> None:
    raws = rosbags_raw([joint_state(0, NAMES)], JOINT_STATE)
    with pytest.raises(BagError, match=r"message 0 .* not a valid geometry_msgs/msg/PoseStamped"):
        decode_messages("geometry_msgs/msg/PoseStamped", raws)
    with pytest.raises(BagError, match="not plain CDR"):
        decode_messages(JOINT_STATE, [b"\x00\x03\x00\x00" + raws[0][4:]])


# ------------------------------------------------------------------------------------------ writer / reader


def write_joint_states(
    path: Path, storage: str, count: int, flush_every: int = 0, **kwargs: object
) -> np.ndarray:
    position = np.random.default_rng(2).normal(size=(count, 3))
    raws = encode_messages(
        JOINT_STATE,
        count,
        {"header.stamp.sec": np.arange(count), "name": NAMES, "position": position, "velocity": -position},
    )
    with BagWriter(path, storage, **kwargs) as writer:
        writer.add_topic("/cylinder_lengths", JOINT_STATE, TopicQos(reliable=False, depth=5))
        writer.add_topic("/empty", "geometry_msgs/msg/PoseStamped")
        for i, raw in enumerate(raws):
            writer.write("/cylinder_lengths", 1_000_000_000 * i + 17, raw)
            if flush_every and i % flush_every == flush_every - 1:
                writer.flush()
    return position


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_written_bag_reads_back_with_our_reader_and_rosbags(tmp_path: Path, storage: str) -> None:
    position = write_joint_states(tmp_path / "bag", storage, 50)
    bag = BagReader(tmp_path / "bag")
    assert bag.storage == storage and bag.message_count == 50 and bag.recovered is None
    assert bag.topics["/cylinder_lengths"].qos == TopicQos(reliable=False, transient_local=False, depth=5)
    arrays = bag.arrays()
    np.testing.assert_array_equal(arrays["/cylinder_lengths"]["position"], position)
    np.testing.assert_array_equal(
        arrays["/cylinder_lengths"].by_name("velocity", ["arm_cylinder", "x"])[:, 0], -position[:, 1]
    )
    np.testing.assert_array_equal(arrays["/cylinder_lengths"].log_time, np.arange(50) * 1_000_000_000 + 17)
    assert arrays["/empty"]["pose.position.x"].shape == (0,)

    with AnyReader([tmp_path / "bag"], default_typestore=STORE) as reader:
        got = [reader.deserialize(raw, c.msgtype).position for c, _, raw in reader.messages()]
        assert {c.topic for c in reader.connections} == {"/cylinder_lengths", "/empty"}
    np.testing.assert_array_equal(np.stack(got), position)


def test_mcap_bag_reads_back_with_mcap_ros2_support(tmp_path: Path) -> None:
    position = write_joint_states(tmp_path / "bag", "mcap", 20)
    with open(tmp_path / "bag" / "bag.mcap", "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        got = [message for _, _, _, message in reader.iter_decoded_messages()]
    np.testing.assert_array_equal(np.array([m.position for m in got]), position)
    assert [m.header.stamp.sec for m in got] == list(range(20))


def test_writer_refuses_to_overwrite_and_removes_only_bags(tmp_path: Path) -> None:
    write_joint_states(tmp_path / "bag", "mcap", 3)
    before = (tmp_path / "bag" / "bag.mcap").read_bytes()
    with pytest.raises(BagError, match="exists; not overwriting"):
        BagWriter(tmp_path / "bag")
    assert (tmp_path / "bag" / "bag.mcap").read_bytes() == before
    write_joint_states(tmp_path / "bag", "sqlite3", 4, overwrite=True)
    assert BagReader(tmp_path / "bag").message_count == 4 and not (tmp_path / "bag" / "bag.mcap").exists()
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "thesis.tex").write_text("precious")
    with pytest.raises(BagError, match="holds more than a bag"):
        BagWriter(tmp_path / "notes", overwrite=True)
    assert (tmp_path / "notes" / "thesis.tex").read_text() == "precious"


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4])
def test_compressed_chunks_with_checksums_read_and_damage_is_caught(tmp_path: Path, compression: int) -> None:
    # What ROS 2's own mcap plugin writes by default: compressed chunks, CRCs.
    position = np.random.default_rng(3).normal(size=(500, 3))
    raws = encode_messages(JOINT_STATE, 500, {"name": NAMES, "position": position})
    path = tmp_path / "ros2.mcap"
    with path.open("wb") as stream:
        writer = McapWriter(stream, chunk_size=4096, compression=compression, enable_data_crcs=True)
        writer.start(profile="ros2", library="test")
        definition = STORE.generate_msgdef(JOINT_STATE, ros_version=2)[0]
        schema = writer.register_schema(JOINT_STATE, "ros2msg", definition.encode())
        channel = writer.register_channel("/cylinder_lengths", "cdr", schema)
        for i, raw in enumerate(raws):
            writer.add_message(channel, 1000 + i, raw, 1000 + i)
        writer.finish()
    arrays = BagReader(path).arrays()["/cylinder_lengths"]
    np.testing.assert_array_equal(arrays["position"], position)
    np.testing.assert_array_equal(arrays.log_time, 1000 + np.arange(500))
    with path.open("rb") as stream:
        chunk = make_reader(stream).get_summary().chunk_indexes[1]
    damaged = bytearray(path.read_bytes())
    # Inside a compressed chunk's records (a damaged message index, which readers may skip, is not).
    damaged[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0x10
    path.write_bytes(bytes(damaged))
    with pytest.raises(BagError, match=r"ros2\.mcap: corrupt: "):
        BagReader(path)


# ------------------------------------------------------------------------------------------ bad bags


def test_truncated_mcap_is_refused_with_the_recoverable_count(tmp_path: Path) -> None:
    write_joint_states(tmp_path / "bag", "mcap", 2000, flush_every=100)
    data = tmp_path / "bag" / "bag.mcap"
    full = data.read_bytes()
    data.write_bytes(full[: len(full) // 2])
    with pytest.raises(BagError, match=r"bag\.mcap: .*(truncated|ends).*--recover reads the \d+ messages"):
        BagReader(tmp_path / "bag")
    bag = BagReader(tmp_path / "bag", recover=True)
    # Each flush closed a chunk of 100: the first half of the file holds the first chunks whole.
    assert bag.message_count in (900, 1000)
    np.testing.assert_array_equal(
        bag.arrays()["/cylinder_lengths"]["header.stamp.sec"], np.arange(bag.message_count)
    )


def test_corrupt_and_empty_files_are_refused(tmp_path: Path) -> None:
    write_joint_states(tmp_path / "bag", "mcap", 100)
    data = tmp_path / "bag" / "bag.mcap"
    full = bytearray(data.read_bytes())
    full[60:80] = b"\xff" * 20  # inside the first chunk's records
    data.write_bytes(bytes(full))
    with pytest.raises(BagError, match="corrupt"):
        BagReader(tmp_path / "bag", recover=True)
    data.write_bytes(b"")
    with pytest.raises(BagError, match="empty"):
        BagReader(tmp_path / "bag")
    data.write_bytes(b"hello, not a bag at all")
    with pytest.raises(BagError, match="neither an MCAP nor an SQLite file"):
        BagReader(tmp_path / "bag")
    write_joint_states(tmp_path / "db", "sqlite3", 10)
    db = tmp_path / "db" / "db.db3"
    db.write_bytes(db.read_bytes()[:2000])
    with pytest.raises(BagError, match="not a readable rosbag2 SQLite file"):
        BagReader(tmp_path / "db")
    with pytest.raises(BagError, match="no such bag"):
        BagReader(tmp_path / "nothing")
    (tmp_path / "plain").mkdir()
    with pytest.raises(BagError, match="not a bag"):
        BagReader(tmp_path / "plain")


def test_unknown_type_and_missing_topic_are_named(tmp_path: Path) -> None:
    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        mystery = writer.add_connection(
            "/mystery", "foo_msgs/msg/Bar", msgdef="", rihs01="RIHS01_" + "0" * 64
        )
        known = writer.add_connection(
            "/custom", "foo_msgs/msg/Known", msgdef="float64 x\nstring label\n", rihs01="RIHS01_" + "1" * 64
        )
        writer.write(mystery, 1, b"\x00\x01\x00\x00\x01\x02\x03\x04")
        writer.write(
            known,
            2,
            encode_messages("geometry_msgs/msg/Point", 1, {"x": 2.5})[0][:12] + b"\x02\x00\x00\x00"
            b"a\x00\x00\x00",
        )
    bag = BagReader(tmp_path / "bag")
    custom = bag.arrays(["/custom"])["/custom"]  # a definition in the bag is enough
    assert custom["x"][0] == 2.5 and custom["label"][0] == "a"
    with pytest.raises(BagError, match="unknown message type 'foo_msgs/msg/Bar'"):
        bag.arrays(["/mystery"])
    with pytest.raises(BagError, match=r"no topic /nope in the bag .*it has /mystery, /custom"):
        bag.arrays(["/nope"])


def test_writer_rejects_unknown_types_and_storages(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="unknown storage"):
        BagWriter(tmp_path / "a", storage="rosbag1")
    with BagWriter(tmp_path / "b") as writer, pytest.raises(BagError, match="unknown message type"):
        writer.add_topic("/x", "foo_msgs/msg/Nothing")
    assert os.path.exists(tmp_path / "b" / "metadata.yaml")
