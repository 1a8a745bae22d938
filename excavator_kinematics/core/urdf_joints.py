"""The excavator's URDF, with its closed loops cut, and the value of every URDF joint for a state D.

numpy only, no rclpy. A URDF is a tree: the excavator's three cylinder loops and the bucket
linkage are closed chains, and a mimic joint (a linear function of one joint) cannot give a
cylinder's angle against its stroke. So the loops are cut the way public excavator descriptions
that show their cylinders do it: every body is a link on its own joint, and the joints that are
not the open chain are *passive*, their values computed here from the closed-form model
(:meth:`Excavator.pins`, eqs. 1-2 of paper 000) and published with the open-chain joints.

The tree (every moving joint turns about -y of its parent, i.e. counter-clockwise in the side view
of docs/excavator.md, so a joint's value is the paper's angle; points [r, z] of the config are
(r, 0, z) in the body's frame):

* ``swing_joint`` (theta1, about z) -> ``upper_structure``; ``boom_joint`` (theta2) -> ``boom``;
  ``arm_joint`` (theta3) -> ``arm``; ``bucket_joint`` (theta4) -> ``bucket``: the open chain;
* per cylinder ``<cylinder>_barrel_joint`` at the base pin (the barrel's angle from the x axis of
  the body the base pin sits on) -> ``<cylinder>_barrel``, then the prismatic joint ``<cylinder>``
  along the barrel (value = the cylinder length, pin to pin, so the machine's ``cylinder_lengths``
  message drives it as it is) -> ``<cylinder>_rod_body``, whose origin is the rod pin;
* the bucket linkage: ``side_link_joint`` at the side-link pivot on the arm (angle of pivot ->
  rod pin R from the arm's x axis) -> ``side_link``; ``h_link_joint`` at R (angle of R -> H-link
  pin from the side link) -> ``h_link``.

Every pin of :meth:`Excavator.pins` is a fixed frame of that name on its body; the tool frame is
``bucket_tip`` (orientation: the bucket frame, as ``bucket_pose``). The loops close in the URDF
for the values of :func:`joint_positions` only: the rod bodies' origins land on the rod pins and
the H-link's end on the bucket's H-link pin (test/test_urdf.py checks each at random states).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from excavator_kinematics.core.kinematics import JOINTS, Excavator
from excavator_kinematics.core.machine_file import CYLINDERS
from manipulator_kinematics.serial_chain import transl
from manipulator_kinematics.urdf import Robot

#: Every joint of the excavator's URDF that moves, in the order of :func:`joint_positions`.
URDF_JOINTS = (
    *JOINTS,
    *(name for cylinder in CYLINDERS for name in (f"{cylinder}_barrel_joint", cylinder)),
    "side_link_joint",
    "h_link_joint",
)
# Turning axis in the boom plane: counter-clockwise seen from the machine's right is about -y.
_AXIS = (0.0, -1.0, 0.0)
# Samples per stroke for the passive joints' ranges (each depends on one cylinder only).
_RANGE_SAMPLES = 4001


def joint_positions(model: Excavator, D: ArrayLike) -> np.ndarray:
    """Values (..., 12) of :data:`URDF_JOINTS` for states D = [theta1, d2, d3, d4] (..., 4).

    rad for the revolute joints, m for the cylinders (= d2, d3, d4). From the pins of
    :meth:`Excavator.pins` in the boom plane; raises StrokeError as the model does.
    """
    D = model.validate(D)
    pins = model.pins(D)
    c1, s1 = np.cos(D[..., 0]), np.sin(D[..., 0])

    def plane(name: str) -> np.ndarray:  # [r, z] of a pin in the boom plane
        p = pins[name]
        return np.stack((p[..., 0] * c1 + p[..., 1] * s1, p[..., 2]), axis=-1)

    def heading(start: str, end: str) -> np.ndarray:
        d = plane(end) - plane(start)
        return np.arctan2(d[..., 1], d[..., 0])

    theta = model.joint_angles(D[..., 1:])
    boom, arm = theta[..., 0], theta[..., 0] + theta[..., 1]
    side = heading("side_link_pivot", "bucket_cylinder_rod")
    values = [
        D[..., 0],
        theta[..., 0],
        theta[..., 1],
        theta[..., 2],
        heading("boom_cylinder_base", "boom_cylinder_rod"),
        D[..., 1],
        heading("arm_cylinder_base", "arm_cylinder_rod") - boom,
        D[..., 2],
        heading("bucket_cylinder_base", "bucket_cylinder_rod") - arm,
        D[..., 3],
        side - arm,
        heading("bucket_cylinder_rod", "h_link_pin") - side,
    ]
    out = np.stack(values, axis=-1)
    revolute = np.array([not name.endswith("_cylinder") for name in URDF_JOINTS])
    out[..., revolute] = (out[..., revolute] + np.pi) % (2.0 * np.pi) - np.pi
    return out


def joint_ranges(model: Excavator) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper limits (12,) of :data:`URDF_JOINTS` over the stroke box.

    The swing and the cylinders: the machine's limits. The angles: each depends on one cylinder
    only, so min/max over a dense sample of that stroke, widened by the largest change between
    neighbouring samples (the extremum between two samples cannot lie further out than that).
    """
    lo, hi = model.joint_limits.lower, model.joint_limits.upper  # a continuous swing: (-pi, pi]
    D = np.linspace(lo, hi, _RANGE_SAMPLES)
    D[:, 0] = 0.0
    values = joint_positions(model, D)
    pad = np.max(np.abs(np.diff(values, axis=0)), axis=0)
    lower, upper = values.min(axis=0) - pad, values.max(axis=0) + pad
    exact = [0, 5, 7, 9]  # swing_joint and the three cylinders
    lower[exact], upper[exact] = lo, hi
    return lower, upper


