"""A cylinder-driven manipulator as data: the machine file of the hydraulic family (paper 000).

Paper 000 treats every cantilever manipulator of construction machinery (its Figs. 1-3) as an
open main chain driven by closed-loop cylinder mechanisms. A machine file says which: bodies
with their pins (each in its own frame), rigid two-pin links, cylinders (base pin, rod pin,
stroke, speed), an optional swing, optional prismatic joints (a telescope), the solve order as
dyads with their branch signs, the main chain's joints and the tool point. docs/hydraulic_family.md
describes the format; :func:`parse` validates a ``hydraulic_machine`` section into a
:class:`Description` with :mod:`manipulator_kinematics.schema` (every unknown, missing or wrong key
refused with the key named, in one line) and derives the solve plan
(:class:`Dyad`, :class:`Place`, :class:`Slide` steps), refusing a dyad whose centres are not known
when it is solved, a loop left open (a dyad side that is neither one body nor one cylinder), a pin
named on more than two bodies, and a body the plan never places.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from manipulator_kinematics.param_files import ConfigError, load_parameters, shown
from manipulator_kinematics.schema import Flag, Names, Number, Numbers, Schema, Text, require, validate

__all__ = ["SECTION", "Cylinder", "Description", "Dyad", "Joint", "Place", "Slide", "parse", "read"]

#: The parameter section of a family machine file (under ``/**: ros__parameters``).
SECTION = "hydraulic_machine"

_POINT = Numbers(2, Number(-30.0, 30.0, "m"))
_NAME = Text(empty=False)
_TOP: Schema = {
    "name": Text(empty=False, doc="machine name"),
    "ground": Text(empty=False, doc="the body whose frame is the boom plane (r, z)"),
    "actuators": Names(doc="cylinders in the order of D (after the swing angle, if any)"),
    "assembly": Names(doc="unknown pins in solve order, one dyad each"),
    "joints": Names(doc="main-chain joints in order (theta2, theta3, ...)"),
}
_LINK: Schema = {"from": _NAME, "to": _NAME, "length": Number(0.0, 30.0, "m", exclusive_min=True)}
_CYLINDER: Schema = {
    "base_pin": _NAME,
    "rod_pin": _NAME,
    "min_length": Number(0.0, 20.0, "m", exclusive_min=True),
    "max_length": Number(0.0, 20.0, "m", exclusive_min=True),
    "reference_length": Number(0.0, 20.0, "m", exclusive_min=True),
    "max_speed": Number(0.0, 5.0, "m/s", exclusive_min=True),
    "zero_offset": Number(-1.0, 1.0, "m", default=0.0, doc="true length = sensor reading + zero_offset"),
}
_SWING: Schema = {
    "actuator": _NAME,
    "min_angle": Number(-2 * math.pi, 2 * math.pi, "rad"),
    "max_angle": Number(-2 * math.pi, 2 * math.pi, "rad"),
    "reference_angle": Number(-2 * math.pi, 2 * math.pi, "rad"),
    "max_speed": Number(0.0, 10.0, "rad/s", exclusive_min=True),
    "zero_offset": Number(
        -math.pi, math.pi, "rad", default=0.0, doc="true angle = encoder reading + zero_offset"
    ),
    "tail_radius": Number(
        0.0,
        30.0,
        "m",
        exclusive_min=True,
        default=None,
        doc="optional: the upper structure's tail swing radius, watched by the avoidance zones at "
        "tail_heights (docs/zones.md)",
    ),
    "tail_heights": Numbers(
        item=Number(-30.0, 30.0, "m"),
        default=None,
        doc="optional: heights (base frame) of the watched points at tail_radius behind the swing axis",
    ),
}
_PRISMATIC: Schema = {
    "parent": _NAME,
    "child": _NAME,
    "cylinder": _NAME,
    "axis_point": _POINT,
    "offset": Number(-20.0, 20.0, "m"),
}
_DYAD: Schema = {"pivot": _NAME, "first": _NAME, "orientation": Number(-1, 1, integer=True)}
_JOINT: Schema = {"parent": _NAME, "child": _NAME, "limits": Numbers(2, Number(-2 * math.pi, 2 * math.pi))}
_TOOL: Schema = {
    "body": _NAME,
    "pin": _NAME,
    "width": Number(0.0, 20.0, "m"),
    "angle": Flag(doc="true: Q has the tool angle alpha"),
    "velocity_rows": Names(doc="rows of Q the velocity IK solves (eq. 9)"),
    "outline": Numbers(
        item=Number(-30.0, 30.0, "m"),
        default=None,
        doc="optional: points [x1, z1, x2, z2, ...] of the tool body's outline (its frame), watched "
        "by the avoidance zones on both side faces (docs/zones.md)",
    ),
}
_SECTIONS = ("bodies", "links", "cylinders", "swing", "prismatic", "dyads", "chain", "tool")
_OPTIONAL = ("links", "swing", "prismatic")


@dataclass(frozen=True)
class Cylinder:
    """A cylinder: |rod pin - base pin| = its length, the column ``index`` of D."""

    name: str
    base: str
    rod: str
    lower: float
    upper: float
    reference: float
    max_speed: float
    index: int
    zero_offset: float = 0.0  # true length = sensor reading + zero_offset (m)


@dataclass(frozen=True)
class Radius:
    """One side of a dyad: a fixed distance on one body, or the length of cylinder D[index]."""

    fixed: float
    index: int | None = None  # column of D when the side is a cylinder


@dataclass(frozen=True)
class Dyad:
    """X = circle(A, r_A) ∩ circle(B, r_B) with sign(cross(B - A, X - A)) = orientation."""

    pin: str
    pivot: str
    first: str
    pivot_radius: Radius
    first_radius: Radius
    orientation: int


@dataclass(frozen=True)
class Place:
    """Body ``body`` placed from two known pins (its frame from their positions)."""

    body: str
    one: str
    two: str


@dataclass(frozen=True)
class Slide:
    """Prismatic child placed along its parent's x axis: origin = axis_point + (D[index] + offset, 0)."""

    parent: str
    child: str
    axis_point: tuple[float, float]
    offset: float
    index: int
    name: str  # its key under prismatic:


