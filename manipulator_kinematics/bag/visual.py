"""Foxglove-ready bags: a recorded bag plus the topics a 3-D panel needs to show the machine.

    add_visuals(source, output)        # a new bag: every message of source, and:

* ``/robot_description`` (std_msgs/String, transient local, one message): the machine's URDF
  (``Machine.urdf``), for machines that have one;
* ``/tf`` (tf2_msgs/TFMessage) at every recorded state and ``/tf_static`` (transient local, one
  message): with a URDF, one transform per URDF joint, parent link -> child link, exactly what
  robot_state_publisher would broadcast for the recorded joint values (moving joints on /tf,
  fixed ones on /tf_static; the values of every moving joint come from ``Scene.joints``, mimic
  joints follow their URDF rule); without one, ``base_link`` -> each frame of the scene;
* ``machine_markers`` (visualization_msgs/MarkerArray): the scene as markers, as the
  ``machine_markers`` node draws it, at most ``rate`` per second;
* with a ``machine_tilt`` topic in the machine's namespace (geometry_msgs/Vector3Stamped: world up
  in its header's frame, a URDF link, as excavator_imu_state publishes it from the cab IMU): at
  every state with a valid tilt at or before its stamp, ``base_level`` -> ``base_link`` on /tf,
  the gravity-aligned level frame as the parent (REP 105, like odom -> base_link;
  :func:`manipulator_kinematics.model.level_rotation`), so the tree's root is ``base_level``.
  ``extra_static`` transforms (e.g. ``site`` -> ``base_level``, the machine's place on a site)
  go on /tf_static with the URDF's fixed joints.

The machines are found as ``evaluate`` finds them (:func:`manipulator_kinematics.bag.evaluate.machines_in`):
through the registry, with the models of ``params`` files or the shipped ones, in every
namespace of the bag. A machine's state is gathered by joint name from its JointState topics
``joint_states`` and ``cylinder_lengths`` (the latest finite value of each joint wins, as in the
node), stamped with the header stamp and written at the record time of the message that
completed it. With one machine in the bag the frames are the URDF's own names; with several,
each machine's frames (and the links of its URDF) get the prefix ``<namespace>_<machine>/``.
``frame_prefix`` ({namespace: prefix}, e.g. ``{"/m1": "m1/"}``) sets a machine's prefix instead,
as the nodes' and robot_state_publisher's ``frame_prefix`` do at run time; ``root_frame`` (e.g.
``world``) adds a static identity transform from it to each machine's base frame, so several
machines form one TF tree.
Messages are serialised with rosbags' ROS 2 Jazzy type store.
"""

from __future__ import annotations

import os
import shutil
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

from manipulator_kinematics.bag.evaluate import load_setup, machines_in, split_topic
from manipulator_kinematics.bag.reader import BagReader, TopicArrays
from manipulator_kinematics.bag.topics import JOINT_STATE, package_topics
from manipulator_kinematics.bag.types import BagError, TopicQos
from manipulator_kinematics.bag.writer import BagWriter
from manipulator_kinematics.model import level_rotation, matrix_quaternion
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.scene import Scene, solids
from manipulator_kinematics.urdf import prefixed_urdf, rotation_rpy

#: JointState topics a machine's state is gathered from (as config/machine_markers.yaml).
STATE_TOPICS = ("joint_states", "cylinder_lengths")
BASE_FRAME = "base_link"
TILT, LEVEL_FRAME = "machine_tilt", "base_level"
MARKERS = "machine_markers"
TF, TF_STATIC, DESCRIPTION = "/tf", "/tf_static", "/robot_description"
LATCHED = TopicQos(reliable=True, transient_local=True, depth=1)
#: States per scene call: bounds the memory of a long bag's batch.
BLOCK = 4096

_STORE = get_typestore(Stores.ROS2_JAZZY)
_T = _STORE.types


# ------------------------------------------------------------------------------------------- URDF
@dataclass(frozen=True)
class UrdfJoint:
    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray  # (4, 4) parent -> joint frame
    axis: np.ndarray  # (3,) unit
    mimic: tuple[str, float, float] | None  # (joint, multiplier, offset)


