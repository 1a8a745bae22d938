"""The excavator drawn as solids (the ``scene`` hook of its Machine record), numpy only.

Everything is placed by :meth:`Excavator.pins` (eqs. 1-3: the closed loops solved for D), so
the drawing is the machine of the config file: the upper structure, the boom, arm and bucket
as outlines through the pins each body carries, each hydraulic cylinder as a barrel fixed at its
base pin and a thinner rod fixed at its rod pin (the rod slides out of the barrel as the
cylinder lengthens), and the bucket linkage: the side link (arm pivot -> bucket cylinder rod
pin) and the connecting (H-) link (rod pin -> bucket). Frames for /tf: ``upper_structure``,
``boom``, ``arm``, ``bucket`` (x from each body's pin to the next, in the boom plane, y to the
machine's left) and ``bucket_tip``; ``joints``: every moving joint of the excavator's URDF
(:func:`excavator_kinematics.core.urdf_joints.joint_positions`: open chain, cylinder barrels and rods,
bucket linkage).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.machine_file import CYLINDERS
from excavator_kinematics.core.urdf_joints import URDF_JOINTS, joint_positions
from manipulator_kinematics.scene import Scene, Segment, Sphere

#: Body radius as a fraction of the reach l2 + l3 + l4 (boom, arm and bucket lengths).
BODY_SHARE = 0.014
#: Pin radius as a fraction of the body radius (a pin sits inside the body it carries).
PIN_SHARE = 0.75
#: Barrel and rod radius as fractions of the body radius.
BARREL_SHARE, ROD_SHARE = 0.75, 0.4
#: The barrel spans this share of the cylinder's minimum length from its base pin; the rod spans
#: the minimum length from its rod pin. Rod and barrel then overlap at every length of a cylinder
#: whose maximum length is below 1.9 times its minimum (every real cylinder: the barrel must hold
#: the stroke), and at the minimum length the rod shows only its eye.
BARREL_LENGTH = 0.9

#: Outlines through the pins of each rigid body (consecutive pins are joined).
BODIES = {
    "boom": ("boom_foot", "boom_cylinder_rod", "arm_cylinder_base", "arm_pin"),
    "arm": ("arm_cylinder_rod", "arm_pin", "side_link_pivot", "bucket_pin"),
    "arm_top": ("arm_cylinder_rod", "bucket_cylinder_base", "side_link_pivot"),
    "bucket": ("bucket_pin", "h_link_pin_on_bucket", "bucket_tip", "bucket_pin"),
}
LINKAGE = {
    "side_link": ("side_link_pivot", "bucket_cylinder_rod"),
    "h_link": ("bucket_cylinder_rod", "h_link_pin"),
}
PINS = (
    "boom_foot",
    "boom_cylinder_base",
    "boom_cylinder_rod",
    "arm_pin",
    "arm_cylinder_base",
    "arm_cylinder_rod",
    "bucket_pin",
    "bucket_cylinder_base",
    "side_link_pivot",
    "bucket_cylinder_rod",
    "h_link_pin",
)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frame(origin: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Pose (..., 4, 4) with axes x, y (unit, orthogonal) and z = x cross y at ``origin``."""
    pose = np.zeros(origin.shape[:-1] + (4, 4))
    pose[..., :3, 0], pose[..., :3, 1], pose[..., :3, 2] = x, y, np.cross(x, y)
    pose[..., :3, 3], pose[..., 3, 3] = origin, 1.0
    return pose


def excavator_scene(model: Excavator, readings: np.ndarray) -> Scene:
    """Scene of the states of sensor readings (..., 4) = [theta1, d_boom, d_arm, d_bucket] (rad,
    m; as on joint_states / cylinder_lengths, D = reading + zero_offset); StrokeError for a state
    the machine cannot take (as :meth:`Excavator.pins`)."""
    D = np.asarray(readings, dtype=float) + model.zero_offset
    pins = model.pins(D)
    theta1 = np.asarray(D, dtype=float)[..., 0]
    body = BODY_SHARE * (model.l2 + model.l3 + model.l4)
    joint = PIN_SHARE * body
    foot = pins["boom_foot"]
    axis_top = np.zeros_like(foot)
    axis_top[..., 2] = foot[..., 2]

    segments = [
        Segment("swing_axis", "base", np.zeros_like(foot), axis_top, body),
        Segment("upper_structure_boom", "base", axis_top, foot, body),
        Segment("upper_structure_cylinder", "base", axis_top, pins["boom_cylinder_base"], body),
    ]
    for name, chain in BODIES.items():
        segments += [
            Segment(f"{name}_{i}", "link", pins[a], pins[b], body) for i, (a, b) in enumerate(pairwise(chain))
        ]
    segments += [Segment(name, "linkage", pins[a], pins[b], 0.6 * body) for name, (a, b) in LINKAGE.items()]
    for cylinder, shortest in zip(CYLINDERS, model.limits.stroke_min.tolist()):
        base, rod = pins[f"{cylinder}_base"], pins[f"{cylinder}_rod"]
        axis = _unit(rod - base)
        segments.append(
            Segment(
                f"{cylinder}_barrel",
                "barrel",
                base,
                base + BARREL_LENGTH * shortest * axis,
                BARREL_SHARE * body,
            )
        )
        segments.append(Segment(f"{cylinder}_rod", "rod", rod - shortest * axis, rod, ROD_SHARE * body))
    spheres = [Sphere(name, "joint", pins[name], joint) for name in PINS]
    spheres.append(Sphere("bucket_tip", "tool", pins["bucket_tip"], joint))

    c, s = np.cos(theta1)[..., None], np.sin(theta1)[..., None]
    zero = np.zeros_like(c)
    forward, left = np.concatenate((c, s, zero), axis=-1), np.concatenate((-s, c, zero), axis=-1)
    bucket_axis = _unit(pins["bucket_tip"] - pins["bucket_pin"])
    frames = {
        "upper_structure": _frame(np.zeros_like(foot), forward, left),
        "boom": _frame(foot, _unit(pins["arm_pin"] - foot), left),
        "arm": _frame(pins["arm_pin"], _unit(pins["bucket_pin"] - pins["arm_pin"]), left),
        "bucket": _frame(pins["bucket_pin"], bucket_axis, left),
        "bucket_tip": _frame(pins["bucket_tip"], bucket_axis, left),
    }
    joints = joint_positions(model, D)
    return Scene(
        tuple(segments),
        tuple(spheres),
        frames,
        "bucket_tip",
        dict(zip(URDF_JOINTS, np.moveaxis(joints, -1, 0), strict=True)),
    )
