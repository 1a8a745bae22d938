"""Machines found through Python entry points: the shared package never imports a machine package.

Each machine package declares one :class:`Machine` in the entry-point group
``manipulator_kinematics.machines`` (``setup.py``)::

    "manipulator_kinematics.machines": ["scara = scara_kinematics.machine:MACHINE"]

A Machine says what the bag tools, the generic nodes and the tests need to know: the parameter
section and default config file of the machine, the schema that validates it, the model factory,
its joints and limits, the topics its nodes use (for ``record``), how to check a recorded run
against the recomputed kinematics (``evaluate``) and how to write a synthetic bag (golden bags).
Adding a machine touches only its own package, its config and the entry point.

The bag hooks (None where a machine has none):

* ``analyse(data, model, context) -> (report, plots)``: ``data: dict[str, TopicArrays]`` maps
  the machine's topic names (relative, as in ``topics``) of one namespace of a bag to their
  messages; ``model`` is the machine's model (``--params`` or the default); ``context`` an
  :class:`manipulator_kinematics.bag.analysis.AnalysisContext` (``t0``: stamp origin in ns,
  ``prefix``: plot-name prefix of the namespace and machine, ``node_settings``: node name ->
  settings of the package's config files merged with ``evaluate --params`` files, so an analysis
  can mirror its nodes' thresholds). Returns a JSON-ready dict (a ``consistency`` entry of
  ``{topic: {matched, unmatched, <quantity>: error_stats}}`` is shown as a table) and a list of
  :class:`manipulator_kinematics.bag.analysis.Plot`. Serial machines use
  :func:`manipulator_kinematics.bag.analysis.serial`.
* ``synthesize(model, samples, rate_hz) -> dict[str, Topic]``: a bag's topics (absolute names ->
  :class:`manipulator_kinematics.bag.synthetic.Topic`): the inputs of the forward node along a
  smooth motion and the outputs it must publish for them (``scripts/make_golden_bags.py`` writes
  ``test/data/<name>_forward_golden``). Serial machines use
  :func:`manipulator_kinematics.bag.synthetic.serial_bag`.
* ``samples(data, model, context) -> (columns, units)``: one row per input the machine's
  forward node accepted, as ``{name: (N,) array}`` with ``stamp_ns`` first, and each column's
  unit; the as-built tools (``mk_asbuilt``) write it as a Parquet table and map the cutting
  edge from the columns ``left_site_x/y/z`` and ``right_site_x/y/z`` where a machine has them
  (docs/asbuilt.md).
* ``forward_node``: console script (= node name) of the machine's forward node; the golden-bag
  replay test (test/test_bag_ros.py) runs it on the golden bag, which must exist.

The description hook:

* ``urdf(model) -> str``: the URDF (XML text) of the machine described by ``model``, for
  robot_state_publisher and ``/robot_description``; :func:`manipulator_kinematics.urdf.machine_urdf`
  calls it and ``mk_urdf`` writes it. Serial machines use
  :func:`manipulator_kinematics.urdf.serial_urdf`.

The drawing hook:

* ``scene(model, state) -> Scene``: the machine as solids in its base frame
  (:class:`manipulator_kinematics.scene.Scene`) for states (..., n) in the order of
  ``joint_names(model)``; markers (``machine_markers``), Foxglove-ready bags
  (:mod:`manipulator_kinematics.bag.visual`) and animations draw it. Serial machines use
  :func:`manipulator_kinematics.scene.serial_scene`.

Machines of one family share a parameter section (the hydraulic family's ``hydraulic_machine``,
:mod:`manipulator_kinematics.hydraulic.machine`): their records differ in name, default file and
``describes`` (which of them a section's values are); the family's shared nodes run whatever
machine file they are given, so a family machine also names the ``node_arguments`` that make them
run it (``--params-file <its file>``).

The avoidance-zone hooks (docs/zones.md), for the markers' zones and monitored points:

* ``monitored(model)``: the points avoidance zones watch, an object with ``names`` and
  ``positions(state) -> (..., P, 3)`` (base frame) for states in the order of ``joint_names``;
* ``read_surface(file, name)``: a LandXML TIN for ``kind: surface`` zones
  (:class:`manipulator_kinematics.zones.Surface`).

A machine may read more than its own section: ``also`` names the other top-level sections of its
files and their schemas (the excavator's files carry its linkage in the family's
``hydraulic_machine`` section beside the ``excavator`` section), and ``read`` turns a file's
top-level sections into the values its factory takes (its own section's, each ``also`` section's
under its name). Such a file describes that one machine (:func:`machines_described`); the nodes of a
machine whose section another machine reads (the family's) skip that machine's own section.

Hooks are usually given as :class:`Hook` ("module:function", imported on the first call), so that
loading the registry, which every node does at start-up, imports no bag, URDF or drawing code.
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.schema import Schema, validate
from manipulator_kinematics.serial_chain import JointLimits

GROUP = "manipulator_kinematics.machines"


class Hook:
    """A hook named ``"module:function"``, imported on its first call."""

    def __init__(self, target: str) -> None:
        self.target = target
        self._function: Callable[..., Any] | None = None

    def resolve(self) -> Callable[..., Any]:
        """The function itself (ImportError or AttributeError if the name is wrong)."""
        if self._function is None:
            module, _, name = self.target.partition(":")
            self._function = getattr(importlib.import_module(module), name)
        return self._function

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.resolve()(*args, **kwargs)

    def __repr__(self) -> str:
        return f"Hook({self.target!r})"


def _joint_names(model: Any) -> tuple[str, ...]:
    return tuple(model.joint_names)


def _limits(model: Any) -> JointLimits:
    return model.limits


@dataclass(frozen=True)
class Machine:
    """One machine kind, as its package declares it.

    ``factory`` builds the model from the validated parameter section; ``topics`` maps each
    topic its nodes use (relative name) to its message type (``pkg/msg/Type``); ``analyse``,
    ``synthesize``, ``samples`` and ``forward_node`` are the bag hooks (module docstring), None where the
    machine has none; ``urdf`` builds the machine's URDF from a model (module docstring);
    ``scene`` draws it, ``monitored`` and ``read_surface`` serve its avoidance zones (module
    docstring). ``describes(values)``: whether a section's values are
    this machine (None: every value of its section is; needed where machines share a section);
    ``node_arguments``: the ROS arguments its nodes need to run it (``forward_node`` included);
    ``also`` and ``read``: the other sections it reads (module docstring).
    """

    name: str
    summary: str
    section: str
    config_file: str
    schema: Schema
    factory: Callable[[dict[str, Any]], Any]
    topics: Mapping[str, str] = field(default_factory=dict)
    joint_names: Callable[[Any], tuple[str, ...]] = _joint_names
    limits: Callable[[Any], JointLimits] = _limits
    analyse: Callable[..., Any] | None = None
    synthesize: Callable[..., Any] | None = None
    samples: Callable[..., Any] | None = None
    forward_node: str | None = None
    urdf: Callable[[Any], str] | None = None
    scene: Callable[[Any, Any], Any] | None = None  # (model, state array) -> scene.Scene
    describes: Callable[[Mapping[str, Any]], bool] | None = None
    node_arguments: tuple[str, ...] = ()
    monitored: Callable[[Any], Any] | None = None  # model -> names + positions(state) (module docstring)
    read_surface: Callable[[str, str], Any] | None = None  # (file, surface name) -> zones.Surface
    also: Mapping[str, Schema] = field(default_factory=dict)  # other sections it reads: schemas
    read: Callable[[Mapping[str, Any], str], dict[str, Any]] | None = None  # (sections, source) -> values

    def values(self, params: Mapping[str, Any], source: str = "parameters") -> dict[str, Any]:
        """What the factory takes from a file's top-level sections ``params``, validated."""
        if self.read is not None:
            return self.read(params, source)
        if self.section not in params:
            raise ConfigError(f"{source}: no {self.section!r} section under /**: ros__parameters")
        return validate(params[self.section], self.schema, self.section)

    def parameters(self, path: str | Path | None = None, node_name: str = "/**") -> dict[str, Any]:
        """The machine's values in ``path`` (default: its shipped config file), validated."""
        path = config_path(self.config_file) if path is None else Path(path)
        return self.values(load_parameters(path, node_name), str(path))

    def model(self, path: str | Path | None = None) -> Any:
        """The model described by ``path`` (default: the shipped machine)."""
        return self.factory(self.parameters(path))

    def model_of(self, params: Mapping[str, Any]) -> Any:
        """The model of a file's nested top-level sections (validated here)."""
        return self.factory(self.values(params))

    def model_from(self, section: Mapping[str, Any]) -> Any:
        """The model of a nested parameter section (validated here), laid out as :meth:`values`
        returns it: each ``also`` section under its name (``model_from(parameters())`` is the
        file's model)."""
        own = {k: v for k, v in section.items() if k not in self.also}
        return self.model_of({self.section: own, **{k: section[k] for k in self.also if k in section}})


