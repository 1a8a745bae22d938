"""``<node> --help``: what a node does, its parameters with defaults, its topics and services.

Written from the same schemas and defaults files the node validates its parameters with, so the
help cannot drift from what the node accepts.
"""

from __future__ import annotations

import inspect
import textwrap
from collections.abc import Mapping
from typing import Any

from manipulator_kinematics.help_text import plain
from manipulator_kinematics.param_files import config_path, flatten, load_parameters
from manipulator_kinematics.registry import Machine, machines
from manipulator_kinematics.schema import REQUIRED, Schema

HELP_FLAGS = ("-h", "--help")
WIDTH = 100


def wants_help(argv: list[str]) -> bool:
    """-h or --help before any ``--ros-args`` (after it, rcl's own arguments start)."""
    head = argv[1 : argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    return any(arg in HELP_FLAGS for arg in head)


def help_text(node_class: type, machine: Machine | None, node_name: str, defaults_file: str | None) -> str:
    """The help of ``node_class`` run as ``node_name`` for ``machine`` (None: any registered one,
    chosen by the params file given)."""
    doc = plain(inspect.getdoc(inspect.getmodule(node_class)) or "")
    settings_file = defaults_file or (machine.config_file if machine else "")
    defaults = load_parameters(config_path(settings_file), f"/**/{node_name}")
    settings = _rows(node_class.SETTINGS, flatten(defaults))
    head = [
        f"usage: {node_name} [-h] [--ros-args [--params-file FILE] [-p NAME:=VALUE] [-r FROM:=TO]]",
        "",
        doc,
        "",
    ]
    tail = [
        "",
        textwrap.fill(
            f"Settings (section /**/{node_name} of a params file; defaults from config/{settings_file}). "
            "Topic names are relative: remap with -r or a namespace.",
            WIDTH,
        ),
        *settings,
        "",
        "Every parameter is read at start-up and read-only: restart the node to change one.",
    ]
    if machine is None:
        files = [f"  {m.name}: config/{m.config_file} (section {m.section!r})" for m in machines().values()]
        return "\n".join([*head, "Machine: the one whose section the params files hold:", *files, *tail])
    shipped = load_parameters(config_path(machine.config_file))
    machine_rows = [
        row
        for section, schema in ((machine.section, machine.schema), *machine.also.items())
        for row in _rows(schema, flatten(shipped.get(section, {})), section)
    ]
    sections = " and ".join(repr(s) for s in (*machine.also, machine.section))
    return "\n".join(
        [
            *head,
            textwrap.fill(
                f"Machine ({machine.name}: {machine.summary}): the section{'s' if machine.also else ''} "
                f"{sections} of a params file (default: config/{machine.config_file}). A file that is "
                f"given must be complete; without one, -p {'<section>' if machine.also else machine.section}"
                ".<key>:=<value> changes single values of the default machine.",
                WIDTH,
            ),
            *machine_rows,
            *tail,
        ]
    )


def _rows(schema: Schema, defaults: Mapping[str, Any], prefix: str = "") -> list[str]:
    rows = []
    for name, spec in _fields(schema):
        full = f"{prefix}.{name}" if prefix else name
        value = defaults.get(name, spec.default)
        shown = "(required)" if value is REQUIRED else ("(none)" if value is None else repr(value))
        what = spec.doc or spec.describe()  # a machine key without a doc: its kind, range and unit
        rows.append(f"  {full} = {shown}" + (f"  # {what}" if what else ""))
    return rows


def _fields(schema: Schema, prefix: str = "") -> list[tuple[str, Any]]:
    out = []
    for key, spec in schema.items():
        name = f"{prefix}.{key}" if prefix else key
        out += _fields(spec, name) if isinstance(spec, Mapping) else [(name, spec)]
    return out
