"""The excavator's machine file: the hydraulic family's description of its linkage, read onto
the excavator's topology, and the few keys only the excavator has.

A machine file (config/excavator_cet200.yaml, docs/excavator.md) holds two sections under
``/**: ros__parameters``:

* ``hydraulic_machine``: the linkage in the hydraulic family's form (docs/hydraulic_family.md,
  :mod:`manipulator_kinematics.hydraulic.description`): bodies with pins, links, cylinders, the
  swing, four dyads with their branch signs, the main chain and the tool. The excavator reads it
  when its topology is the excavator's, :data:`TOPOLOGY` (the one place where the family's names
  meet the excavator's: four dyads boom_cyl_rod, arm_cyl_rod, bkt_cyl_rod, hlink_pin_on_bucket,
  each body's frame from its root pin along its next pin); any other topology is refused in one
  line naming the key and pointing at the hydraulic_* nodes / HydraulicModel. The orientations
  (assembly branches) are the dyads' signs.
* ``excavator``: what the family form does not carry, :data:`SCHEMA` (``base_height`` and the
  IMU mounts).

A file of the old form (one ``excavator`` section with the geometry under ``boom``, ``arm``,
``boom_cylinder``, ... ``h_link``, :data:`OLD_SCHEMA`) is converted on load
(:func:`manipulator_kinematics.hydraulic.convert.from_excavator_file`) with one logged line saying
how to write the converted file (``mk_machine_check OLD.yaml --convert NEW.yaml``).

Every value is checked by the shared :func:`manipulator_kinematics.schema.validate` (unknown,
missing, mistyped and out-of-range keys are errors naming the dotted key); :func:`describe` then
checks what one key alone cannot (a stroke's ends in order, reference values inside their limits,
the bodies' frames) and folds the values into a :class:`Description`, the geometry the kinematics
(:class:`excavator_kinematics.core.kinematics.Excavator`) is built from. Whether the linkage
assembles over the whole stroke box, on the right branches and inside the chain's joint limits is
checked by the model, which has the closed loops. Plain data and numpy: no rclpy.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from manipulator_kinematics.hydraulic.convert import from_excavator_file
from manipulator_kinematics.hydraulic.description import SECTION as FAMILY
from manipulator_kinematics.param_files import ConfigError
from manipulator_kinematics.schema import (
    Field,
    Flag,
    Names,
    Number,
    Numbers,
    Schema,
    Text,
    require,
    validate,
)

#: The excavator-only section of a machine file.
SECTION = "excavator"
CYLINDERS = ("boom_cylinder", "arm_cylinder", "bucket_cylinder")
# Lengths this close outside a stroke end still count as inside, so that lengths computed from
# angles at a stroke end (round-off of a few ulp) are accepted.
STROKE_TOLERANCE = 1e-9

_LOG = logging.getLogger(__name__)

# Sanity bounds, not limits of one machine: every excavator from a mini to a 100 t mining
# machine fits inside them, a typo of a few orders of magnitude does not.
_LENGTH = Number(min=0.0, max=30.0, unit="m", exclusive_min=True)
_STROKE = Number(min=0.0, max=20.0, unit="m", exclusive_min=True)
_COORDINATE = Number(min=-30.0, max=30.0, unit="m")
_POINT = Numbers(2, item=_COORDINATE)
# The sign of cross(first - pivot, second - pivot) of a closing triangle: -1 or 1 (0 is refused
# by describe()).
_ORIENTATION = Number(min=-1.0, max=1.0, integer=True)
_RPY = Numbers(3, item=Number(min=-2.0 * math.pi, max=2.0 * math.pi, unit="rad"))
_CYLINDER_SPEED = Number(min=0.0, max=5.0, unit="m/s", exclusive_min=True)
# A swing range of up to a full turn either way of the reference heading, or open at both ends
# (-.inf, .inf): a continuous swing, its angles wrapped to (-pi, pi].
_SWING_ANGLE = Number(min=-2.0 * math.pi, max=2.0 * math.pi, unit="rad")
_SWING_LIMIT = Number(
    min=-2.0 * math.pi,
    max=2.0 * math.pi,
    unit="rad",
    open=True,
    doc="swing stop; -.inf (min) and .inf (max) together: continuous swing",
)
_SWING_SPEED = Number(min=0.0, max=10.0, unit="rad/s", exclusive_min=True)
_OUTLINE = Numbers(
    item=_COORDINATE,
    default=None,
    doc="optional: points of the bucket's side outline [x1, z1, x2, z2, ...] (m, bucket frame), "
    "watched by the avoidance zones on both side faces (docs/zones.md)",
)
_TAIL_RADIUS = Number(
    min=0.0,
    max=30.0,
    unit="m",
    exclusive_min=True,
    default=None,
    doc="optional: the upper structure's tail swing radius (the counterweight's rear), watched by "
    "the avoidance zones at tail_heights",
)
_TAIL_HEIGHTS = Numbers(
    item=_COORDINATE,
    default=None,
    doc="optional: heights (m, base frame) of the watched points at the tail swing radius, e.g. the "
    "counterweight's bottom and top",
)
_IMU: Schema = {
    "cab": {"rotation_rpy": _RPY},
    "boom": {"rotation_rpy": _RPY},
    "arm": {"rotation_rpy": _RPY},
    "bucket_linkage": {"body": Text(choices=("h_link", "bucket")), "rotation_rpy": _RPY},
}

#: The ``excavator`` section of a machine file: what the family form does not carry. Every key
#: is required.
SCHEMA: Schema = {
    # Height of the base frame's origin above the level ground the machine stands on: z = 0 of
    # the working ranges (SAE J1193 / ISO 7135 ground reference plane) is z = -base_height.
    "base_height": Number(min=-30.0, max=30.0, unit="m"),
    # Inclination sensors (excavator_imu_state): each one's mounting rotation, the sensor frame's
    # roll, pitch, yaw (fixed x, y, z axes, rad) in the frame of the body it is bolted to (the
    # upper structure's base frame, the boom/arm/bucket link frames, or the H-link's: x from the
    # bucket cylinder's rod pin to the H-link pin, y = the boom-plane normal, left).
    "imu": _IMU,
}

#: The excavator's topology in the family's names (docs/hydraulic_family.md), plain data: the
#: bodies with their pins (root pin first, the pin its frame's x axis runs to second), the two
#: links, the cylinders' (base, rod) pins in the order of D, the dyads' (pivot, first) in solve
#: order (the order of Description.orientations), the main chain's (parent, child) and the tool.
#: The inverse of :func:`manipulator_kinematics.hydraulic.convert.from_excavator_section`.
TOPOLOGY: dict[str, Any] = {
    "ground": "upper_structure",
    "bodies": {
        "upper_structure": ("boom_foot", "boom_cyl_base"),
        "boom": ("boom_foot", "arm_pin", "boom_cyl_rod", "arm_cyl_base"),
        "arm": ("arm_pin", "bucket_pin", "arm_cyl_rod", "bkt_cyl_base", "ilink_pin_on_arm"),
        "bucket": ("bucket_pin", "tip", "hlink_pin_on_bucket"),
    },
    "links": {
        "side_link": ("ilink_pin_on_arm", "bkt_cyl_rod"),
        "h_link": ("bkt_cyl_rod", "hlink_pin_on_bucket"),
    },
    "swing": "swing_joint",
    "cylinders": {
        "boom_cylinder": ("boom_cyl_base", "boom_cyl_rod"),
        "arm_cylinder": ("arm_cyl_base", "arm_cyl_rod"),
        "bucket_cylinder": ("bkt_cyl_base", "bkt_cyl_rod"),
    },
    "dyads": {
        "boom_cyl_rod": ("boom_foot", "boom_cyl_base"),
        "arm_cyl_rod": ("arm_pin", "arm_cyl_base"),
        "bkt_cyl_rod": ("ilink_pin_on_arm", "bkt_cyl_base"),
        "hlink_pin_on_bucket": ("bucket_pin", "bkt_cyl_rod"),
    },
    "chain": {"theta2": ("upper_structure", "boom"), "theta3": ("boom", "arm"), "theta4": ("arm", "bucket")},
    "tool": ("bucket", "tip"),
}
#: The dyads in the order of Description.orientations (boom, arm, bucket cylinder, H-link).
DYADS = tuple(TOPOLOGY["dyads"])
_HINT = (
    "the excavator nodes and Excavator read the excavator's topology only (docs/excavator.md); "
    "run this machine with the hydraulic_* nodes or HydraulicModel"
)


def _one(name: str, doc: str = "") -> Text:
    return Text(choices=(name,), doc=doc)


def _names(names: tuple[str, ...] | list[str]) -> Names:
    return Names(count=len(names), doc=f"exactly: {', '.join(names)}")


def _geometry_schema() -> Schema:
    """The ``hydraulic_machine`` section of the excavator's topology: :data:`TOPOLOGY`'s names,
    the excavator's sanity bounds for the numbers."""
    t = TOPOLOGY
    cylinder: Schema = {
        "min_length": _STROKE,
        "max_length": _STROKE,
        "reference_length": _STROKE,
        "max_speed": _CYLINDER_SPEED,
        "zero_offset": Number(-1.0, 1.0, "m", default=0.0, doc="true length = sensor reading + zero_offset"),
    }
    return {
        "name": Text(empty=False, doc="the machine's name: the robot name of its URDF"),
        "ground": _one(t["ground"]),
        "bodies": {body: {"pins": dict.fromkeys(pins, _POINT)} for body, pins in t["bodies"].items()},
        "links": {
            name: {"from": _one(a), "to": _one(b), "length": _LENGTH} for name, (a, b) in t["links"].items()
        },
        "swing": {
            "actuator": _one(t["swing"]),
            "min_angle": _SWING_LIMIT,
            "max_angle": _SWING_LIMIT,
            "reference_angle": _SWING_ANGLE,
            "max_speed": _SWING_SPEED,
            "zero_offset": Number(
                -math.pi, math.pi, "rad", default=0.0, doc="true angle = encoder reading + zero_offset"
            ),
            "tail_radius": _TAIL_RADIUS,
            "tail_heights": _TAIL_HEIGHTS,
        },
        "actuators": _names(list(t["cylinders"])),
        "cylinders": {
            name: {"base_pin": _one(base), "rod_pin": _one(rod), **cylinder}
            for name, (base, rod) in t["cylinders"].items()
        },
        "assembly": _names(list(t["dyads"])),
        "dyads": {
            pin: {"pivot": _one(pivot), "first": _one(first), "orientation": _ORIENTATION}
            for pin, (pivot, first) in t["dyads"].items()
        },
        "joints": _names(list(t["chain"])),
        "chain": {
            joint: {
                "parent": _one(parent),
                "child": _one(child),
                "limits": Numbers(2, Number(-2.0 * math.pi, 2.0 * math.pi, "rad")),
            }
            for joint, (parent, child) in t["chain"].items()
        },
        "tool": {
            "body": _one(t["tool"][0]),
            "pin": _one(t["tool"][1]),
            "width": _LENGTH,
            "angle": Flag(doc="true: Q has the bucket angle alpha (the excavator's always has)"),
            "velocity_rows": Names(doc="rows of Q the velocity IK solves: x, y, z, alpha"),
            "outline": _OUTLINE,
        },
    }


