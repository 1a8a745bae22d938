"""The one node style of the package: a node built from a registered machine and a settings schema.

Parameters, one dialect for every node (``config/<machine>.yaml`` or ``config/<x>_nodes.yaml``):

* the machine under ``/**: ros__parameters: <section>: {...}`` (``excavator``, ``scara``, ...);
* the node's settings under ``/**/<node>: ros__parameters: {...}``: ``base_frame``,
  ``qos_depth``, ``warning_period``, ``topics.<key>`` and the node's own keys.

Precedence, the same for every node (:func:`command_line_values`): the package's defaults file,
then every ``--params-file`` in the order given (a later file wins; within one file the node's own
section ``/**/<node>`` or ``/<ns>/<node>`` beats ``/**``), then every ``-p name:=value``, which
wins over every params file wherever it stands on the command line. rcl alone orders sections by
their first appearance, so ``-p`` lost to a ``/**/<node>`` section of a file that also held a
``/**`` section; the node applies this rule to its parameters before it reads them.

Rules (:func:`machine_section`): with no machine file on the command line a node runs the default
machine of the package, and ``-p <section>.<key>:=v`` may change single values of it; a machine
file that is given must be complete, and is never filled from the default machine. Unknown,
missing and invalid keys, in the machine and in the settings, are refused at start-up with the
key named (:func:`manipulator_kinematics.schema.validate`). Every parameter is declared read-only
with a description: a run-time ``ros2 param set`` is refused with that reason.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import yaml
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from manipulator_kinematics.node_util import param
from manipulator_kinematics.param_files import (
    ConfigError,
    RosLoader,
    config_path,
    flatten,
    given_parameters,
    load_parameters,
    merge,
    params_files,
    ros_arguments,
    unflatten,
)
from manipulator_kinematics.registry import Machine, machines
from manipulator_kinematics.schema import Number, Schema, Text, validate

#: Parameters rclpy declares on every node by itself.
_RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")


def command_line_values(node_name: str, argv: Sequence[str]) -> dict[str, Any]:
    """The parameter values the command line gives the node ``node_name`` (fully qualified), flat,
    by the one precedence rule (module docstring): params files in order, then ``-p``. A ``-p``
    value is YAML, as rcl reads it; ``-p other_node:name:=v`` applies to that node only."""
    assigned: dict[str, Any] = {}
    base = node_name.rsplit("/", 1)[-1]
    for flag, value in ros_arguments(argv):
        if flag not in ("-p", "--param") or value is None:
            continue
        name, _, text = value.partition(":=")
        target, _, name = name.rpartition(":")
        if target in ("", base, node_name):
            try:
                assigned[name] = yaml.load(text, Loader=RosLoader) if text else ""
            except yaml.YAMLError:  # rcl takes such a value as a string
                assigned[name] = text
    return {**flatten(given_parameters(argv, node_name)), **assigned}


def apply_precedence(node: Node, argv: Sequence[str]) -> None:
    """Give every parameter the value :func:`command_line_values` says it has (rcl's own merge can
    differ: module docstring). Done before anything is read or declared read-only."""
    for name, value in command_line_values(node.get_fully_qualified_name(), argv).items():
        if name in _RCLPY_PARAMETERS or not node.has_parameter(name):
            continue
        current = node.get_parameter(name).value
        if _plain(current) != value:
            node.undeclare_parameter(name)
            node.declare_parameter(name, value, ignore_override=True)


def _plain(value: Any) -> Any:
    return value if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") else list(value)


def machine_section(node: Node, machine: Machine, argv: Sequence[str]) -> dict[str, Any]:
    """The machine description this node runs, validated (module docstring: the rules); a machine
    that reads several sections (``Machine.also``) takes them all from the files given, or all
    from its default file."""
    keys = (machine.section, *machine.also)
    given = {key: unflatten(_values(node, key)) for key in keys}
    files = given_parameters(argv, node.get_fully_qualified_name())
    if any(key in files for key in keys):
        source = ", ".join(str(path) for path in params_files(argv)) or "parameters"
        return machine.values({key: v for key, v in given.items() if key in files or v}, source)
    default = load_parameters(config_path(machine.config_file))
    return machine.values({key: merge(default.get(key, {}), given[key]) for key in keys})


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
        name: value
        for name, value in _values(node, "").items()
        if name not in _RCLPY_PARAMETERS and name.split(".", 1)[0] not in ignore
    }
    settings = validate(merge(defaults, unflatten(given)), schema)
    declare(node, settings, schema)
    return settings


def declare(node: Node, values: Mapping[str, Any], schema: Schema, prefix: str = "") -> None:
    """Declare every value (nested) read-only: its schema field's ``doc`` (else what it takes) as
    description, what it takes (the field's ``describe()``) as constraints, a single number's range."""
    for name, value in flatten(dict(values)).items():
        if value is not None:  # an optional setting left out: nothing to declare
            spec = _field(schema, name.split("."))
            bounds = None
            # An open limit (-inf or inf) is a value outside any range: no range for those.
            if isinstance(spec, Number) and not spec.open and math.isfinite(spec.min + spec.max):
                bounds = (spec.min, spec.max)
            kind = spec.describe()
            param(node, f"{prefix}.{name}" if prefix else name, value, spec.doc or kind, bounds, kind)


#: Reliability of a node's input subscriptions (setting ``input_reliability``). A best-effort
#: subscription hears reliable and best-effort publishers (a sensor driver on SensorDataQoS);
#: a reliable one only reliable publishers, and lets none of their messages get lost. Each node's
#: default is in its config file, with the reason (docs/architecture.md, "Input QoS").
RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}


#: Setting ``frame_prefix`` of every node that publishes or accepts frame_ids.
FRAME_PREFIX = Text(
    doc="put before base_frame (and every other frame_id the node publishes or accepts), as "
    "robot_state_publisher's frame_prefix: 'm1/' puts a machine's frames under m1/"
)


def input_reliability(what: str) -> Text:
    """The ``input_reliability`` setting of a node whose inputs are ``what``."""
    return Text(
        choices=tuple(RELIABILITY),
        doc=f"QoS reliability of the subscriptions to {what}: "
        "best_effort hears both kinds of publisher, reliable only reliable ones",
    )


def input_qos(depth: int, reliability: str) -> QoSProfile:
    """Keep-last ``depth`` subscription QoS with the ``input_reliability`` setting's policy."""
    return QoSProfile(depth=depth, reliability=RELIABILITY[reliability])


class MachineNode(Node):
    """Base of the package's nodes: ``self.machine``, ``self.model`` and ``self.settings``.

    ``SETTINGS`` is the node's settings schema; ``DEFAULTS_FILE`` the config file whose
    ``/**/<node>`` section holds their defaults (the machine's own file unless given).
    """

    SETTINGS: ClassVar[Schema] = {}
    DEFAULTS_FILE: str | None = None

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, automatically_declare_parameters_from_overrides=True)
        apply_precedence(self, argv)
        self.machine = machine
        section = machine_section(self, machine, argv)
        declare(
            self, {k: v for k, v in section.items() if k not in machine.also}, machine.schema, machine.section
        )
        for key, schema in machine.also.items():
            declare(self, section[key], schema, key)
        self.model = machine.factory(section)
        # Machine sections, not settings: this machine's, and those of machines that also read
        # its section (the excavator's own keys in a file the family's nodes run).
        readers = tuple(m.section for m in machines().values() if machine.section in m.also)
        self.settings = node_settings(
            self,
            self.SETTINGS,
            self.DEFAULTS_FILE or machine.config_file,
            node_name,
            ignore=(machine.section, *machine.also, *readers),
        )


def _values(node: Node, prefix: str) -> dict[str, Any]:
    return {name: parameter.value for name, parameter in node.get_parameters_by_prefix(prefix).items()}


def _field(schema: Schema, path: list[str]) -> Any:
    spec: Any = schema
    for part in path:
        if not isinstance(spec, Mapping):  # a field that holds a whole subtree (schema.Tree)
            return spec
        if part not in spec:
            return None
        spec = spec[part]
    return spec


__all__ = [
    "FRAME_PREFIX",
    "RELIABILITY",
    "ConfigError",
    "MachineNode",
    "apply_precedence",
    "command_line_values",
    "declare",
    "input_qos",
    "input_reliability",
    "machine_section",
    "node_settings",
    "params_files",
    "ros_arguments",
]
