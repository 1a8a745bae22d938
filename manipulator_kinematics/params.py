"""ROS 2 parameter files as plain nested dicts (no rclpy), so cores and nodes share one loader.

A parameters file looks like ``{node_or_/**: {ros__parameters: {...}}}``; nested keys become
dotted parameter names in ROS (``excavator.boom.length``). Cores take the nested dict.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

CONFIG_DIR = Path(__file__).resolve().parent.parent / "config"
#: Longest text of one value in an error line (characters): longer ones are cut with "...".
SHOWN = 100
#: Most items of a list in a parameters file, and its largest size: no parameter of this package
#: comes near either, and rcl takes seconds to parse a 100,000-element list (refused before it).
MAX_ITEMS = 10_000
MAX_FILE_BYTES = 4 << 20


# libyaml's parser where PyYAML has it: the pure-Python one takes 3.5 s for a 1.2 MB file, this 0.4 s.
class RosLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """YAML as rcl reads a parameter: a plain ``1e3`` is a number (YAML 1.2), as rcl's parser
    takes it, not the string PyYAML's YAML 1.1 rules make of it; quoted values stay strings."""


RosLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


class ConfigError(ValueError):
    """A machine description is missing a key or holds an invalid value; the message names it."""


def shown(value: Any, limit: int = SHOWN) -> str:
    """``repr(value)`` for an error line, cut with "..." beyond ``limit`` characters (a list's
    length added), so that no value, such as a 100,000-element list, makes a line long."""
    text = repr(value)
    if len(text) <= limit:
        return text
    count = f" ({len(value)} items)" if isinstance(value, (list, tuple)) else ""
    return f"{text[: limit - 20]}...{text[-12:]}{count}"


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
        document = yaml.load(stream, Loader=RosLoader) or {}
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
                raise ConfigError(f"{expect} {shown(arg)}: expected NAME:=VALUE")
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
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ConfigError(f"--params-file {path}: {size / 2**20:.1f} MiB, more than the "
                              f"{MAX_FILE_BYTES >> 20} MiB a parameters file may have")
        with open(path, encoding="utf-8") as stream:
            _refuse_long_lists(path, stream)
            stream.seek(0)
            document = yaml.load(stream, Loader=RosLoader)
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
                raise ConfigError(f"--params-file {path}: {node}: {name} = {shown(value)} is not a ROS "
                                  "parameter value (a number, string, bool, or a list of one of those)")


def _refuse_long_lists(path: Path, stream: Any) -> None:
    """ConfigError naming the first list of more than MAX_ITEMS items, read as YAML events up to
    its item MAX_ITEMS + 1: a 100,000-element list is refused in milliseconds, before PyYAML
    builds it (0.4 s) and rcl parses it (2 s)."""
    stack: list[list[Any]] = []  # per open collection: [is_mapping, next_is_key, items, key]
    for event in yaml.parse(stream, Loader=RosLoader):
        if isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            stack.pop()
            continue
        if not isinstance(event, (yaml.NodeEvent, yaml.CollectionStartEvent)):
            continue
        if stack and not stack[-1][0]:  # an item of a list
            stack[-1][2] += 1
            if stack[-1][2] > MAX_ITEMS:
                keys = [str(c[3])[:SHOWN] for c in stack if c[0]]
                name = ".".join(keys[2:] if keys[1:2] == ["ros__parameters"] else keys[1:])
                raise ConfigError(f"--params-file {path}: {keys[0] if keys else ''}: {name} has more "
                                  f"than the {MAX_ITEMS} items a parameter may have")
        elif stack:  # a key of a mapping, or its value
            if stack[-1][1]:
                stack[-1][3] = getattr(event, "value", "?")
            stack[-1][1] = not stack[-1][1]
        if isinstance(event, yaml.CollectionStartEvent):
            stack.append([isinstance(event, yaml.MappingStartEvent), True, 0, None])


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