#: The ``hydraulic_machine`` section as the excavator reads it.
GEOMETRY: Schema = _geometry_schema()


def _cylinder(**pins: Any) -> dict[str, Any]:
    return {
        **pins,
        "orientation": _ORIENTATION,
        "min_length": _STROKE,
        "max_length": _STROKE,
        "reference_length": _STROKE,
        "max_speed": _CYLINDER_SPEED,
    }


#: The ``excavator`` section of the old form (before the hydraulic family), read to convert it.
OLD_SCHEMA: Schema = {
    "name": Text(empty=False, doc="the machine's name: the robot name of its URDF"),
    "base_height": SCHEMA["base_height"],
    "boom": {"foot_pin": _POINT, "length": _LENGTH},
    "arm": {"length": _LENGTH},
    "bucket": {"length": _LENGTH, "width": _LENGTH, "outline": _OUTLINE},
    "boom_cylinder": _cylinder(base_pin=_POINT, rod_pin=_POINT),
    "arm_cylinder": _cylinder(base_pin=_POINT, rod_pin=_POINT),
    "bucket_cylinder": _cylinder(base_pin=_POINT),
    "side_link": {"pivot": _POINT, "length": _LENGTH},
    "h_link": {"bucket_pin": _POINT, "length": _LENGTH, "orientation": _ORIENTATION},
    "imu": _IMU,
    "swing": {
        "min_angle": _SWING_LIMIT,
        "max_angle": _SWING_LIMIT,
        "reference_angle": _SWING_ANGLE,
        "max_speed": _SWING_SPEED,
        "tail_radius": _TAIL_RADIUS,
        "tail_heights": _TAIL_HEIGHTS,
    },
}
#: Keys of the old form's ``excavator`` section that the new one does not have.
_OLD_KEYS = frozenset(OLD_SCHEMA) - frozenset(SCHEMA)