def _at(r: float, z: float) -> np.ndarray:
    return transl(r, 0.0, z)


def body_points(model: Excavator) -> dict[str, np.ndarray]:
    """[r, z] of every pin in the frame of the body it is fixed to (the tree of the module
    docstring), and the side-link and H-link lengths; from :meth:`Excavator.pins` at the
    reference state, so only the model's public geometry is used."""
    D = model.limits.reference.copy()
    D[0] = 0.0  # swing 0: base x = r, base z = z
    pins = {name: p[[0, 2]] for name, p in model.pins(D).items()}
    values = joint_positions(model, D)
    t2, t3, t4 = values[1:4]
    side = values[URDF_JOINTS.index("side_link_joint")] + t2 + t3  # side link heading in the plane
    frames = {  # body -> (origin, heading) in the plane
        "upper_structure": (np.zeros(2), 0.0),
        "boom": (pins["boom_foot"], t2),
        "arm": (pins["arm_pin"], t2 + t3),
        "bucket": (pins["bucket_pin"], t2 + t3 + t4),
        "side_link": (pins["side_link_pivot"], side),
        "h_link": (pins["bucket_cylinder_rod"], side + values[URDF_JOINTS.index("h_link_joint")]),
    }

    def local(body: str, pin: str) -> np.ndarray:
        origin, heading = frames[body]
        c, s = math.cos(heading), math.sin(heading)
        d = pins[pin] - origin
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])

    return {pin: local(body, pin) for body, pin in _PINS} | {
        "side_link_length": float(np.hypot(*(pins["bucket_cylinder_rod"] - pins["side_link_pivot"]))),
        "h_link_length": float(np.hypot(*(pins["h_link_pin"] - pins["bucket_cylinder_rod"]))),
    }


# Every pin of Excavator.pins and the body it is fixed to in the URDF.
_PINS = (
    ("upper_structure", "boom_foot"),
    ("upper_structure", "boom_cylinder_base"),
    ("boom", "boom_cylinder_rod"),
    ("boom", "arm_pin"),
    ("boom", "arm_cylinder_base"),
    ("arm", "arm_cylinder_rod"),
    ("arm", "bucket_pin"),
    ("arm", "bucket_cylinder_base"),
    ("arm", "side_link_pivot"),
    ("side_link", "bucket_cylinder_rod"),
    ("h_link", "h_link_pin"),
    ("bucket", "h_link_pin_on_bucket"),
    ("bucket", "bucket_tip"),
)