@dataclass(frozen=True)
class Joint:
    """A main-chain joint: revolute (theta = phi_child - phi_parent) or prismatic (d = s)."""

    name: str
    parent: str
    child: str
    lower: float
    upper: float
    pivot: str | None  # the hinge pin (revolute); None for a prismatic joint
    slide: Slide | None

    @property
    def hinge(self) -> str:
        """The hinge pin of a revolute joint (a prismatic joint has none)."""
        if self.pivot is None:
            raise ValueError(f"{self.name} is prismatic: it has no hinge pin")
        return self.pivot


@dataclass(frozen=True)
class Description:
    """A validated machine of the hydraulic family (module docstring)."""

    name: str
    ground: str
    bodies: Mapping[str, Mapping[str, np.ndarray]]  # body -> pin -> local (x, z)
    cylinders: tuple[Cylinder, ...]
    swing: Mapping[str, Any] | None
    steps: tuple[Dyad | Place | Slide, ...]
    joints: tuple[Joint, ...]
    tool_body: str
    tool_pin: str
    width: float
    has_angle: bool
    velocity_rows: tuple[int, ...]
    #: Avoidance-zone points (docs/zones.md): the tool body's outline, (x, z) in its frame, and
    #: the upper structure's tail, (radius behind the swing axis, height); empty where not given.
    outline: tuple[tuple[float, float], ...] = ()
    tail: tuple[tuple[float, float], ...] = ()

    @property
    def actuator_names(self) -> tuple[str, ...]:
        swing = (self.swing["actuator"],) if self.swing else ()
        return swing + tuple(c.name for c in self.cylinders)

    @property
    def lower(self) -> np.ndarray:
        swing = [self.swing["min_angle"]] if self.swing else []
        return np.array(swing + [c.lower for c in self.cylinders])

    @property
    def upper(self) -> np.ndarray:
        swing = [self.swing["max_angle"]] if self.swing else []
        return np.array(swing + [c.upper for c in self.cylinders])

    @property
    def reference(self) -> np.ndarray:
        swing = [self.swing["reference_angle"]] if self.swing else []
        return np.array(swing + [c.reference for c in self.cylinders])

    @property
    def max_speed(self) -> np.ndarray:
        swing = [self.swing["max_speed"]] if self.swing else []
        return np.array(swing + [c.max_speed for c in self.cylinders])

    @property
    def zero_offset(self) -> np.ndarray:
        """Per actuator, what its sensor misses: true value = reading + zero_offset (rad, m)."""
        swing = [self.swing["zero_offset"]] if self.swing else []
        return np.array(swing + [c.zero_offset for c in self.cylinders])

    @property
    def task_names(self) -> tuple[str, ...]:
        return ("x", "y", "z", "alpha") if self.has_angle else ("x", "y", "z")

    @property
    def joint_names(self) -> tuple[str, ...]:
        return (("theta1",) if self.swing else ()) + tuple(j.name for j in self.joints)