def urdf_joints(text: str) -> list[UrdfJoint]:
    """Every joint of a URDF document (origin, axis, mimic), in document order."""
    out = []
    for joint in ET.fromstring(text).iter("joint"):
        origin = joint.find("origin")
        pose = np.eye(4)
        if origin is not None:
            pose[:3, :3] = rotation_rpy([float(v) for v in origin.get("rpy", "0 0 0").split()])
            pose[:3, 3] = [float(v) for v in origin.get("xyz", "0 0 0").split()]
        axis = joint.find("axis")
        direction = np.array([float(v) for v in (axis.get("xyz") if axis is not None else "1 0 0").split()])
        mimic = joint.find("mimic")
        out.append(
            UrdfJoint(
                joint.get("name"),
                joint.get("type"),
                joint.find("parent").get("link"),
                joint.find("child").get("link"),
                pose,
                direction / np.linalg.norm(direction),
                None
                if mimic is None
                else (
                    mimic.get("joint"),
                    float(mimic.get("multiplier", "1")),
                    float(mimic.get("offset", "0")),
                ),
            )
        )
    return out


def joint_transforms(joints: Sequence[UrdfJoint], values: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Parent -> child transform (..., 4, 4) of every moving joint for joint ``values`` (name ->
    (...,)), as robot_state_publisher computes it: origin, then the motion about/along the axis."""
    out = {}
    for j in joints:
        if j.kind == "fixed":
            continue
        if j.mimic is not None:
            name, multiplier, offset = j.mimic
            q = multiplier * np.asarray(values[name], dtype=float) + offset
        elif j.name in values:
            q = np.asarray(values[j.name], dtype=float)
        else:
            raise BagError(f"URDF joint {j.name!r} has no value in the machine's scene")
        motion = np.broadcast_to(np.eye(4), q.shape + (4, 4)).copy()
        if j.kind == "prismatic":
            motion[..., :3, 3] = q[..., None] * j.axis
        else:  # revolute, continuous: Rodrigues' rotation about the axis
            x, y, z = j.axis
            k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
            s, c = np.sin(q)[..., None, None], np.cos(q)[..., None, None]
            motion[..., :3, :3] = np.eye(3) + s * k + (1.0 - c) * (k @ k)
        out[j.name] = j.origin @ motion
    return out


def link_pose(
    joints: Sequence[UrdfJoint], moving: Mapping[str, np.ndarray], frame: str, root: str = BASE_FRAME
) -> np.ndarray:
    """``root`` -> ``frame`` (..., 4, 4) through the URDF's joints (``moving``: joint_transforms)."""
    parent_of = {j.child: j for j in joints}
    pose = np.eye(4)
    while frame != root:
        joint = parent_of.get(frame)
        if joint is None:
            raise BagError(f"frame {frame!r} is not a link of the URDF below {root!r}")
        pose = moving.get(joint.name, joint.origin) @ pose
        frame = joint.parent
    return pose


def level_poses(
    tilt: TopicArrays, stamp_ns: np.ndarray, joints: Sequence[UrdfJoint], moving: Mapping[str, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Which states (M,) have a tilt and base_level -> base_link (K, 4, 4) for them: the latest
    finite, unit (1e-3), upward tilt at or before each stamp, turned into base_link through the
    URDF at that state."""
    up = np.column_stack([tilt[f"vector.{axis}"] for axis in "xyz"]).astype(float)
    valid = np.isfinite(up).all(axis=1) & (np.abs(np.linalg.norm(up, axis=1) - 1.0) <= 1e-3) & (up[:, 2] > 0)
    frames = set(np.asarray(tilt["header.frame_id"])[valid].tolist())
    if len(frames) > 1:
        raise BagError(f"{tilt.topic}: the tilt changes frame ({sorted(frames)})")
    stamps = tilt.stamp_ns()[valid]
    order = np.argsort(stamps, kind="stable")
    row = np.searchsorted(stamps[order], stamp_ns, side="right") - 1
    have = row >= 0
    if not frames or not have.any():
        return have, np.empty((0, 4, 4))
    frame = frames.pop() or BASE_FRAME
    rotation = np.broadcast_to(link_pose(joints, moving, frame)[..., :3, :3], (len(stamp_ns), 3, 3))[have]
    pose = np.broadcast_to(np.eye(4), (int(have.sum()), 4, 4)).copy()
    pose[:, :3, :3] = level_rotation(np.einsum("kij,kj->ki", rotation, up[valid][order][row[have]]))
    return have, pose


# ---------------------------------------------------------------------------------------- states
def gather_states(
    data: Mapping[str, TopicArrays], names: Sequence[str], topics: Iterable[str] = STATE_TOPICS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(record times (M,), header stamps (M,) ns, states (M, n)) of a machine with joints ``names``:
    after each JointState message of ``topics`` (record order) that carries one of them, the
    latest finite position of every joint, once every joint has one; of consecutive messages
    with one stamp, only after the last."""
    parts = []
    for topic in topics:
        arrays = data.get(topic)
        if arrays is None or arrays.msgtype != JOINT_STATE or not len(arrays):
            continue
        position = arrays.by_name("position", names)
        some = np.isfinite(position).any(axis=1)
        parts.append((arrays.log_time[some], arrays.stamp_ns()[some], position[some]))
    if not parts:
        return np.empty(0, np.int64), np.empty(0, np.int64), np.empty((0, len(names)))
    log_time, stamp, position = (np.concatenate([p[k] for p in parts]) for k in range(3))
    order = np.argsort(log_time, kind="stable")
    log_time, stamp, position = log_time[order], stamp[order], position[order]
    rows = np.arange(len(log_time))[:, None]
    latest = np.maximum.accumulate(np.where(np.isfinite(position), rows, -1), axis=0)
    # A state is complete once every joint has a value, and final for its stamp after the last
    # message of that stamp (the excavator's joint_states and cylinder_lengths share one stamp).
    last_of_stamp = np.r_[stamp[1:] != stamp[:-1], True]
    keep = (latest >= 0).all(axis=1) & last_of_stamp
    values = np.take_along_axis(position, np.maximum(latest, 0), axis=0)
    return log_time[keep], stamp[keep], values[keep]


def decimate(t_ns: np.ndarray, rate: float) -> np.ndarray:
    """Indices of the last sample in each 1/rate interval of ``t_ns`` (at most ``rate`` per second)."""
    if not len(t_ns):
        return np.empty(0, np.int64)
    slot = np.floor((t_ns - t_ns[0]) * (rate * 1e-9)).astype(np.int64)
    return np.flatnonzero(np.r_[slot[1:] != slot[:-1], True])


def drawable_scene(machine: Machine, model: Any, states: np.ndarray) -> tuple[Scene, np.ndarray]:
    """The scene of the states the machine can take, and which those are (a recorded state
    beyond a stroke end, which the model refuses, is left out)."""
    try:
        return machine.scene(model, states), np.ones(len(states), dtype=bool)
    except ValueError:
        keep = machine.limits(model).within(states)
        return machine.scene(model, states[keep]), keep


# -------------------------------------------------------------------------------------- messages
def _time(stamp_ns: int) -> Any:
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _header(stamp_ns: int, frame_id: str) -> Any:
    return _T["std_msgs/msg/Header"](stamp=_time(stamp_ns), frame_id=frame_id)


def _transform(stamp_ns: int, parent: str, child: str, pose: np.ndarray, quaternion: np.ndarray) -> Any:
    t = _T
    return t["geometry_msgs/msg/TransformStamped"](
        header=_header(stamp_ns, parent),
        child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](*(float(v) for v in pose[:3, 3])),
            rotation=t["geometry_msgs/msg/Quaternion"](*(float(v) for v in quaternion)),
        ),
    )


def tf_messages(
    stamp_ns: np.ndarray, edges: Sequence[tuple[str, str]], poses: Sequence[np.ndarray]
) -> list[bytes]:
    """One TFMessage per stamp: transform i from ``edges[i]`` = (parent, child), ``poses[i]`` (M, 4, 4)."""
    quaternions = [matrix_quaternion(p[..., :3, :3]) for p in poses]
    out = []
    for k, stamp in enumerate(stamp_ns.tolist()):
        transforms = [
            _transform(stamp, parent, child, poses[i][k], quaternions[i][k])
            for i, (parent, child) in enumerate(edges)
        ]
        message = _T["tf2_msgs/msg/TFMessage"](transforms=transforms)
        out.append(_STORE.serialize_cdr(message, "tf2_msgs/msg/TFMessage"))
    return out


def marker_messages(scene: Scene, stamp_ns: np.ndarray, frame_id: str) -> list[bytes]:
    """One MarkerArray per state of ``scene`` (M,): ns = kind, id = row, as the node publishes."""
    t = _T
    parts = solids(scene)
    marker = t["visualization_msgs/msg/Marker"]
    colors = [t["std_msgs/msg/ColorRGBA"](*(float(v) for v in c)) for c in parts.color]
    shapes = [marker.CYLINDER if c else marker.SPHERE for c in parts.cylinder.tolist()]
    empty_image = t["sensor_msgs/msg/CompressedImage"](
        header=_header(0, ""), format="", data=np.empty(0, np.uint8)
    )
    no_mesh = t["visualization_msgs/msg/MeshFile"](filename="", data=np.empty(0, np.uint8))
    forever = t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0)
    out = []
    for k, stamp in enumerate(stamp_ns.tolist()):
        header = _header(stamp, frame_id)
        markers = []
        for i, kind in enumerate(parts.kinds):
            pose = t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](*(float(v) for v in parts.position[k, i])),
                orientation=t["geometry_msgs/msg/Quaternion"](*(float(v) for v in parts.orientation[k, i])),
            )
            markers.append(
                marker(
                    header=header,
                    ns=kind,
                    id=i,
                    type=shapes[i],
                    action=0,
                    pose=pose,
                    scale=t["geometry_msgs/msg/Vector3"](*(float(v) for v in parts.scale[k, i])),
                    color=colors[i],
                    lifetime=forever,
                    frame_locked=False,
                    points=[],
                    colors=[],
                    texture_resource="",
                    texture=empty_image,
                    uv_coordinates=[],
                    text="",
                    mesh_resource="",
                    mesh_file=no_mesh,
                    mesh_use_embedded_materials=False,
                )
            )
        array = t["visualization_msgs/msg/MarkerArray"](markers=markers)
        out.append(_STORE.serialize_cdr(array, "visualization_msgs/msg/MarkerArray"))
    return out


