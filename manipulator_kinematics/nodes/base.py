"""The one node style of the package: a node built from a registered machine and a settings schema.

Parameters, one dialect for every node (``config/<machine>.yaml`` or ``config/<x>_nodes.yaml``):

* the machine under ``/**: ros__parameters: <section>: {...}`` (``excavator``, ``scara``, ...);
* the node's settings under ``/**/<node>: ros__parameters: {...}``: ``base_frame``,
  ``qos_depth``, ``warning_period``, ``topics.<key>`` and the node's own keys.

Rules (:func:`machine_section`): with no machine file on the command line a node runs the default
machine of the package, and ``-p <section>.<key>:=v`` may change single values of it; a machine
file that is given must be complete, and is never filled from the default machine. Unknown,
missing and invalid keys, in the machine and in the settings, are refused at start-up with the
key named (:func:`manipulator_kinematics.config.validate`). Every parameter is declared read-only
with a description: a run-time ``ros2 param set`` is refused with that reason.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

from rclpy.node import Node

from manipulator_kinematics.config import Schema, validate
from manipulator_kinematics.node_util import param
from manipulator_kinematics.params import ConfigError, config_path, flatten, load_parameters, unflatten
from manipulator_kinematics.registry import Machine

#: Parameters rclpy declares on every node by itself.
_RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")


def params_files(argv: Sequence[str]) -> list[Path]:
    """The ``--params-file`` arguments inside ``--ros-args`` sections of a command line."""
    files, in_ros_args, expect = [], False, False
    for arg in argv:
        if expect:
            files.append(Path(arg))
            expect = False
        elif arg == "--ros-args":
            in_ros_args = True
        elif arg == "--":
            in_ros_args = False
        elif in_ros_args and arg == "--params-file":
            expect = True
    return files


def machine_section(node: Node, machine: Machine, argv: Sequence[str]) -> dict[str, Any]:
    """The machine description this node runs, validated (module docstring: the rules)."""
    given = unflatten(_values(node, machine.section))
    from_file = any(machine.section in load_parameters(path, node.get_fully_qualified_name())
                    for path in params_files(argv) if path.is_file())
    if from_file:
        return validate(given, machine.schema, machine.section)
    default = load_parameters(config_path(machine.config_file))[machine.section]
    return validate(_merge(default, given), machine.schema, machine.section)


def node_settings(
    node: Node, schema: Schema, defaults_file: str, section: str, ignore: Sequence[str] = ()
) -> dict[str, Any]:
    """The node's settings: the package's ``defaults_file`` section ``/**/<section>`` (the node's
    own name, whatever ``-r __node:=`` renamed it to), overridden by the parameters given to the
    node, validated against ``schema``. ``ignore`` lists parameter prefixes that are not settings
    (the machine section)."""
    defaults = load_parameters(config_path(defaults_file), f"/**/{section}")
    for prefix in ignore:
        defaults.pop(prefix, None)
    given = {
        name: value for name, value in _values(node, "").items()
        if name not in _RCLPY_PARAMETERS and name.split(".", 1)[0] not in ignore
    }
    settings = validate(_merge(defaults, unflatten(given)), schema)
    declare(node, settings, schema)
    return settings


def declare(node: Node, values: Mapping[str, Any], schema: Schema, prefix: str = "") -> None:
    """Declare every value (nested) read-only, described by its schema field's ``doc``."""
    for name, value in flatten(dict(values)).items():
        if value is not None:  # an optional setting left out: nothing to declare
            param(node, f"{prefix}.{name}" if prefix else name, value, _doc(schema, name.split(".")))


class MachineNode(Node):
    """Base of the package's nodes: ``self.machine``, ``self.model`` and ``self.settings``.

    ``SETTINGS`` is the node's settings schema; ``DEFAULTS_FILE`` the config file whose
    ``/**/<node>`` section holds their defaults (the machine's own file unless given).
    """

    SETTINGS: ClassVar[Schema] = {}
    DEFAULTS_FILE: str | None = None

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, automatically_declare_parameters_from_overrides=True)
        self.machine = machine
        section = machine_section(self, machine, argv)
        declare(self, section, machine.schema, machine.section)
        self.model = machine.factory(section)
        self.settings = node_settings(self, self.SETTINGS, self.DEFAULTS_FILE or machine.config_file,
                                      node_name, ignore=(machine.section,))


def _values(node: Node, prefix: str) -> dict[str, Any]:
    return {name: parameter.value for name, parameter in node.get_parameters_by_prefix(prefix).items()}


def _doc(schema: Schema, path: list[str]) -> str:
    spec: Any = schema
    for part in path:
        if not isinstance(spec, Mapping) or part not in spec:
            return ""
        spec = spec[part]
    return getattr(spec, "doc", "")


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        both_sections = isinstance(value, dict) and isinstance(out.get(key), dict)
        out[key] = _merge(out[key], value) if both_sections else value
    return out


__all__ = ["ConfigError", "MachineNode", "declare", "machine_section", "node_settings", "params_files"]
