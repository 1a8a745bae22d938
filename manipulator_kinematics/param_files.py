"""ROS 2 parameter files as plain nested dicts (no rclpy), so cores and nodes share one loader.

A parameters file looks like ``{node_or_/**: {ros__parameters: {...}}}``; nested keys become
dotted parameter names in ROS (``hydraulic_machine.links.h_link.length``). Cores take the nested dict.

Each file is parsed once per process (:func:`read_document`, kept while the file is unchanged): the
start-up check of the command line (:func:`check_ros_arguments`), the node's values
(:func:`given_parameters`, :func:`load_parameters`), the machine and settings readers and the bag
tools all read that one document. Dicts are merged by one function, :func:`merge`.

:func:`read_document` is also the one safe reader of every YAML file of the package (parameters
and machine files, region tables, bag metadata): a file that is not a regular file, larger than
MAX_FILE_BYTES, not UTF-8 or not YAML, or that holds an alias or anchor, a tag outside the core
schema, collections nested deeper than MAX_DEPTH or of more than MAX_ITEMS items is refused with
one line naming the file and the reason, before anything is built from it (docs/architecture.md,
"Files the package reads"). :func:`open_input` opens every other file input by the same rule.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any, BinaryIO

import yaml

CONFIG_DIR = Path(__file__).resolve().parent.parent / "config"
#: Longest text of one value in an error line (characters): longer ones are cut with "...".
SHOWN = 100
#: Bounds of every YAML file the package reads (:func:`read_document`), checked before anything is
#: built from it: its size, the items of one list or mapping, the nesting of its collections. No
#: file of the package comes near any (the largest, the pump boom's region table, has 36 KB, 8
#: levels), and rcl takes seconds to parse a 100,000-element list (refused before it).
MAX_FILE_BYTES = 4 << 20
MAX_ITEMS = 10_000
MAX_DEPTH = 32
#: The tags a file may give explicitly, YAML's core schema: ``!!python/object`` and every other
#: one are refused by name (rcl knows none but ``!!str``).
CORE_TAGS = ("str", "int", "float", "bool", "null", "seq", "map")
_TAGS = frozenset([None, "!", *(f"tag:yaml.org,2002:{kind}" for kind in CORE_TAGS)])


class _Refused(yaml.MarkedYAMLError):
    """YAML that :func:`parse_yaml` refuses: ``where`` (the key, "" for none) and the problem."""

    def __init__(self, where: str, problem: str, mark: yaml.Mark) -> None:
        super().__init__(problem=problem, problem_mark=mark)
        self.where = where


class _CheckedComposer(yaml.composer.Composer):
    """PyYAML's composer with the bounds of every file (:func:`parse_yaml`), checked on each event
    before a node is built from it, so what follows a refused node is never read. (libyaml's own
    composer cannot be checked: it builds a whole document, nine levels of aliases included.)"""

    _path: list[Any]  # the mapping key of each node being composed (None: a list item, the root)

    def compose_document(self) -> yaml.Node:
        self._path = []
        return super().compose_document()

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        event = self.peek_event()
        problem = ""
        items = (
            index
            if isinstance(parent, yaml.SequenceNode)
            else len(parent.value)
            if isinstance(parent, yaml.MappingNode) and index is None
            else 0
        )
        if items >= MAX_ITEMS:
            problem = f"more than the {MAX_ITEMS} items a list or mapping may have"
        elif isinstance(event, yaml.AliasEvent):
            problem = f"alias *{shown(event.anchor, 40)[1:-1]}: aliases are refused (as rcl refuses them)"
        elif event.anchor is not None:
            problem = f"anchor &{shown(event.anchor, 40)[1:-1]}: anchors are refused (as rcl refuses aliases)"
        elif event.tag not in _TAGS:
            problem = f"tag {shown(event.tag, 60)}: only YAML's core tags ({', '.join(CORE_TAGS)})"
        elif isinstance(event, yaml.CollectionStartEvent) and len(self._path) >= MAX_DEPTH:
            problem = f"nested deeper than the {MAX_DEPTH} levels a file may have"
        key = index.value if isinstance(index, yaml.ScalarNode) else None
        if problem:
            raise _Refused(self._where(key), problem, event.start_mark)
        self._path.append(key)
        try:
            return super().compose_node(parent, index)
        finally:
            self._path.pop()

    def _where(self, key: Any) -> str:
        """``<section>: <dotted key>`` of the node being composed (``key``: its own key), a
        parameters file's ``ros__parameters`` left out of the name (``/**: scara.l1``)."""
        keys = [shown(str(k), 40)[1:-1] for k in (*self._path, key) if k is not None]
        if keys[1:2] == ["ros__parameters"]:
            return f"{keys[0]}: {'.'.join(keys[2:])}" if keys[2:] else keys[0]
        return ".".join(keys)