def read(path: str | Path, node_name: str = "/**") -> Description:
    """The machine of a family machine file (a ROS 2 parameters file with a ``hydraulic_machine``
    section)."""
    params = load_parameters(path, node_name)
    if SECTION not in params:
        raise ConfigError(f"{path}: no {SECTION!r} section under /**: ros__parameters")
    return parse(params[SECTION])


def parse(section: Any, prefix: str = SECTION) -> Description:
    """The :class:`Description` of a ``hydraulic_machine`` mapping; ConfigError names the key."""
    if not isinstance(section, Mapping):
        raise ConfigError(f"{prefix}: expected a mapping of keys, got {shown(section)}")
    for key in section:
        if key not in _TOP and key not in _SECTIONS:  # the unknown-key line, with "did you mean"
            validate({key: None}, {**_TOP, **dict.fromkeys(_SECTIONS, Text())}, prefix)
    top = validate({k: v for k, v in section.items() if k not in _SECTIONS}, _TOP, prefix)
    for key in _SECTIONS:
        if key not in section and key not in _OPTIONAL:
            raise ConfigError(f"{prefix}.{key}: missing")

    bodies = _bodies(section["bodies"], f"{prefix}.bodies")
    for name, link in _optional(section, "links", prefix).items():
        key = f"{prefix}.links.{name}"
        values = validate(link, _LINK, key)
        require(name not in bodies, key, "a body of that name exists already")
        require(values["from"] != values["to"], f"{key}.to", f"pin {values['to']!r} named twice")
        bodies[name] = {values["from"]: np.zeros(2), values["to"]: np.array([values["length"], 0.0])}
    require(top["ground"] in bodies, f"{prefix}.ground", f"no body {top['ground']!r}")
    owners: dict[str, list[str]] = {}
    for body, pins in bodies.items():
        for pin in pins:
            owners.setdefault(pin, []).append(body)
    for pin, names in owners.items():
        if len(names) > 2:
            third = names[2]
            where = f"links.{third}" if third in section.get("links", {}) else f"bodies.{third}.pins.{pin}"
            raise ConfigError(
                f"{prefix}.{where}: pin {pin!r} named twice: already the hinge of {names[0]} and "
                f"{names[1]} (a hinge joins two bodies)"
            )

    swing = None
    if "swing" in section:
        swing = validate(section["swing"], _SWING, f"{prefix}.swing")
        require(swing["min_angle"] < swing["max_angle"], f"{prefix}.swing.max_angle", "must exceed min_angle")
        require(
            swing["min_angle"] <= swing["reference_angle"] <= swing["max_angle"],
            f"{prefix}.swing.reference_angle",
            "outside [min_angle, max_angle]",
        )
        radius, heights = swing["tail_radius"], swing["tail_heights"]
        require(
            (radius is None) == (heights is None),
            f"{prefix}.swing.{'tail_heights' if heights is None else 'tail_radius'}",
            "tail_radius and tail_heights go together",
        )
    offset = 1 if swing else 0
    raw_cylinders = _named(section["cylinders"], f"{prefix}.cylinders")
    cylinders = []
    for i, name in enumerate(top["actuators"]):
        key = f"{prefix}.cylinders.{name}"
        require(name in raw_cylinders, key, "missing (named in actuators)")
        c = validate(raw_cylinders[name], _CYLINDER, key)
        for end in ("base_pin", "rod_pin"):
            require(c[end] in owners, f"{key}.{end}", f"no body has pin {c[end]!r}")
        require(c["min_length"] < c["max_length"], f"{key}.max_length", "must exceed min_length")
        require(
            c["min_length"] <= c["reference_length"] <= c["max_length"],
            f"{key}.reference_length",
            "outside [min_length, max_length]",
        )
        cylinders.append(
            Cylinder(
                name,
                c["base_pin"],
                c["rod_pin"],
                c["min_length"],
                c["max_length"],
                c["reference_length"],
                c["max_speed"],
                i + offset,
                c["zero_offset"],
            )
        )
    for name in raw_cylinders:
        require(name in top["actuators"], f"{prefix}.cylinders.{name}", "not named in actuators")
    by_cylinder = {c.name: c for c in cylinders}

    slides = {}
    for name, raw in _optional(section, "prismatic", prefix).items():
        key = f"{prefix}.prismatic.{name}"
        p = validate(raw, _PRISMATIC, key)
        for end in ("parent", "child"):
            require(p[end] in bodies, f"{key}.{end}", f"no body {p[end]!r}")
        require(p["cylinder"] in by_cylinder, f"{key}.cylinder", f"no cylinder {p['cylinder']!r}")
        slides[(p["parent"], p["child"])] = Slide(
            p["parent"],
            p["child"],
            tuple(p["axis_point"]),
            p["offset"],
            by_cylinder[p["cylinder"]].index,
            name,
        )

    steps = _plan(top, bodies, owners, cylinders, slides, section["dyads"], prefix)
    joints = _chain(top, bodies, slides, section["chain"], prefix)
    tool = validate(section["tool"], _TOOL, f"{prefix}.tool")
    require(
        tool["body"] == joints[-1].child,
        f"{prefix}.tool.body",
        f"must be the last body of the chain, {joints[-1].child!r}",
    )
    require(tool["pin"] in bodies[tool["body"]], f"{prefix}.tool.pin", f"not a pin of {tool['body']!r}")
    has_angle = tool["angle"]
    tasks = ("x", "y", "z", "alpha") if has_angle else ("x", "y", "z")
    for row in tool["velocity_rows"]:
        require(row in tasks, f"{prefix}.tool.velocity_rows", f"{row!r} is not one of {', '.join(tasks)}")
    outline = tool["outline"] or []
    require(len(outline) % 2 == 0, f"{prefix}.tool.outline", "expected [x, z] pairs: an even count")
    tail = [(swing["tail_radius"], h) for h in swing["tail_heights"] or []] if swing else []
    return Description(
        name=top["name"],
        ground=top["ground"],
        bodies=bodies,
        cylinders=tuple(cylinders),
        swing=swing,
        steps=steps,
        joints=joints,
        tool_body=tool["body"],
        tool_pin=tool["pin"],
        width=tool["width"],
        has_angle=has_angle,
        velocity_rows=tuple(tasks.index(r) for r in tool["velocity_rows"]),
        outline=tuple(zip(outline[::2], outline[1::2], strict=True)),
        tail=tuple(tail),
    )