def wrap_swing(angle: Any) -> Any:
    """Swing angle(s) wrapped to (-pi, pi], the range of a continuous swing."""
    return math.pi - np.mod(math.pi - np.asarray(angle, dtype=float), 2.0 * math.pi)


@dataclass(frozen=True)
class Limits:
    """Stroke ends, swing range and speed limits (SI units), all from the machine file."""

    stroke_min: np.ndarray  # (3,) boom, arm, bucket cylinder minimum length
    stroke_max: np.ndarray  # (3,)
    swing_min: float
    swing_max: float
    max_cylinder_speed: np.ndarray  # (3,) m/s
    max_swing_speed: float  # rad/s
    reference: np.ndarray  # (4,) D of the reference state [theta1, d2, d3, d4]

    @property
    def continuous_swing(self) -> bool:
        """Open swing limits (-inf, inf): the swing turns without end, angles wrapped to (-pi, pi]."""
        return math.isinf(self.swing_max)

    @property
    def d_min(self) -> np.ndarray:
        """Lower limits of D = [theta1, d2, d3, d4]."""
        return np.concatenate(([self.swing_min], self.stroke_min))

    @property
    def d_max(self) -> np.ndarray:
        return np.concatenate(([self.swing_max], self.stroke_max))

    @property
    def max_rates(self) -> np.ndarray:
        """Speed limits of D, [rad/s, m/s, m/s, m/s]."""
        return np.concatenate(([self.max_swing_speed], self.max_cylinder_speed))