# libyaml's parser where PyYAML has it: the pure-Python one takes 3.5 s for a 1.2 MB file, this 0.4 s.
_Base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class RosLoader(_CheckedComposer, _Base):  # type: ignore[misc,valid-type]  # a base chosen at run time
    """YAML as rcl reads a parameter: a plain ``1e3`` is a number (YAML 1.2), as rcl's parser
    takes it, not the string PyYAML's YAML 1.1 rules make of it; quoted values stay strings.
    Refuses (a YAMLError) what :func:`parse_yaml` says."""

    def __init__(self, stream: bytes | str) -> None:
        _Base.__init__(self, stream)
        yaml.composer.Composer.__init__(self)


RosLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


#: Plain scalars rcl's parser reads as booleans though YAML 1.1 (PyYAML) reads them as strings
#: (``velocity_rows: [x, y, z]``: rcl refuses the list, "Sequence should be of same type").
_RCL_BOOLEAN = re.compile(r"^(?:y|Y|n|N)$")


class _RosDumper(yaml.SafeDumper):
    """PyYAML's safe dumper, quoting the strings rcl would read as something else."""

    def represent_str(self, data: str) -> yaml.ScalarNode:
        if _RCL_BOOLEAN.match(data):
            return self.represent_scalar("tag:yaml.org,2002:str", data, style='"')
        return super().represent_str(data)


_RosDumper.add_representer(str, _RosDumper.represent_str)


def dump_parameters(document: Any) -> str:
    """``document`` (nested plain data) as a parameters file rcl reads as :func:`load_parameters`
    does: block mappings, flow lists, keys in their order, ``y``/``n`` quoted."""
    return yaml.dump(document, Dumper=_RosDumper, sort_keys=False, default_flow_style=None)


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
    """The parsed YAML of ``path``: the one reader of every YAML file of the package (parameters and
    machine files, node settings, region tables, bag metadata). Parsed once per process while the
    file keeps its size and modification time; shared by every caller: read it, do not change it
    (:func:`merge` copies).

    ConfigError ``<path>: <reason>``, one line, before anything is built from the file: it is
    missing or not a regular file (a directory, FIFO or device: nothing blocks on it or reads it
    without end), larger than MAX_FILE_BYTES, or :func:`parse_yaml` refuses what it holds.
    """
    try:
        status = os.stat(path)
        _check_file(status, MAX_FILE_BYTES)
        return _parse(str(Path(path).resolve()), status.st_mtime_ns, status.st_size)
    except OSError as error:
        raise ConfigError(f"{path}: {error.strerror or error}") from None
    except ConfigError as error:
        raise ConfigError(f"{path}: {error}") from None


def open_input(path: str | Path, max_bytes: int) -> BinaryIO:
    """``path`` opened for reading bytes, the rule of every file input of the package: ConfigError
    ``<path>: <reason>`` if it is missing, not a regular file (a FIFO would block the reader, a
    device such as /dev/zero never end) or larger than ``max_bytes``. Read at most
    ``max_bytes + 1`` from it (a file can grow after the check)."""
    try:
        return _open(path, max_bytes)
    except OSError as error:
        raise ConfigError(f"{path}: {error.strerror or error}") from None
    except ConfigError as error:
        raise ConfigError(f"{path}: {error}") from None


