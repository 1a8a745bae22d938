"""The package's topics, from the machine registry, and its nodes' settings, from its config files
(no rclpy).

Each registered machine declares the topics its nodes use (``Machine.topics``: relative name ->
message type); ``record`` subscribes to all of them by default and ``evaluate`` reads them. The
node settings (sections ``/**/<node>`` of ``config/*.yaml``) are what an analysis mirrors.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from manipulator_kinematics.param_files import CONFIG_DIR, ConfigError, config_path, merge, read_document
from manipulator_kinematics.registry import machines

JOINT_STATE = "sensor_msgs/msg/JointState"
#: The key of rosbag2's metadata ``custom_data`` under which ``record`` stores the settings of the
#: nodes that published the recorded topics: JSON, full node name -> its parameters (nested).
SETTINGS_KEY = "manipulator_kinematics.node_settings"
POSE = "geometry_msgs/msg/PoseStamped"
TWIST = "geometry_msgs/msg/TwistStamped"
ACCEL = "geometry_msgs/msg/AccelStamped"


def package_topics() -> dict[str, str]:
    """{topic name as the nodes use it (relative): message type} over every registered machine.

    Raises ValueError when two machines declare one topic name with different types.
    """
    topics: dict[str, str] = {}
    owner: dict[str, str] = {}
    for name, machine in machines().items():
        for topic, msgtype in machine.topics.items():
            if topics.setdefault(topic, msgtype) != msgtype:
                raise ValueError(
                    f"machines {owner[topic]} and {name} declare topic {topic!r} with different types "
                    f"({topics[topic]}, {msgtype})"
                )
            owner.setdefault(topic, name)
    return topics


def node_sections(path: Path) -> dict[str, dict[str, Any]]:
    """Node name -> its own ``ros__parameters`` (nested) of every node section of a parameters
    file (``name``, ``/**/name`` or ``/ns/name``; ``/**`` holds machines, not nodes)."""
    document = read_document(path) or {}
    if not isinstance(document, dict):
        raise ConfigError(f"{path}: not a ROS parameters file (top level is not a mapping)")
    out: dict[str, dict[str, Any]] = {}
    for key, section in document.items():
        if key != "/**" and isinstance(section, dict):
            parameters = section.get("ros__parameters") or {}
            if not isinstance(parameters, dict):
                raise ConfigError(f"{path}: {key}: ros__parameters is not a mapping")
            node = str(key).rsplit("/", 1)[-1]
            out[node] = merge(out.get(node, {}), parameters)
    return out


def config_files() -> list[Path]:
    """The package's config files, from the source tree or else the installed share directory."""
    files = sorted(CONFIG_DIR.glob("*.yaml"))
    folders = {config_path(m.config_file).parent for m in machines().values()} if not files else set()
    return files or sorted(path for folder in folders for path in folder.glob("*.yaml"))


def node_settings() -> dict[str, dict[str, Any]]:
    """Node name -> the settings it reads from the package's config files (nested)."""
    out: dict[str, dict[str, Any]] = {}
    for path in config_files():
        for node, parameters in node_sections(path).items():
            out[node] = merge(out.get(node, {}), parameters)
    return out


def encode_recorded_settings(settings: dict[str, dict[str, Any]]) -> str:
    """``custom_data[SETTINGS_KEY]`` of a bag: full node name (``/ns/node``) -> parameters (nested)."""
    # default=str: a byte-array parameter's bytes (nothing an analysis reads) as text.
    return json.dumps(settings, sort_keys=True, separators=(",", ":"), default=str)


def decode_recorded_settings(text: str) -> dict[str, dict[str, Any]]:
    """Inverse of :func:`encode_recorded_settings`; ValueError naming the key if it is not that."""
    try:
        settings = json.loads(text)
    except (ValueError, RecursionError) as error:
        raise ValueError(f"custom_data: {SETTINGS_KEY}: not JSON ({error})") from None
    if not isinstance(settings, dict) or not all(
        isinstance(node, str) and node.startswith("/") and isinstance(values, dict)
        for node, values in settings.items()
    ):
        raise ValueError(f"custom_data: {SETTINGS_KEY}: not a mapping of node names to parameters")
    return settings