def string_message(text: str) -> bytes:
    return _STORE.serialize_cdr(_T["std_msgs/msg/String"](data=text), "std_msgs/msg/String")


# ------------------------------------------------------------------------------------------- bags
@dataclass
class Added:
    """The messages added for one machine: topic -> (type, QoS, record times, CDR bytes)."""

    machine: str
    namespace: str
    states: int
    topics: dict[str, tuple[str, TopicQos, list[int], list[bytes]]]


def visual_topics(
    bag: BagReader,
    params: Sequence[Path] = (),
    rate: float = 30.0,
    frame_prefix: Mapping[str, str] | None = None,
    root_frame: str = "",
    extra_static: Sequence[tuple[str, str, np.ndarray]] = (),
) -> list[Added]:
    """The visual topics (module docstring) of every machine with a scene hook found in ``bag``;
    ``extra_static``: (parent, child, (4, 4) pose) transforms for /tf_static."""
    frame_prefix = {"/" + ns.strip("/"): p for ns, p in (frame_prefix or {}).items()}
    setup = load_setup(params)
    ours = package_topics()
    grouped: dict[str, dict[str, str]] = {}
    for topic, info in bag.topics.items():
        split = split_topic(topic, list(ours))
        if split is not None and info.count and info.msgtype == ours[split[1]]:
            grouped.setdefault(split[0], {})[split[1]] = topic
    # The JointState topics are all it takes: to find the machines (evaluate's rule) and their states.
    arrays = bag.arrays(
        [
            t
            for names in grouped.values()
            for n, t in names.items()
            if bag.topics[t].msgtype == JOINT_STATE or n == TILT
        ]
    )
    found = []
    for namespace, names in sorted(grouped.items()):
        data = {name: arrays[topic] for name, topic in names.items() if topic in arrays}
        found += [(namespace, data, m) for m in machines_in(data, setup) if m.scene is not None]
    added = []
    for namespace, data, machine in found:
        space = namespace.strip("/").replace("/", "_")
        automatic = "" if len(found) == 1 else f"{space}_{machine.name}/".lstrip("_")
        prefix = frame_prefix.get(namespace, automatic)
        base = "" if namespace == "/" else namespace
        model = setup.model(machine)
        log_time, stamp, states = gather_states(data, machine.joint_names(model))
        if not len(states):
            continue
        topics: dict[str, tuple[str, TopicQos, list[int], list[bytes]]] = {}
        tf_raw, marker_raw, tf_times, marker_times = [], [], [], []
        static: list[bytes] = []
        urdf = machine.urdf(model) if machine.urdf is not None else None
        joints = urdf_joints(urdf) if urdf is not None else []
        for start in range(0, len(states), BLOCK):
            block = slice(start, start + BLOCK)
            scene, keep = drawable_scene(machine, model, states[block])
            t_log, t_stamp = log_time[block][keep], stamp[block][keep]
            if urdf is not None:
                moving = joint_transforms(joints, scene.joints)
                edges = [(prefix + j.parent, prefix + j.child) for j in joints if j.name in moving]
                poses = [moving[j.name] for j in joints if j.name in moving]
            else:
                edges = [(prefix + BASE_FRAME, prefix + name) for name in scene.frames]
                poses = list(scene.frames.values())
            tf_raw += tf_messages(t_stamp, edges, poses)
            tf_times += t_log.tolist()
            if TILT in data and urdf is not None:
                have, level = level_poses(data[TILT], t_stamp, joints, moving)
                tf_raw += tf_messages(t_stamp[have], [(prefix + LEVEL_FRAME, prefix + BASE_FRAME)], [level])
                tf_times += t_log[have].tolist()
            shown = decimate(t_stamp, rate)
            marker_raw += marker_messages(scene.take(shown), t_stamp[shown], prefix + BASE_FRAME)
            marker_times += t_log[shown].tolist()
        first = int(log_time[0])
        topics[TF] = ("tf2_msgs/msg/TFMessage", TopicQos(reliable=True, depth=100), tf_times, tf_raw)
        topics[f"{base}/{MARKERS}"] = (
            "visualization_msgs/msg/MarkerArray",
            TopicQos(reliable=True),
            marker_times,
            marker_raw,
        )
        extras = () if added else extra_static  # once, with the first machine
        fixed = [j for j in joints if j.kind == "fixed"]
        edges = [(prefix + j.parent, prefix + j.child) for j in fixed] + [e[:2] for e in extras]
        origins = [j.origin[None] for j in fixed] + [e[2][None] for e in extras]
        if root_frame:
            edges.append((root_frame, prefix + BASE_FRAME))
            origins.append(np.eye(4)[None])
        if edges:
            static = tf_messages(np.array([stamp[0]]), edges, origins)
            topics[TF_STATIC] = ("tf2_msgs/msg/TFMessage", LATCHED, [first], static)
        if urdf is not None:
            topics[f"{base}{DESCRIPTION}"] = (
                "std_msgs/msg/String",
                LATCHED,
                [first],
                [string_message(prefixed_urdf(urdf, prefix))],
            )
        added.append(Added(machine.name, namespace, len(states), topics))
    return added