def _named(value: Any, key: str) -> dict[str, Any]:
    if not isinstance(value, Mapping) or not value:
        raise ConfigError(f"{key}: expected a mapping of names, got {shown(value)}")
    return {str(k): v for k, v in value.items()}


def _optional(section: Mapping[str, Any], key: str, prefix: str) -> dict[str, Any]:
    return _named(section[key], f"{prefix}.{key}") if key in section else {}


def _bodies(value: Any, key: str) -> dict[str, dict[str, np.ndarray]]:
    bodies = {}
    for name, body in _named(value, key).items():
        if not isinstance(body, Mapping) or set(body) != {"pins"}:
            unknown = sorted(set(body) - {"pins"}) if isinstance(body, Mapping) else []
            what = f"{unknown[0]}: unknown key (known: pins)" if unknown else "pins: missing"
            raise ConfigError(f"{key}.{name}.{what}")
        pins = _named(body["pins"], f"{key}.{name}.pins")
        bodies[name] = {
            pin: np.array(_POINT.check(xz, f"{key}.{name}.pins.{pin}")) for pin, xz in pins.items()
        }
    return bodies


def _plan(
    top: dict[str, Any],
    bodies: dict[str, dict[str, np.ndarray]],
    owners: dict[str, list[str]],
    cylinders: list[Cylinder],
    slides: dict[tuple[str, str], Slide],
    raw: Any,
    prefix: str,
) -> tuple[Dyad | Place | Slide, ...]:
    """The solve plan: each dyad of ``assembly`` in order, each body placed as soon as two of its
    pins are known, each prismatic child as soon as its parent is placed."""
    dyads = _named(raw, f"{prefix}.dyads")
    for name in dyads:
        require(name in top["assembly"], f"{prefix}.dyads.{name}", "not named in assembly")
    known = set(bodies[top["ground"]])
    placed = {top["ground"]}
    steps: list[Dyad | Place | Slide] = []

    def settle() -> None:
        progress = True
        while progress:
            progress = False
            for body, pins in bodies.items():
                have = [p for p in pins if p in known]
                if body not in placed and len(have) >= 2:
                    steps.append(Place(body, have[0], have[1]))
                    placed.add(body)
                    known.update(pins)
                    progress = True
            for (parent, child), slide in slides.items():
                if parent in placed and child not in placed:
                    steps.append(slide)
                    placed.add(child)
                    known.update(bodies[child])
                    progress = True

    def radius(centre: str, pin: str, key: str) -> Radius:
        for c in cylinders:
            if {c.base, c.rod} == {centre, pin}:
                return Radius(0.0, c.index)
        for body in owners.get(pin, []):
            if centre in bodies[body]:
                return Radius(float(np.linalg.norm(bodies[body][pin] - bodies[body][centre])))
        raise ConfigError(f"{key}: loop left open: no body or cylinder joins {centre!r} and {pin!r}")

    settle()
    for pin in top["assembly"]:
        key = f"{prefix}.dyads.{pin}"
        require(pin in dyads, key, "missing (named in assembly)")
        d = validate(dyads[pin], _DYAD, key)
        require(d["orientation"] != 0, f"{key}.orientation", "must be 1 or -1")
        require(pin in owners, key, f"no body has pin {pin!r}")
        require(pin not in known, key, f"pin {pin!r} is known already at this step (solved twice)")
        for end in ("pivot", "first"):
            require(d[end] in known, f"{key}.{end}", f"pin {d[end]!r} is not known at this step")
        steps.append(
            Dyad(
                pin,
                d["pivot"],
                d["first"],
                radius(d["pivot"], pin, f"{key}.pivot"),
                radius(d["first"], pin, f"{key}.first"),
                int(d["orientation"]),
            )
        )
        known.add(pin)
        settle()
    for body in bodies:
        require(
            body in placed,
            f"{prefix}.bodies.{body}",
            "never placed: fewer than two of its pins are known after the assembly",
        )
    return tuple(steps)