def _open(path: str | Path, max_bytes: int) -> BinaryIO:
    # Opened without blocking (a FIFO) and checked on the open file (it may have been replaced
    # since a stat).
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        _check_file(os.fstat(fd), max_bytes)
    except ConfigError:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb")


def _check_file(status: os.stat_result, max_bytes: int) -> None:
    if not stat.S_ISREG(status.st_mode):
        kinds = (
            (stat.S_ISDIR, "a directory"),
            (stat.S_ISFIFO, "a FIFO"),
            (stat.S_ISCHR, "a character device"),
            (stat.S_ISBLK, "a block device"),
            (stat.S_ISSOCK, "a socket"),
        )
        kind = next((name for test, name in kinds if test(status.st_mode)), "something")
        raise ConfigError(f"{kind}, not a regular file")
    if status.st_size > max_bytes:
        raise ConfigError(
            f"{status.st_size / 2**20:.1f} MiB, more than the {max_bytes >> 20} MiB such a file may have"
        )


def clear_cache() -> None:
    """Forget every parsed file (a benchmark timing the parse itself)."""
    _parse.cache_clear()


@lru_cache(maxsize=64)
def _parse(path: str, mtime_ns: int, size: int) -> Any:
    with _open(path, MAX_FILE_BYTES) as stream:
        data = stream.read(MAX_FILE_BYTES + 1)
    if len(data) > MAX_FILE_BYTES:  # grew since the check
        raise ConfigError(f"more than the {MAX_FILE_BYTES >> 20} MiB such a file may have")
    return parse_yaml(data)


def parse_yaml(data: bytes | str) -> Any:
    """YAML as rcl reads it (:class:`RosLoader`), refused with ConfigError (one line, the reason)
    before anything is built when it is not UTF-8 or not YAML, or holds what rcl refuses or no file
    of the package needs: an alias or anchor (nine levels of aliases in 1.4 KB had the code that
    walks PyYAML's output expand them to gigabytes), a tag outside YAML's core schema
    (``!!python/object``, ``!!binary``, ...), collections nested deeper than MAX_DEPTH (a
    RecursionError in the code that walks them), a list or mapping of more than MAX_ITEMS items.
    Bytes go to libyaml as they are: it decodes UTF-8 itself, faster than from a str."""
    try:
        if isinstance(data, bytes):
            data.decode("utf-8")
        return yaml.load(data, Loader=RosLoader)
    except UnicodeDecodeError as error:  # rcl reads UTF-8 (libyaml)
        raise ConfigError(f"not UTF-8 text (byte {error.start})") from None
    except _Refused as error:
        line = f"line {error.problem_mark.line + 1}"
        raise ConfigError(
            f"{error.where} ({line}): {error.problem}" if error.where else f"{line}: {error.problem}"
        ) from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        line = f" (line {mark.line + 1})" if mark is not None else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise ConfigError(f"not valid YAML{line}: {shown(problem, 60)[1:-1]}") from None
    except ValueError as error:  # a value the constructor cannot build (an int of 5,000 digits)
        raise ConfigError(f"a value cannot be read: {shown(str(error), 80)[1:-1]}") from None


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
        document = read_document(path)  # the one parse every later reader of the file shares
    except ConfigError as error:
        raise ConfigError(f"--params-file {error}") from None
    if not isinstance(document, dict) or not document:
        raise ConfigError(f"--params-file {path}: expected sections {{node: {{ros__parameters: {{...}}}}}}")
    for node, section in document.items():
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise ConfigError(f"--params-file {path}: {node}: expected a mapping 'ros__parameters:'")
        for name, value in _leaves(section["ros__parameters"]):
            if not _parameter_value(value):
                raise ConfigError(
                    f"--params-file {path}: {node}: {name} = {shown(value)} is not a ROS "
                    "parameter value (a number, string, bool, or a list of one of those)"
                )


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
        kinds = {
            bool if isinstance(v, bool) else (float if isinstance(v, (int, float)) else type(v))
            for v in value
        }
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