@dataclass(frozen=True)
class Description:
    """One machine's geometry and limits (SI units), as the kinematics reads them.

    Points are [r, z] in the frame of the body they sit on (docs/excavator.md): ``foot`` and the
    boom cylinder's base pin in the base frame, the boom cylinder's rod pin and the arm cylinder's
    base pin in the boom frame, the arm cylinder's rod pin, the bucket cylinder's base pin and the
    side-link pivot in the arm frame, the H-link pin in the bucket frame. Orientations are -1 or 1.
    """

    name: str
    foot: tuple[float, float]  # boom foot pin [l1, l0]
    boom_length: float  # l2
    arm_length: float  # l3
    bucket_length: float  # l4
    bucket_width: float  # cutting edge, the tip in its middle
    boom_cylinder_pins: tuple[tuple[float, float], tuple[float, float]]  # base, rod
    arm_cylinder_pins: tuple[tuple[float, float], tuple[float, float]]  # base, rod
    bucket_cylinder_base: tuple[float, float]
    side_link_pivot: tuple[float, float]
    side_link_length: float
    h_link_pin: tuple[float, float]
    h_link_length: float
    orientations: tuple[int, int, int, int]  # boom, arm, bucket cylinder, H-link
    imu: dict[str, Any]  # the machine file's imu section (mounting rotations), as validated
    limits: Limits
    # The main chain's joint limits (theta2, theta3, theta4), rad: the joints' ranges over the
    # stroke box must lie inside them (the model checks, as the family's does).
    joint_limits: tuple[tuple[float, float], ...] = ((-math.pi, math.pi),) * 3
    # Optional points the avoidance zones watch besides the pins: [x, y] on the bucket's side
    # outline (bucket frame), and [r, z] of the upper structure's tail (r behind the swing axis).
    bucket_outline: tuple[tuple[float, float], ...] = ()
    tail: tuple[tuple[float, float], ...] = ()
    # The sensors' zero offsets in the order of D (swing rad, boom/arm/bucket cylinder m): true =
    # reading + offset (issue 33; a measure-up writes them). Strokes and swing limits are true.
    zero_offset: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    # The machine file's hydraulic_machine section as validated: the same machine for the
    # family's model (HydraulicModel of parse(family)), which gives the monitored points
    # (excavator_kinematics.core.monitored). Not part of the geometry's identity.
    family: Mapping[str, Any] = field(default_factory=dict, compare=False, repr=False)