def _chain(
    top: dict[str, Any],
    bodies: dict[str, dict[str, np.ndarray]],
    slides: dict[tuple[str, str], Slide],
    raw: Any,
    prefix: str,
) -> tuple[Joint, ...]:
    chain = _named(raw, f"{prefix}.chain")
    for name in chain:
        require(name in top["joints"], f"{prefix}.chain.{name}", "not named in joints")
    joints = []
    parent = top["ground"]
    for name in top["joints"]:
        key = f"{prefix}.chain.{name}"
        require(name in chain, key, "missing (named in joints)")
        j = validate(chain[name], _JOINT, key)
        require(j["parent"] == parent, f"{key}.parent", f"must be {parent!r} (the chain's previous body)")
        require(j["child"] in bodies, f"{key}.child", f"no body {j['child']!r}")
        require(j["limits"][0] < j["limits"][1], f"{key}.limits", "lower must be below upper")
        slide = slides.get((j["parent"], j["child"]))
        pivot = None
        if slide is None:
            shared = [p for p in bodies[j["parent"]] if p in bodies[j["child"]]]
            require(
                len(shared) == 1,
                key,
                f"{j['parent']!r} and {j['child']!r} must share one hinge pin, they share {len(shared)}",
            )
            pivot = shared[0]
        lower, upper = j["limits"]
        joints.append(Joint(name, j["parent"], j["child"], lower, upper, pivot, slide))
        parent = j["child"]
    return tuple(joints)
