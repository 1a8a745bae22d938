"""ROS 2 parameter files as plain nested dicts (no rclpy), so cores and nodes share one loader.

A parameters file looks like ``{node_or_/**: {ros__parameters: {...}}}``; nested keys become
dotted parameter names in ROS (``excavator.boom.length``). Cores take the nested dict.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

CONFIG_DIR = Path(__file__).resolve().parent.parent / "config"


class ConfigError(ValueError):
    """A machine description is missing a key or holds an invalid value; the message names it."""


def config_path(name: str) -> Path:
    """Path of a config file shipped with the package (source tree or installed share/)."""
    candidates = [CONFIG_DIR / name]
    if not candidates[0].is_file():
        share = _installed_share()
        if share is not None:
            candidates.append(share / "config" / name)
    for path in candidates:
        if path.is_file():
            return path
    raise FileNotFoundError(f"config file {name!r} not found in {[str(c) for c in candidates]}")


def _installed_share() -> Path | None:
    """share/manipulator_kinematics of an installed package (colcon/ament), if there is one."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:  # the numpy cores work without any ROS installed
        return None
    try:
        return Path(get_package_share_directory("manipulator_kinematics"))
    except (PackageNotFoundError, OSError, ValueError, LookupError):  # OSError: no AMENT_PREFIX_PATH
        return None


def load_parameters(path: str | Path, node_name: str = "/**") -> dict[str, Any]:
    """Merge the ``ros__parameters`` that apply to ``node_name`` (plain or fully qualified), the
    more specific section winning: ``/**``, then ``/**/<name>``, then ``<name>`` / ``/<ns>/<name>``.
    """
    with open(path, encoding="utf-8") as stream:
        document = yaml.safe_load(stream) or {}
    if not isinstance(document, dict):
        raise ConfigError(f"{path}: not a ROS parameters file (top level is not a mapping)")
    base = node_name.rsplit("/", 1)[-1]
    keys = ["/**"] if base in ("**", "") else ["/**", f"/**/{base}", base, f"/{base}", node_name]
    merged: dict[str, Any] = {}
    for key in dict.fromkeys(keys):
        section = document.get(key)
        if isinstance(section, dict):
            parameters = section.get("ros__parameters") or {}
            if not isinstance(parameters, dict):
                raise ConfigError(f"{path}: {key}: ros__parameters is not a mapping")
            _deep_update(merged, parameters)
    return merged


def unflatten(flat: dict[str, Any]) -> dict[str, Any]:
    """``{'a.b': 1}`` -> ``{'a': {'b': 1}}`` (ROS parameter names back to the file's nesting)."""
    nested: dict[str, Any] = {}
    for name, value in flat.items():
        node = nested
        *parents, leaf = name.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return nested


def flatten(nested: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Inverse of :func:`unflatten`."""
    flat: dict[str, Any] = {}
    for key, value in nested.items():
        name = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            flat.update(flatten(value, name))
        else:
            flat[name] = value
    return flat


def _deep_update(target: dict[str, Any], source: dict[str, Any]) -> None:
    for key, value in source.items():
        if isinstance(value, dict) and isinstance(target.get(key), dict):
            _deep_update(target[key], value)
        else:
            target[key] = value