def excavator_urdf(model: Excavator) -> str:
    """The URDF (XML text) of the excavator ``model`` (module docstring), named as the machine file
    names the machine (``hydraulic_machine.name``)."""
    g = body_points(model)
    lower, upper = joint_ranges(model)
    limits = {joint: (lower[i], upper[i]) for i, joint in enumerate(URDF_JOINTS)}
    scale = model.l2 + model.l3 + model.l4
    beam, barrel, rod, pin = 0.012 * scale, 0.007 * scale, 0.0045 * scale, 0.008 * scale

    robot = Robot(model.name, f"generated by mk_urdf from the {model.name} config: do not edit")
    for link in ("base_link", "upper_structure", "boom", "arm", "bucket"):
        robot.link(link)

    def turn(joint: str, parent: str, child: str, origin: np.ndarray) -> None:
        robot.joint(joint, "revolute", parent, child, origin, axis=_AXIS, limits=limits[joint])

    if model.limits.continuous_swing:  # open limits: URDF's joint without limits
        robot.joint("swing_joint", "continuous", "base_link", "upper_structure", axis=(0.0, 0.0, 1.0))
    else:
        robot.joint(
            "swing_joint",
            "revolute",
            "base_link",
            "upper_structure",
            axis=(0.0, 0.0, 1.0),
            limits=limits["swing_joint"],
        )
    turn("boom_joint", "upper_structure", "boom", _at(*g["boom_foot"]))
    turn("arm_joint", "boom", "arm", _at(*g["arm_pin"]))
    turn("bucket_joint", "arm", "bucket", _at(*g["bucket_pin"]))

    # Cylinders: barrel at the base pin on ``body``; the rod body's origin is the rod pin.
    for cylinder, body, i in (
        ("boom_cylinder", "upper_structure", 0),
        ("arm_cylinder", "boom", 1),
        ("bucket_cylinder", "arm", 2),
    ):
        retracted, extended = model.limits.stroke_min[i], model.limits.stroke_max[i]
        robot.link(f"{cylinder}_barrel")
        turn(f"{cylinder}_barrel_joint", body, f"{cylinder}_barrel", _at(*g[f"{cylinder}_base"]))
        robot.link(f"{cylinder}_rod_body")
        robot.joint(
            cylinder,
            "prismatic",
            f"{cylinder}_barrel",
            f"{cylinder}_rod_body",
            axis=(1.0, 0.0, 0.0),
            limits=limits[cylinder],
        )
        # Display only: a barrel a little shorter than the retracted cylinder, a rod that stays
        # inside it at full extension.
        robot.segment(f"{cylinder}_barrel", (0.0, 0.0, 0.0), (0.9 * retracted, 0.0, 0.0), barrel, "steel")
        robot.segment(
            f"{cylinder}_rod_body", (0.0, 0.0, 0.0), (-(extended - 0.8 * retracted), 0.0, 0.0), rod, "chrome"
        )
    robot.link("side_link")
    turn("side_link_joint", "arm", "side_link", _at(*g["side_link_pivot"]))
    robot.link("h_link")
    turn("h_link_joint", "side_link", "h_link", _at(g["side_link_length"], 0.0))

    plane = g
    outline = {
        "upper_structure": [
            ((0.0, 0.0), plane["boom_foot"]),
            (plane["boom_foot"], plane["boom_cylinder_base"]),
        ],
        "boom": [
            ((0.0, 0.0), plane["arm_cylinder_base"]),
            (plane["arm_cylinder_base"], plane["arm_pin"]),
            ((0.0, 0.0), plane["boom_cylinder_rod"]),
            (plane["boom_cylinder_rod"], plane["arm_cylinder_base"]),
        ],
        "arm": [
            (plane["arm_cylinder_rod"], (0.0, 0.0)),
            ((0.0, 0.0), plane["bucket_pin"]),
            (plane["arm_cylinder_rod"], plane["bucket_cylinder_base"]),
            (plane["bucket_cylinder_base"], plane["side_link_pivot"]),
        ],
        "bucket": [
            ((0.0, 0.0), plane["bucket_tip"]),
            ((0.0, 0.0), plane["h_link_pin_on_bucket"]),
            (plane["h_link_pin_on_bucket"], plane["bucket_tip"]),
        ],
        "side_link": [((0.0, 0.0), plane["bucket_cylinder_rod"])],
        "h_link": [((0.0, 0.0), plane["h_link_pin"])],
    }
    for body, segments in outline.items():
        width = beam if body in ("boom", "arm", "bucket", "upper_structure") else rod
        for start, end in segments:
            robot.segment(body, (start[0], 0.0, start[1]), (end[0], 0.0, end[1]), width, "structure")
    for body, pin_name in _PINS:  # bucket_tip (the tool frame) keeps the bucket frame's orientation
        r, z = g[pin_name]
        robot.fixed(pin_name, body, _at(r, z))
        robot.sphere(body, (r, 0.0, z), pin, "pin")
    return robot.xml()
