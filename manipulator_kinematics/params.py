"""ROS 2 parameter files as plain nested dicts (no rclpy), so cores and nodes share one loader.

A parameters file looks like ``{node_or_/**: {ros__parameters: {...}}}``; nested keys become
dotted parameter names in ROS (``excavator.boom.length``). Cores take the nested dict.

Each file is parsed once per process (:func:`read_document`, kept while the file is unchanged): the
start-up check of the command line (:func:`check_ros_arguments`), the node's values
(:func:`given_parameters`, :func:`load_parameters`), the machine and settings readers and the bag
tools all read that one document. Dicts are merged by one function, :func:`merge`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from functools import lru_cache
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
class RosLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]  # a base chosen at run time
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
    document = read_document(path) or {}
    if not isinstance(document, dict):
        raise ConfigError(f"{path}: not a ROS parameters file (top level is not a mapping)")
    base = node_name.rsplit("/", 1)[-1]
    keys = ["/**"] if base in ("**", "") else ["/**", f"/**/{base}", base, f"/{base}", node_name]
    layers = []
    for key in dict.fromkeys(keys):
        section = document.get(key)
        if isinstance(section, dict):
            parameters = section.get("ros__parameters") or {}
            if not isinstance(parameters, dict):
                raise ConfigError(f"{path}: {key}: ros__parameters is not a mapping")
            layers.append(parameters)
    return merge(*layers)


def given_parameters(argv: Sequence[str], node_name: str = "/**") -> dict[str, Any]:
    """The nested values the ``--params-file`` files of ``argv`` give the node ``node_name`` (fully
    qualified), a later file winning (:func:`load_parameters` within each file). Files that do not
    exist are left out: :func:`check_ros_arguments` refuses them before a node is built."""
    return merge(*(load_parameters(path, node_name) for path in params_files(argv) if path.is_file()))


def merge(*layers: Mapping[str, Any]) -> dict[str, Any]:
    """The nested dict of ``layers`` laid over each other in order, a later one winning: a key that
    is a mapping in both is merged key by key, any other value replaced. A new dict: no layer is
    changed and none of their mappings or lists is shared with it (documents are parsed once and
    kept, callers may change what they get)."""
    out: dict[str, Any] = {}
    for layer in layers:
        for key, value in layer.items():
            if isinstance(value, Mapping):
                below = out.get(key)
                out[key] = merge(below, value) if isinstance(below, dict) else merge(value)
            else:
                out[key] = list(value) if isinstance(value, list) else value
    return out


def read_document(path: str | Path) -> Any:
    """The parsed YAML of ``path`` (RosLoader), parsed once per process while the file keeps its size
    and modification time. Shared by every caller: read it, do not change it (:func:`merge` copies)."""
    status = Path(path).stat()
    return _parse(str(Path(path).resolve()), status.st_mtime_ns, status.st_size)


@lru_cache(maxsize=64)
def _parse(path: str, mtime_ns: int, size: int) -> Any:
    # The bytes: libyaml decodes them itself (UTF-8), 0.9 ms for the pump boom's 130 KB region
    # table against 1.5 ms from a text stream (read in chunks through Python) and 1.7 from a str.
    with open(path, "rb") as stream:
        return yaml.load(stream.read(), Loader=RosLoader)


def ros_arguments(argv: Sequence[str]) -> list[tuple[str, str | None]]:
    """(flag, value) of every ``--params-file``, ``-p``/``--param`` and ``-r``/``--remap`` inside
    ``--ros-args`` sections, in order, the flag as given; value None for a flag that ends the line."""
    found: list[tuple[str, str | None]] = []
    in_ros_args, expect = False, None
    for arg in argv:
        if expect is not None:
            found.append((expect, arg))
            expect = None
        elif arg == "--ros-args":
            in_ros_args = True
        elif arg == "--":
            in_ros_args = False
        elif in_ros_args and arg in ("--params-file", "-p", "--param", "-r", "--remap"):
            expect = arg
    return found if expect is None else [*found, (expect, None)]


def params_files(argv: Sequence[str]) -> list[Path]:
    """The ``--params-file`` arguments inside ``--ros-args`` sections of a command line."""
    return [Path(value) for flag, value in ros_arguments(argv) if flag == "--params-file" and value]


def check_ros_arguments(argv: Sequence[str]) -> None:
    """Refuse, with one line naming the argument, what rcl would refuse with a traceback: a
    ``--params-file`` that is missing, is not YAML, is not shaped ``{node: {ros__parameters: {...}}}``
    or holds a value no ROS parameter can take (null, an empty mapping, a mixed or nested list);
    a ``-p``/``-r`` rule without ``:=``. Only arguments inside ``--ros-args`` sections count."""
    for flag, value in ros_arguments(argv):
        if value is None:
            raise ConfigError(f"{flag}: a value must follow it")
        if flag == "--params-file":
            _check_params_file(Path(value))
        elif ":=" not in value or value.startswith(":="):
            raise ConfigError(f"{flag} {shown(value)}: expected NAME:=VALUE")


def _check_params_file(path: Path) -> None:
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ConfigError(f"--params-file {path}: {size / 2**20:.1f} MiB, more than the "
                              f"{MAX_FILE_BYTES >> 20} MiB a parameters file may have")
        with open(path, encoding="utf-8") as stream:
            _refuse_long_lists(path, stream)
        document = read_document(path)  # the one parse every later reader of the file shares
    except OSError as error:
        raise ConfigError(f"--params-file {path}: {error.strerror}") from None
    except UnicodeDecodeError as error:  # rcl reads UTF-8 (libyaml)
        raise ConfigError(f"--params-file {path}: not UTF-8 text (byte {error.start})") from None
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
