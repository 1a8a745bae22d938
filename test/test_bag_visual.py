"""Foxglove-ready bags (manipulator_kinematics.bag.visual, ``record --visuals``): the added
/robot_description, /tf, /tf_static and machine_markers read back with mcap-ros2-support (an
independent reader) and checked against the package's FK of the recorded states."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from ros_harness import REPO

from excavator_kinematics.core.kinematics import bucket_quaternion
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.types import BagError
from manipulator_kinematics.bag.visual import add_visuals
from manipulator_kinematics.bag.writer import BagWriter
from manipulator_kinematics.model import quaternion_matrix
from manipulator_kinematics.registry import machine
from manipulator_kinematics.scene import solids
from manipulator_kinematics.urdf import machine_urdf

DATA = REPO / "test" / "data"
CYLINDERS = ["boom_cylinder", "arm_cylinder", "bucket_cylinder"]


def read(bag: Path, topics: list[str] | None = None) -> dict[str, list]:
    """Messages by topic (ROS 2 messages, in order), as mcap-ros2-support decodes them."""
    out: dict[str, list] = {}
    for file in sorted(bag.glob("*.mcap")):
        with file.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, message in reader.iter_decoded_messages(topics=topics):
                out.setdefault(channel.topic, []).append(message)
    return out


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def matrix(transform) -> np.ndarray:
    t, r = transform.translation, transform.rotation
    out = np.eye(4)
    out[:3, :3] = quaternion_matrix([r.x, r.y, r.z, r.w])
    out[:3, 3] = [t.x, t.y, t.z]
    return out


def chain(
    tf_message, static: dict[str, tuple[str, np.ndarray]], frame: str, root: str = "base_link"
) -> np.ndarray:
    """Pose of ``frame`` in ``root`` from one /tf message and the /tf_static transforms."""
    edges = dict(static)
    edges.update({t.child_frame_id: (t.header.frame_id, matrix(t.transform)) for t in tf_message.transforms})
    pose = np.eye(4)
    while frame != root:
        parent, step = edges[frame]
        pose, frame = step @ pose, parent
    return pose


def static_edges(messages: list) -> dict[str, tuple[str, np.ndarray]]:
    return {
        t.child_frame_id: (t.header.frame_id, matrix(t.transform)) for m in messages for t in m.transforms
    }


def joint_positions(messages: list, names: list[str]) -> dict[int, np.ndarray]:
    out = {}
    for m in messages:
        by_name = dict(zip(m.name, m.position, strict=True))
        out[stamp_ns(m.header)] = np.array([by_name[n] for n in names])
    return out


@pytest.fixture(scope="module")
def excavator_bag(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("visual") / "excavator"
    add_visuals(DATA / "excavator_forward_golden", out)
    return out


def test_excavator_tf_matches_the_forward_kinematics(excavator_bag: Path) -> None:
    exc = machine("excavator").model()
    msgs = read(excavator_bag)
    swing = joint_positions(msgs["/joint_states"], ["swing_joint"])
    lengths = joint_positions(msgs["/cylinder_lengths"], CYLINDERS)
    static = static_edges(msgs["/tf_static"])
    assert len(msgs["/tf_static"]) == 1 and len(msgs["/tf"]) == len(lengths)
    worst = 0.0
    for m in msgs["/tf"]:
        stamp = stamp_ns(m.transforms[0].header)
        D = np.r_[swing[stamp], lengths[stamp]]
        tip = chain(m, static, "bucket_tip")
        q = exc.pose(D)
        worst = max(worst, float(np.abs(tip[:3, 3] - q[:3]).max()))
        np.testing.assert_allclose(tip[:3, :3], quaternion_matrix(bucket_quaternion(D[0], q[3])), atol=1e-9)
        # A pin of the closed loops as well: the bucket cylinder's rod pin on the side link.
        rod = chain(m, static, "bucket_cylinder_rod")
        np.testing.assert_allclose(rod[:3, 3], exc.pins(D)["bucket_cylinder_rod"], atol=1e-9)
    assert worst < 1e-9


def test_excavator_description_and_markers(excavator_bag: Path) -> None:
    m = machine("excavator")
    exc = m.model()
    msgs = read(excavator_bag)
    (description,) = msgs["/robot_description"]
    assert description.data == machine_urdf("excavator")
    topics = BagReader(excavator_bag).topics
    assert topics["/robot_description"].qos.transient_local and topics["/tf_static"].qos.transient_local
    assert topics["/tf"].msgtype == "tf2_msgs/msg/TFMessage"
    markers = msgs["/machine_markers"]
    # The golden bag is 2 s at 50 Hz: at most 30 arrays per second, on 1/30 s slots.
    assert 55 <= len(markers) <= 61
    swing = joint_positions(msgs["/joint_states"], ["swing_joint"])
    lengths = joint_positions(msgs["/cylinder_lengths"], CYLINDERS)
    array = markers[len(markers) // 2]
    stamp = stamp_ns(array.markers[0].header)
    expected = solids(m.scene(exc, np.r_[swing[stamp], lengths[stamp]]))
    assert [mk.ns for mk in array.markers] == list(expected.kinds)
    got = np.array([[mk.pose.position.x, mk.pose.position.y, mk.pose.position.z] for mk in array.markers])
    np.testing.assert_allclose(got, expected.position, atol=1e-12)
    scale = np.array([[mk.scale.x, mk.scale.y, mk.scale.z] for mk in array.markers])
    np.testing.assert_allclose(scale, expected.scale, atol=1e-12)


def test_serial_tf_matches_fkine_and_the_bag_is_rewritten_in_place(tmp_path: Path) -> None:
    model = machine("palletizer").model()
    bag = tmp_path / "palletizer"
    shutil.copytree(DATA / "palletizer_forward_golden", bag)
    before = BagReader(bag).message_count
    (added,) = add_visuals(bag, bag)
    assert added.machine == "palletizer" and added.states == 100
    assert BagReader(bag).message_count == before + sum(len(t[3]) for t in added.topics.values())
    assert [p.name for p in tmp_path.iterdir()] == ["palletizer"]
    msgs = read(bag)
    q = joint_positions(msgs["/joint_states"], list(model.joint_names))
    static = static_edges(msgs["/tf_static"])
    for m in msgs["/tf"]:
        stamp = stamp_ns(m.transforms[0].header)
        np.testing.assert_allclose(chain(m, static, "tool"), model.fkine(q[stamp]), atol=1e-9)


def test_a_bag_without_machine_states_is_refused(tmp_path: Path) -> None:
    source = BagReader(DATA / "scara_forward_golden")
    only_poses = tmp_path / "only_poses"
    with BagWriter(only_poses) as writer:
        writer.add_topic("/tool_pose", source.topics["/tool_pose"].msgtype)
        for topic, t, raw in source.messages(["/tool_pose"]):
            writer.write(topic, t, raw)
    with pytest.raises(BagError, match="nothing to draw"):
        add_visuals(only_poses, tmp_path / "out")
    assert not (tmp_path / "out").exists()
