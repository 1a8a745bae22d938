"""ROS 2 parameter files as plain nested dicts (no rclpy), so cores and nodes share one loader.

A parameters file looks like ``{node_or_/**: {ros__parameters: {...}}}``; nested keys become
dotted parameter names in ROS (``excavator.boom.length``). Cores take the nested dict.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

CONFIG_DIR = Path(__file__).resolve().parent.parent / "config"
#: libyaml's parser when PyYAML has it: the same safe constructor, about 10 times faster.
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


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
        document = yaml.load(stream, Loader=_LOADER) or {}
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


def check_ros_arguments(argv: Sequence[str]) -> None:
    """Refuse, with one line naming the argument, what rcl would refuse with a traceback: a
    ``--params-file`` that is missing, is not YAML, is not shaped ``{node: {ros__parameters: {...}}}``
    or holds a value no ROS parameter can take (null, an empty mapping, a mixed or nested list);
    a ``-p``/``-r`` rule without ``:=``. Only arguments inside ``--ros-args`` sections count."""
    in_ros_args, expect = False, None
    for arg in argv:
        if expect is not None:
            if expect == "--params-file":
                _check_params_file(Path(arg))
            elif ":=" not in arg or arg.startswith(":="):
                raise ConfigError(f"{expect} {arg!r}: expected NAME:=VALUE")
            expect = None
        elif arg == "--ros-args":
            in_ros_args = True
        elif arg == "--":
            in_ros_args = False
        elif in_ros_args and arg in ("--params-file", "-p", "--param", "-r", "--remap"):
            expect = arg
    if expect is not None:
        raise ConfigError(f"{expect}: a value must follow it")


def _check_params_file(path: Path) -> None:
    try:
        with open(path, encoding="utf-8") as stream:
            document = yaml.safe_load(stream)
    except OSError as error:
        raise ConfigError(f"--params-file {path}: {error.strerror}") from None
    except yaml.YAMLError as error:
        where = getattr(error, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        raise ConfigError(f"--params-file {path}: not valid YAML{line}") from None
    if not isinstance(document, dict) or not document:
        raise ConfigError(f"--params-file {path}: expected sections {{node: {{ros__parameters: {{...}}}}}}")
    for node, section in document.items():
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise ConfigError(f"--params-file {path}: {node}: expected a mapping 'ros__parameters:'")
        for name, value in _leaves(section["ros__parameters"]):
            if not _parameter_value(value):
                raise ConfigError(f"--params-file {path}: {node}: {name} = {value!r} is not a ROS parameter "
                                  "value (a number, string, bool, or a list of one of those)")


def _leaves(nested: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """(dotted name, value) of every leaf; an empty mapping is a leaf (rcl cannot declare it)."""
    out = []
    for key, value in nested.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        out += _leaves(value, name) if isinstance(value, dict) and value else [(name, value)]
    return out


def _parameter_value(value: Any) -> bool:
    if isinstance(value, (bool, int, float, str)):
        return True
    if isinstance(value, list) and value:
        kinds = {bool if isinstance(v, bool) else (float if isinstance(v, (int, float)) else type(v))
                 for v in value}
        return len(kinds) == 1 and kinds <= {bool, float, str}
    return False


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