def upgrade(params: Mapping[str, Any], source: str = "") -> dict[str, Any]:
    """A file's top-level sections in the current form: an ``excavator`` section of the old form
    (geometry keys, no ``hydraulic_machine`` section) converted, with one logged line saying how
    to write the converted file; any other file as it is."""
    old = params.get(SECTION)
    if FAMILY in params or not isinstance(old, Mapping) or not _OLD_KEYS & set(old):
        return dict(params)
    converted = from_excavator_file(validate(old, OLD_SCHEMA, SECTION))
    _LOG.warning(
        "%s: an excavator file of the old form (excavator.boom, ...), converted on load; write it "
        "once in the current form with: mk_machine_check OLD.yaml --convert NEW.yaml "
        "(docs/excavator.md)",
        source or "parameters",
    )
    return {**params, **converted}


def read(params: Mapping[str, Any], source: str = "") -> dict[str, Any]:
    """The validated sections of a machine file's parameters (top-level keys ``hydraulic_machine``
    and ``excavator``; the old form converted, :func:`upgrade`): the ``excavator`` section's values
    with the geometry under the key ``hydraulic_machine``, what :func:`describe` takes."""
    params = upgrade(params, source)
    for key in (FAMILY, SECTION):
        require(
            key in params,
            key,
            f"missing: an excavator's machine file has the sections {FAMILY} and {SECTION}",
        )
    return {**validate(params[SECTION], SCHEMA, SECTION), FAMILY: geometry(params[FAMILY])}


def geometry(section: Any) -> dict[str, Any]:
    """A ``hydraulic_machine`` section validated as the excavator's (:data:`GEOMETRY`); one line
    naming the key, and for a topology that is not the excavator's where to run it instead."""
    try:
        return validate(section, GEOMETRY, FAMILY)
    except ConfigError as error:
        text = str(error)
        key = text.split(":", 1)[0].split(" ", 1)[0].split("[", 1)[0]
        # A wrong value or a misspelt key is the user's typo, not another machine; a missing pin
        # is another linkage.
        missing_pin = ".pins." in key and text.endswith("missing")
        if "did you mean" in text or (isinstance(_field(key), (Number, Numbers)) and not missing_pin):
            raise
        raise ConfigError(f"{error}: {_HINT}") from None


def _field(key: str) -> Field | Schema | None:
    spec: Any = GEOMETRY
    for part in key.split(".")[1:]:
        if not isinstance(spec, Mapping) or part not in spec:
            return None
        spec = spec[part]
    return spec


