"""The excavator's machine file: its schema and the conversion to the model's description.

The ``excavator:`` section of a parameters file (config/excavator_cet200.yaml, docs/excavator.md)
is checked key by key by the shared :func:`manipulator_kinematics.schema.validate` against
:data:`SCHEMA` (unknown, missing, mistyped and out-of-range keys are errors naming the dotted
key); :func:`describe` then checks what one key alone cannot (a stroke's ends in order, reference
values inside their limits) and folds the values into a :class:`Description`, the geometry the
kinematics (:class:`excavator_kinematics.core.kinematics.Excavator`) is built from. Whether the linkage
assembles over the whole stroke box is checked by the model, which has the closed loops.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from manipulator_kinematics.schema import Number, Numbers, Schema, Text, require, validate

SECTION = "excavator"
CYLINDERS = ("boom_cylinder", "arm_cylinder", "bucket_cylinder")
# Lengths this close outside a stroke end still count as inside, so that lengths computed from
# angles at a stroke end (round-off of a few ulp) are accepted.
STROKE_TOLERANCE = 1e-9

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


def wrap_swing(angle: Any) -> Any:
    """Swing angle(s) wrapped to (-pi, pi], the range of a continuous swing."""
    return math.pi - np.mod(math.pi - np.asarray(angle, dtype=float), 2.0 * math.pi)


def _cylinder(**pins: Any) -> dict[str, Any]:
    return {
        **pins,
        "orientation": _ORIENTATION,
        "min_length": _STROKE,
        "max_length": _STROKE,
        "reference_length": _STROKE,
        "max_speed": _CYLINDER_SPEED,
    }


#: The ``excavator:`` section of a parameters file; every key is required.
SCHEMA: Schema = {
    "name": Text(empty=False, doc="the machine's name: the robot name of its URDF"),
    # Height of the base frame's origin above the level ground the machine stands on: z = 0 of
    # the working ranges (SAE J1193 / ISO 7135 ground reference plane) is z = -base_height.
    "base_height": Number(min=-30.0, max=30.0, unit="m"),
    "boom": {"foot_pin": _POINT, "length": _LENGTH},
    "arm": {"length": _LENGTH},
    # width: of the cutting edge, whose ends the grade outputs report (design_surface).
    "bucket": {
        "length": _LENGTH,
        "width": _LENGTH,
        "outline": Numbers(
            item=_COORDINATE,
            default=None,
            doc="optional: points of the bucket's side outline [x1, y1, x2, y2, ...] (m, bucket "
            "frame), watched by the avoidance zones on both side faces (docs/zones.md)",
        ),
    },
    "boom_cylinder": _cylinder(base_pin=_POINT, rod_pin=_POINT),
    "arm_cylinder": _cylinder(base_pin=_POINT, rod_pin=_POINT),
    "bucket_cylinder": _cylinder(base_pin=_POINT),
    "side_link": {"pivot": _POINT, "length": _LENGTH},
    "h_link": {"bucket_pin": _POINT, "length": _LENGTH, "orientation": _ORIENTATION},
    # Inclination sensors (excavator_imu_state): each one's mounting rotation, the sensor frame's
    # roll, pitch, yaw (fixed x, y, z axes, rad) in the frame of the body it is bolted to (the
    # upper structure's base frame, the boom/arm/bucket link frames, or the H-link's: x from the
    # bucket cylinder's rod pin to the H-link pin, y = the boom-plane normal, left).
    "imu": {
        "cab": {"rotation_rpy": _RPY},
        "boom": {"rotation_rpy": _RPY},
        "arm": {"rotation_rpy": _RPY},
        "bucket_linkage": {"body": Text(choices=("h_link", "bucket")), "rotation_rpy": _RPY},
    },
    "swing": {
        "min_angle": _SWING_LIMIT,
        "max_angle": _SWING_LIMIT,
        "reference_angle": _SWING_ANGLE,
        "max_speed": Number(min=0.0, max=10.0, unit="rad/s", exclusive_min=True),
        "tail_radius": Number(
            min=0.0,
            max=30.0,
            unit="m",
            exclusive_min=True,
            default=None,
            doc="optional: the upper structure's tail swing radius (the counterweight's rear), "
            "watched by the avoidance zones at tail_heights",
        ),
        "tail_heights": Numbers(
            item=_COORDINATE,
            default=None,
            doc="optional: heights (m, base frame) of the watched points at the tail swing radius, "
            "e.g. the counterweight's bottom and top",
        ),
    },
}


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
    # Optional points the avoidance zones watch besides the pins: [x, y] on the bucket's side
    # outline (bucket frame), and [r, z] of the upper structure's tail (r behind the swing axis).
    bucket_outline: tuple[tuple[float, float], ...] = ()
    tail: tuple[tuple[float, float], ...] = ()


def describe(params: Mapping[str, Any], prefix: str = SECTION) -> Description:
    """The description of a section already checked by ``validate(section, SCHEMA, prefix)``;
    ConfigError naming the key when two keys disagree."""
    swing = params["swing"]
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
    for name in (*CYLINDERS, "h_link"):
        require(params[name]["orientation"] != 0, f"{prefix}.{name}.orientation", "must be 1 or -1, got 0")
    for name in CYLINDERS:
        c = params[name]
        require(
            c["min_length"] < c["max_length"],
            f"{prefix}.{name}.max_length",
            f"{c['max_length']} m must be above min_length {c['min_length']} m",
        )
        require(
            c["min_length"] <= c["reference_length"] <= c["max_length"],
            f"{prefix}.{name}.reference_length",
            f"{c['reference_length']} m outside the stroke [{c['min_length']}, {c['max_length']}] m",
        )

    def point(value: list[float]) -> tuple[float, float]:
        return value[0], value[1]

    outline = params["bucket"]["outline"] or []
    require(len(outline) % 2 == 0, f"{prefix}.bucket.outline", "expected [x, y] pairs: an even count")
    radius, heights = swing["tail_radius"], swing["tail_heights"]
    require(
        (radius is None) == (heights is None),
        f"{prefix}.swing.{'tail_heights' if heights is None else 'tail_radius'}",
        "tail_radius and tail_heights go together",
    )

    cylinders = [params[name] for name in CYLINDERS]
    return Description(
        name=params["name"],
        foot=point(params["boom"]["foot_pin"]),
        boom_length=params["boom"]["length"],
        arm_length=params["arm"]["length"],
        bucket_length=params["bucket"]["length"],
        bucket_width=params["bucket"]["width"],
        boom_cylinder_pins=(point(cylinders[0]["base_pin"]), point(cylinders[0]["rod_pin"])),
        arm_cylinder_pins=(point(cylinders[1]["base_pin"]), point(cylinders[1]["rod_pin"])),
        bucket_cylinder_base=point(cylinders[2]["base_pin"]),
        side_link_pivot=point(params["side_link"]["pivot"]),
        side_link_length=params["side_link"]["length"],
        h_link_pin=point(params["h_link"]["bucket_pin"]),
        h_link_length=params["h_link"]["length"],
        orientations=(*(c["orientation"] for c in cylinders), params["h_link"]["orientation"]),
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
        bucket_outline=tuple(zip(outline[::2], outline[1::2], strict=True)),
        tail=tuple((radius, z) for z in heights or ()),
    )


def parse(section: Any, prefix: str = SECTION) -> Description:
    """A raw ``excavator:`` section (nested dict) -> its Description, or ConfigError naming the key."""
    return describe(validate(section, SCHEMA, prefix), prefix)