@cache
def machines() -> dict[str, Machine]:
    """Every installed machine by name (entry points of :data:`GROUP`)."""
    found: dict[str, Machine] = {}
    for entry in entry_points(group=GROUP):
        machine = entry.load()
        if not isinstance(machine, Machine) or machine.name != entry.name:
            raise TypeError(f"entry point {entry.name} = {entry.value} is not a Machine named {entry.name!r}")
        found[entry.name] = machine
    return dict(sorted(found.items()))


def machine(name: str) -> Machine:
    """The machine ``name``; KeyError with the known names (and a near miss) otherwise."""
    known = machines()
    if name in known:
        return known[name]
    close = difflib.get_close_matches(name, list(known), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise KeyError(f"no machine {name!r}{hint}; installed: {', '.join(known) or 'none'}")


def machines_described(params: Mapping[str, Any]) -> dict[str, Machine]:
    """The machines a file's top-level sections ``params`` describe, by their section: a section
    that another machine of the file also reads (``also``) is that machine's, not one of its own."""
    found = {key: m for key, values in params.items() if (m := by_section(key, values)) is not None}
    taken = {key for m in found.values() for key in m.also}
    return {key: m for key, m in found.items() if key not in taken}


def by_section(section: str, values: Any = None) -> Machine | None:
    """The machine that a params file's top-level key ``section`` with its ``values`` describes.

    Where several machines share the section (one family), the one whose ``describes`` accepts
    ``values``; a section none of them ships (a user's own machine of the family) gets the
    family's first machine by name: every machine of a family has the same model factory, which
    reads any file of the section, so that record lends it its defaults and name only. None when
    no machine has the section."""
    candidates = [m for m in machines().values() if m.section == section]
    if len(candidates) > 1 and isinstance(values, Mapping):
        return next((m for m in candidates if m.describes is not None and m.describes(values)), candidates[0])
    return candidates[0] if candidates else None
