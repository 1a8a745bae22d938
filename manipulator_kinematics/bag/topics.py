"""The package's topics: names from the nodes' config files, message types by topic key (no rclpy).

A node's section of a ``config/*.yaml`` file names each of its topics either as ``topics.<key>``
(excavator nodes) or as ``<key>_topic`` (SCARA nodes); the key says what flows there, so it fixes
the message type. ``record`` subscribes to all of them by default.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from manipulator_kinematics.params import CONFIG_DIR, config_path, flatten, load_parameters

JOINT_STATE = "sensor_msgs/msg/JointState"
POSE = "geometry_msgs/msg/PoseStamped"
TWIST = "geometry_msgs/msg/TwistStamped"
ACCEL = "geometry_msgs/msg/AccelStamped"

#: Message type of each topic key used in the nodes' config files.
TYPES_BY_KEY: dict[str, str] = {
    "cylinder_lengths": JOINT_STATE,
    "joint_states": JOINT_STATE,
    "open_chain_joint_states": JOINT_STATE,
    "rate_commands": JOINT_STATE,
    "rate_command_array": "std_msgs/msg/Float64MultiArray",
    "bucket_pose": POSE,
    "bucket_twist": TWIST,
    "bucket_accel": ACCEL,
    "target_bucket_twist": TWIST,
    "pose": POSE,
    "twist": TWIST,
}


def config_files() -> list[Path]:
    """The package's config files, from the source tree or else the installed share directory."""
    files = sorted(CONFIG_DIR.glob("*.yaml"))
    return files or sorted(config_path("excavator_nodes.yaml").parent.glob("*.yaml"))


def _sections() -> list[tuple[Path, str]]:
    """(config file, node section key) of every node section (``name`` or ``/**/name``)."""
    out = []
    for path in config_files():
        with open(path, encoding="utf-8") as stream:
            document = yaml.safe_load(stream) or {}
        out += [(path, key) for key in document if key != "/**"]
    return out


def node_settings(node: str) -> dict:
    """The settings a node of the package reads from its config file (nested dict)."""
    for path, key in _sections():
        if key.rsplit("/", 1)[-1] == node:
            return load_parameters(path, key)
    raise KeyError(f"no section for node {node!r} in {[p.name for p in config_files()]}")


def package_topics() -> dict[str, str]:
    """{topic name as the nodes use it (relative): message type} over every node's config.

    Raises KeyError naming a topic key whose type is not in :data:`TYPES_BY_KEY`.
    """
    topics: dict[str, str] = {}
    for path, node in _sections():
        for name, value in flatten(load_parameters(path, node)).items():
            if name.startswith("topics."):
                key = name[len("topics.") :]
            elif name.endswith("_topic"):
                key = name[: -len("_topic")]
            else:
                continue
            if key not in TYPES_BY_KEY:
                raise KeyError(f"{path.name}: {node}: topic key {key!r} has no message type in TYPES_BY_KEY")
            topics.setdefault(value, TYPES_BY_KEY[key])
    return topics