def describe(params: Mapping[str, Any]) -> Description:
    """The description of a machine file's sections as :func:`read` returns them; ConfigError
    naming the key when two keys disagree."""
    g = params[FAMILY]
    prefix = FAMILY
    swing = g["swing"]
    lower, upper = math.isinf(swing["min_angle"]), math.isinf(swing["max_angle"])
    if lower or upper:
        require(
            lower and upper and swing["min_angle"] < 0.0 < swing["max_angle"],
            f"{prefix}.swing.{'max_angle' if lower else 'min_angle'}",
            "a continuous swing has both limits open (min_angle: -.inf, max_angle: .inf), got "
            f"[{swing['min_angle']}, {swing['max_angle']}] rad",
        )
        require(
            -math.pi < swing["reference_angle"] <= math.pi,
            f"{prefix}.swing.reference_angle",
            f"{swing['reference_angle']} rad: a continuous swing's angles are in (-pi, pi]",
        )
    require(
        swing["min_angle"] < swing["max_angle"],
        f"{prefix}.swing.max_angle",
        f"{swing['max_angle']} must be above min_angle {swing['min_angle']}",
    )
    require(
        swing["min_angle"] <= swing["reference_angle"] <= swing["max_angle"],
        f"{prefix}.swing.reference_angle",
        f"{swing['reference_angle']} rad outside [min_angle, max_angle] = "
        f"[{swing['min_angle']}, {swing['max_angle']}] rad",
    )
    for pin in DYADS:
        require(
            g["dyads"][pin]["orientation"] != 0, f"{prefix}.dyads.{pin}.orientation", "must be 1 or -1, got 0"
        )
    cylinders = [g["cylinders"][name] for name in CYLINDERS]
    for name, c in zip(CYLINDERS, cylinders, strict=True):
        key = f"{prefix}.cylinders.{name}"
        require(
            c["min_length"] < c["max_length"],
            f"{key}.max_length",
            f"{c['max_length']} m must be above min_length {c['min_length']} m",
        )
        require(
            c["min_length"] <= c["reference_length"] <= c["max_length"],
            f"{key}.reference_length",
            f"{c['reference_length']} m outside the stroke [{c['min_length']}, {c['max_length']}] m",
        )
    chain = g["chain"]
    for joint in TOPOLOGY["chain"]:
        lo, hi = chain[joint]["limits"]
        require(lo < hi, f"{prefix}.chain.{joint}.limits", "lower must be below upper")
    tool = g["tool"]
    require(tool["angle"], f"{prefix}.tool.angle", "an excavator's Q has the bucket angle: true")
    require(
        tool["velocity_rows"] == ["x", "y", "z", "alpha"],
        f"{prefix}.tool.velocity_rows",
        f"the excavator's velocity IK solves [x, y, z, alpha], got {tool['velocity_rows']}",
    )

    bodies = g["bodies"]

    def local(body: str) -> dict[str, tuple[float, float]]:
        """The body's pins in its frame, which must run from its root pin along its next pin (the
        excavator's link frames): root [0, 0], next [length, 0]."""
        pins = bodies[body]["pins"]
        root, axis = TOPOLOGY["bodies"][body][:2]
        require(pins[root] == [0.0, 0.0], f"{prefix}.bodies.{body}.pins.{root}", f"{_FRAME}: expected [0, 0]")
        require(
            pins[axis][1] == 0.0 and pins[axis][0] > 0.0,
            f"{prefix}.bodies.{body}.pins.{axis}",
            f"{_FRAME}: expected [length, 0] with length > 0",
        )
        return {pin: (xz[0], xz[1]) for pin, xz in pins.items()}

    boom, arm, bucket = local("boom"), local("arm"), local("bucket")
    base = bodies["upper_structure"]["pins"]
    links = g["links"]
    outline = tool["outline"] or []
    require(len(outline) % 2 == 0, f"{prefix}.tool.outline", "expected [x, z] pairs: an even count")
    radius, heights = swing["tail_radius"], swing["tail_heights"]
    require(
        (radius is None) == (heights is None),
        f"{prefix}.swing.{'tail_heights' if heights is None else 'tail_radius'}",
        "tail_radius and tail_heights go together",
    )
    return Description(
        name=g["name"],
        foot=(base["boom_foot"][0], base["boom_foot"][1]),
        boom_length=boom["arm_pin"][0],
        arm_length=arm["bucket_pin"][0],
        bucket_length=bucket["tip"][0],
        bucket_width=tool["width"],
        boom_cylinder_pins=((base["boom_cyl_base"][0], base["boom_cyl_base"][1]), boom["boom_cyl_rod"]),
        arm_cylinder_pins=(boom["arm_cyl_base"], arm["arm_cyl_rod"]),
        bucket_cylinder_base=arm["bkt_cyl_base"],
        side_link_pivot=arm["ilink_pin_on_arm"],
        side_link_length=links["side_link"]["length"],
        h_link_pin=bucket["hlink_pin_on_bucket"],
        h_link_length=links["h_link"]["length"],
        orientations=tuple(g["dyads"][pin]["orientation"] for pin in DYADS),
        imu=params["imu"],
        limits=Limits(
            stroke_min=np.array([c["min_length"] for c in cylinders]),
            stroke_max=np.array([c["max_length"] for c in cylinders]),
            swing_min=swing["min_angle"],
            swing_max=swing["max_angle"],
            max_cylinder_speed=np.array([c["max_speed"] for c in cylinders]),
            max_swing_speed=swing["max_speed"],
            reference=np.array([swing["reference_angle"], *(c["reference_length"] for c in cylinders)]),
        ),
        joint_limits=tuple((chain[j]["limits"][0], chain[j]["limits"][1]) for j in TOPOLOGY["chain"]),
        bucket_outline=tuple(zip(outline[::2], outline[1::2], strict=True)),
        tail=tuple((radius, z) for z in heights or ()),
        zero_offset=(swing["zero_offset"], *(c["zero_offset"] for c in cylinders)),
        family=g,
    )


_FRAME = "the excavator's link frames run from the body's root pin along its next pin"


def parse(params: Mapping[str, Any], source: str = "") -> Description:
    """A machine file's top-level sections (nested dicts) -> its Description, or ConfigError naming
    the key."""
    return describe(read(params, source))