def add_visuals(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    params: Sequence[Path] = (),
    rate: float = 30.0,
    overwrite: bool = False,
    storage: str | None = None,
    frame_prefix: Mapping[str, str] | None = None,
    root_frame: str = "",
    extra_static: Sequence[tuple[str, str, np.ndarray]] = (),
) -> list[Added]:
    """Write ``output``: every message of the bag ``source`` and its visual topics (module
    docstring). ``output`` may be ``source`` itself: the new bag is written beside it and
    replaces it once complete. BagError if no registered machine with a scene is in the bag."""
    source, output = Path(source), Path(output)
    bag = BagReader(source)
    added = visual_topics(bag, params, rate, frame_prefix, root_frame, extra_static)
    if not added:
        raise BagError(f"{source}: no registered machine's state topics in the bag: nothing to draw")
    merged: dict[str, tuple[str, TopicQos, list[int], list[bytes]]] = {}
    for item in added:
        for topic, (msgtype, qos, times, raws) in item.topics.items():
            if topic in bag.topics:
                raise BagError(f"{source}: already holds {topic}")
            if topic in merged:  # /tf and /tf_static of several machines share the topic
                merged[topic] = (msgtype, qos, merged[topic][2] + times, merged[topic][3] + raws)
            else:
                merged[topic] = (msgtype, qos, times, raws)
    in_place = source.resolve() == output.resolve()
    # In place: written in a hidden folder beside it under the same name (the data file is named
    # after its directory), then moved over the source once complete.
    scratch = output.parent / f".{output.name}.visual-tmp"
    if in_place and scratch.exists():
        shutil.rmtree(scratch)
    target = scratch / output.name if in_place else output
    with BagWriter(target, storage or bag.storage, overwrite=overwrite or in_place) as writer:
        for key, value in bag.custom_data.items():  # the recorded node settings among them
            writer.set_custom_data(key, value)
        for topic, info in bag.topics.items():
            writer.add_topic(topic, info.msgtype, info.qos)
        for topic, (msgtype, qos, _, _) in merged.items():
            writer.add_topic(topic, msgtype, qos)
        extra = [
            (t, time, raw)
            for t, (_, _, times, raws) in merged.items()
            for time, raw in zip(times, raws, strict=True)
        ]
        extra.sort(key=lambda item: item[1])
        pending = iter(extra)
        upcoming = next(pending, None)
        for topic, log_time, raw in bag.messages():
            while upcoming is not None and upcoming[1] <= log_time:
                writer.write(*upcoming)
                upcoming = next(pending, None)
            writer.write(topic, log_time, raw)
        while upcoming is not None:
            writer.write(*upcoming)
            upcoming = next(pending, None)
    if in_place:
        shutil.rmtree(source)
        target.rename(source)
        scratch.rmdir()
    return added


__all__ = [
    "Added",
    "UrdfJoint",
    "add_visuals",
    "decimate",
    "gather_states",
    "joint_transforms",
    "level_poses",
    "link_pose",
    "marker_messages",
    "tf_messages",
    "urdf_joints",
    "visual_topics",
]
