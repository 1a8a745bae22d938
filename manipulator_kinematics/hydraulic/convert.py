"""An excavator file of the old form (one ``excavator:`` section with the geometry under ``boom``,
``arm``, ``boom_cylinder``, ... ``h_link``) in the current form: a ``hydraulic_machine`` section of
the family form (docs/hydraulic_family.md) and an ``excavator`` section with what the family form
does not carry (``base_height``, ``imu``), as config/excavator_cet200.yaml has them.

The old form names one topology (boom, arm and bucket cylinders, a side link and an H-link); its
keys map one to one onto bodies, links, cylinders and four dyads (the bucket outline and the
swing tail onto ``tool.outline`` and ``swing.tail_*``). Joint limits are not in the old form: the
converted chain allows [-pi, pi] for each joint. Plain data in, plain data out: no machine package
imported (``mk_machine_check OLD.yaml --convert NEW.yaml`` writes a converted file).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

__all__ = ["EXTRAS", "from_excavator_file", "from_excavator_section"]

#: Keys of an old ``excavator`` section that stay in the ``excavator`` section.
EXTRAS = ("base_height", "imu")

_ALL = [-math.pi, math.pi]


def from_excavator_section(old: Mapping[str, Any]) -> dict[str, Any]:
    """The family section of a validated ``excavator`` section (its schema's keys)."""
    boom, arm, bucket = old["boom"], old["arm"], old["bucket"]
    boom_cyl, arm_cyl, bucket_cyl = old["boom_cylinder"], old["arm_cylinder"], old["bucket_cylinder"]
    swing = old["swing"]

    def cylinder(section: Mapping[str, Any], base: str, rod: str) -> dict[str, Any]:
        return {
            "base_pin": base,
            "rod_pin": rod,
            "min_length": section["min_length"],
            "max_length": section["max_length"],
            "reference_length": section["reference_length"],
            "max_speed": section["max_speed"],
        }

    return {
        "name": old["name"],
        "ground": "upper_structure",
        "bodies": {
            "upper_structure": {
                "pins": {"boom_foot": list(boom["foot_pin"]), "boom_cyl_base": list(boom_cyl["base_pin"])}
            },
            "boom": {
                "pins": {
                    "boom_foot": [0.0, 0.0],
                    "arm_pin": [boom["length"], 0.0],
                    "boom_cyl_rod": list(boom_cyl["rod_pin"]),
                    "arm_cyl_base": list(arm_cyl["base_pin"]),
                }
            },
            "arm": {
                "pins": {
                    "arm_pin": [0.0, 0.0],
                    "bucket_pin": [arm["length"], 0.0],
                    "arm_cyl_rod": list(arm_cyl["rod_pin"]),
                    "bkt_cyl_base": list(bucket_cyl["base_pin"]),
                    "ilink_pin_on_arm": list(old["side_link"]["pivot"]),
                }
            },
            "bucket": {
                "pins": {
                    "bucket_pin": [0.0, 0.0],
                    "tip": [bucket["length"], 0.0],
                    "hlink_pin_on_bucket": list(old["h_link"]["bucket_pin"]),
                }
            },
        },
        "links": {
            "side_link": {
                "from": "ilink_pin_on_arm",
                "to": "bkt_cyl_rod",
                "length": old["side_link"]["length"],
            },
            "h_link": {"from": "bkt_cyl_rod", "to": "hlink_pin_on_bucket", "length": old["h_link"]["length"]},
        },
        "swing": {
            "actuator": "swing_joint",
            "min_angle": swing["min_angle"],
            "max_angle": swing["max_angle"],
            "reference_angle": swing["reference_angle"],
            "max_speed": swing["max_speed"],
            **{k: swing[k] for k in ("tail_radius", "tail_heights") if swing.get(k) is not None},
        },
        "actuators": ["boom_cylinder", "arm_cylinder", "bucket_cylinder"],
        "cylinders": {
            "boom_cylinder": cylinder(boom_cyl, "boom_cyl_base", "boom_cyl_rod"),
            "arm_cylinder": cylinder(arm_cyl, "arm_cyl_base", "arm_cyl_rod"),
            "bucket_cylinder": cylinder(bucket_cyl, "bkt_cyl_base", "bkt_cyl_rod"),
        },
        "assembly": ["boom_cyl_rod", "arm_cyl_rod", "bkt_cyl_rod", "hlink_pin_on_bucket"],
        "dyads": {
            "boom_cyl_rod": {
                "pivot": "boom_foot",
                "first": "boom_cyl_base",
                "orientation": boom_cyl["orientation"],
            },
            "arm_cyl_rod": {
                "pivot": "arm_pin",
                "first": "arm_cyl_base",
                "orientation": arm_cyl["orientation"],
            },
            "bkt_cyl_rod": {
                "pivot": "ilink_pin_on_arm",
                "first": "bkt_cyl_base",
                "orientation": bucket_cyl["orientation"],
            },
            "hlink_pin_on_bucket": {
                "pivot": "bucket_pin",
                "first": "bkt_cyl_rod",
                "orientation": old["h_link"]["orientation"],
            },
        },
        "joints": ["theta2", "theta3", "theta4"],
        "chain": {
            "theta2": {"parent": "upper_structure", "child": "boom", "limits": _ALL},
            "theta3": {"parent": "boom", "child": "arm", "limits": _ALL},
            "theta4": {"parent": "arm", "child": "bucket", "limits": _ALL},
        },
        "tool": {
            "body": "bucket",
            "pin": "tip",
            "width": bucket["width"],
            "angle": True,
            "velocity_rows": ["x", "y", "z", "alpha"],
            **({"outline": list(bucket["outline"])} if bucket.get("outline") is not None else {}),
        },
    }


def from_excavator_file(old: Mapping[str, Any]) -> dict[str, Any]:
    """The sections of the current form (``hydraulic_machine`` and ``excavator``) of a validated
    old ``excavator`` section."""
    return {"hydraulic_machine": from_excavator_section(old), "excavator": {k: old[k] for k in EXTRAS}}
