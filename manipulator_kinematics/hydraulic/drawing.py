"""Scene and URDF of any machine of the hydraulic family, drawn from its pins (numpy only).

The URDF is a tree, so the closed loops are cut: every body of the machine file is a link hung
from a body already placed, at the pin they share (the main chain's joints first, then every
linkage body, e.g. the loader's bell crank on the lift arm), and every cylinder is two links, a
barrel turning on its base pin and a rod sliding in it to the rod pin. Their joints are not mimic
joints: URDF's mimic is linear (joint = k x other + c), a four-bar's or a Z-bar's is not. So every
joint is published as a value of its own (:func:`urdf_joint_values`, the scene's ``joints``; the
family forward node's ``urdf_joint_states``): the swing as ``swing_joint`` (rad) and each
cylinder's slide as the cylinder's name with its length (m), the names of D, so a driver's
``joint_states`` already carry them, and the passive joints (the chain's ``theta2``..., each
linkage body's ``<body>_joint``, each barrel's ``<cylinder>_barrel_joint``, a hanging tool's
``tool_joint`` that keeps it level) computed by the model.

Frames: link ``<body>`` has its origin at the pin it hangs from (the ground body at the boom
plane's origin, a prismatic child at its own origin) and its x axis along the body's x axis; a
barrel's and a rod's x axis run from the base pin to the rod pin, the rod's origin at the rod pin.
Revolute joints turn about -y (counter-clockwise seen from the machine's right, as the machine
file's angles), the swing about z.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from manipulator_kinematics.hydraulic.description import Description
from manipulator_kinematics.scene import JOINT_FACTOR, LINK_SHARE, Scene, Segment, Sphere

__all__ = ["family_scene", "family_urdf", "urdf_joint_values"]

#: A barrel is this part of its cylinder's shortest length; the rod as long as the shortest length.
BARREL_SHARE = 0.9
_Y = np.array([0.0, -1.0, 0.0])
#: The passive joint of a tool without a tool angle (it hangs level: the crane's rotator).
TOOL_JOINT = "tool_joint"  # revolute axis: counter-clockwise seen from the machine's right


@dataclass(frozen=True)
class _Hang:
    """Body ``child`` hung from ``parent``: by the revolute ``joint`` at ``pin``, or by the slide."""

    joint: str
    parent: str
    child: str
    pin: str | None  # None: the prismatic child of a slide
    chain: bool  # a main-chain joint (its limits are the machine file's)


@dataclass(frozen=True)
class _Layout:
    anchors: dict[str, np.ndarray]  # body -> its link frame's origin in its own frame (x, z)
    hangs: tuple[_Hang, ...]  # in tree order
    cylinders: tuple[tuple[str, str, int], ...]  # (cylinder, body of its base pin, index in D)


def _layout(description: Description) -> _Layout:
    d = description
    anchors = {d.ground: np.zeros(2)}
    hangs = []
    for joint in d.joints:
        if joint.slide is None:
            anchors[joint.child] = d.bodies[joint.child][joint.pivot]
        else:
            anchors[joint.child] = np.zeros(2)
        hangs.append(_Hang(joint.name, joint.parent, joint.child, joint.pivot, True))
    progress = True
    while progress:  # every other body, at a pin it shares with a body already placed
        progress = False
        for body, pins in d.bodies.items():
            if body in anchors:
                continue
            for pin in pins:
                parent = next((b for b in anchors if pin in d.bodies[b]), None)
                if parent is not None:
                    anchors[body] = pins[pin]
                    hangs.append(_Hang(f"{body}_joint", parent, body, pin, False))
                    progress = True
                    break
    cylinders = tuple(
        (c.name, next(b for b in anchors if c.base in d.bodies[b]), c.index) for c in d.cylinders
    )
    return _Layout(anchors, tuple(hangs), cylinders)


def _wrap(angle: np.ndarray) -> np.ndarray:
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def _plane_frames(model: Any, D: np.ndarray) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Each URDF link's frame in the boom plane, (origin (..., 2), angle (...)), and the swing."""
    h = model.hydraulic
    layout = _layout(h.description)
    placed = h.placements(D)
    frames = {}
    for body, (origin, phi) in placed.items():
        a = layout.anchors[body]
        c, s = np.cos(phi), np.sin(phi)
        frames[body] = (origin + np.stack((c * a[0] - s * a[1], s * a[0] + c * a[1]), axis=-1), phi)
    pins = {}
    for body, pin_map in h.description.bodies.items():
        origin, phi = placed[body]
        c, s = np.cos(phi), np.sin(phi)
        for pin, xz in pin_map.items():
            pins.setdefault(pin, origin + np.stack((c * xz[0] - s * xz[1], s * xz[0] + c * xz[1]), axis=-1))
    for cylinder in h.description.cylinders:
        base, rod = pins[cylinder.base], pins[cylinder.rod]
        e = rod - base
        angle = np.arctan2(e[..., 1], e[..., 0])
        frames[f"{cylinder.name}_barrel"] = (base, angle)
        frames[f"{cylinder.name}_rod"] = (rod, angle)
    t1 = D[..., 0] if h.swing else np.zeros(D.shape[:-1])
    return frames, t1


def urdf_joint_values(model: Any, D: Any) -> dict[str, np.ndarray]:
    """Every moving joint of :func:`family_urdf` -> its values (...,) at actuator states D (..., m)."""
    D = np.asarray(D, dtype=float)
    h = model.hydraulic
    d = h.description
    layout = _layout(d)
    frames, _ = _plane_frames(model, D)
    values = {}
    if h.swing:
        values[h.actuator_names[0]] = D[..., 0]
    for hang in layout.hangs:
        if hang.pin is None:
            slide = next(j.slide for j in d.joints if j.child == hang.child)
            values[hang.joint] = D[..., slide.index] + slide.offset
        else:
            values[hang.joint] = _wrap(frames[hang.child][1] - frames[hang.parent][1])
    if not d.has_angle:
        values[TOOL_JOINT] = _wrap(-frames[d.tool_body][1])
    for name, body, index in layout.cylinders:
        values[f"{name}_barrel_joint"] = _wrap(frames[f"{name}_barrel"][1] - frames[body][1])
        values[name] = D[..., index]
    return values


def _pose(origin: np.ndarray, phi: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """(..., 4, 4) of a boom-plane frame: Rz(t1) Trans(r, 0, z) Ry(-phi)."""
    c1, s1, cp, sp = np.cos(t1), np.sin(t1), np.cos(phi), np.sin(phi)
    T = np.zeros(np.shape(phi) + (4, 4))
    T[..., 0, :3] = np.stack((c1 * cp, -s1, -c1 * sp), axis=-1)
    T[..., 1, :3] = np.stack((s1 * cp, c1, -s1 * sp), axis=-1)
    T[..., 2, :3] = np.stack((sp, np.zeros_like(sp), cp), axis=-1)
    T[..., :3, 3] = np.stack((origin[..., 0] * c1, origin[..., 0] * s1, origin[..., 1]), axis=-1)
    T[..., 3, 3] = 1.0
    return T


def _size(model: Any) -> float:
    """The machine's size: the longest distance between two pins at the reference state (m)."""
    pins = np.stack(list(model.hydraulic.pins(model.hydraulic.reference).values()))
    return float(np.max(np.linalg.norm(pins[:, None] - pins[None], axis=-1)))


def family_scene(model: Any, q: Any) -> Scene:
    """The machine at sensor readings q (..., m) (the joint_states values; D = q + zero_offset,
    :meth:`FamilyArm.true_state`): each body a star of segments from its first pin
    to its other pins (the ground body's kind ``base``, the main chain's ``link``, the linkage's
    ``linkage``), a telescope's sleeve to its axis point, each cylinder a barrel from its base pin
    and a rod to its rod pin, a sphere on every pin and the tool point; frames: every URDF link
    and ``tool``; joints: every moving URDF joint (:func:`urdf_joint_values`)."""
    D = model.true_state(q)
    h = model.hydraulic
    d = h.description
    pins = _pins(model, D)
    size = _size(model)
    link, joint = LINK_SHARE * size, LINK_SHARE * JOINT_FACTOR * size
    chain = {j.child for j in d.joints}
    segments = []
    for body, pin_map in d.bodies.items():
        kind = "base" if body == d.ground else "link" if body in chain else "linkage"
        first, *rest = pin_map
        segments += [Segment(f"{body}_{pin}", kind, pins[first], pins[pin], link) for pin in rest]
    for hinge in d.joints:  # a telescope's sleeve: its parent from the first pin to the slide's axis point
        if hinge.slide is not None:
            start = pins[next(iter(d.bodies[hinge.parent]))]
            end = _points(model, D, hinge.parent, np.asarray(hinge.slide.axis_point, dtype=float))
            segments.append(Segment(f"{hinge.parent}_sleeve", "link", start, end, link))
    for c in d.cylinders:
        base, rod = pins[c.base], pins[c.rod]
        u = (rod - base) / np.linalg.norm(rod - base, axis=-1)[..., None]
        segments.append(
            Segment(f"{c.name}_barrel", "barrel", base, base + BARREL_SHARE * c.lower * u, 1.2 * link)
        )
        segments.append(Segment(f"{c.name}_rod", "rod", rod - c.lower * u, rod, 0.6 * link))
    tool = pins[d.tool_pin]
    spheres = [Sphere(pin, "joint", point, joint) for pin, point in pins.items() if pin != d.tool_pin]
    spheres.append(Sphere("tool", "tool", tool, joint))
    plane, t1 = _plane_frames(model, D)
    frames = {name: _pose(origin, phi, t1) for name, (origin, phi) in plane.items()}
    frames["tool"] = model.fkine(q)
    return Scene(tuple(segments), tuple(spheres), frames, "tool", urdf_joint_values(model, D))


def _pins(model: Any, D: np.ndarray) -> dict[str, np.ndarray]:
    """Every pin in the base frame (..., 3), for any finite D (a measured state may be a little
    beyond a stroke end)."""
    h = model.hydraulic
    placed = h.placements(D)
    t1 = D[..., 0] if h.swing else np.zeros(D.shape[:-1])
    out = {}
    for body, pin_map in h.description.bodies.items():
        origin, phi = placed[body]
        c, s = np.cos(phi), np.sin(phi)
        for pin, xz in pin_map.items():
            if pin not in out:
                r = origin[..., 0] + c * xz[0] - s * xz[1]
                z = origin[..., 1] + s * xz[0] + c * xz[1]
                out[pin] = np.stack((r * np.cos(t1), r * np.sin(t1), z), axis=-1)
    return out


def _points(model: Any, D: np.ndarray, body: str, local: np.ndarray) -> np.ndarray:
    """The point ``local`` (x, z) of ``body`` in the base frame (..., 3)."""
    h = model.hydraulic
    origin, phi = h.placements(D)[body]
    c, s = np.cos(phi), np.sin(phi)
    r = origin[..., 0] + c * local[0] - s * local[1]
    z = origin[..., 1] + s * local[0] + c * local[1]
    t1 = D[..., 0] if h.swing else np.zeros(D.shape[:-1])
    return np.stack((r * np.cos(t1), r * np.sin(t1), z), axis=-1)


def family_urdf(model: Any) -> str:
    """URDF of a family machine (module docstring): ``base_link``, the swing (if any), every body
    and cylinder, visuals from the pins; the chain's joints with the machine file's limits, the
    cylinders' slides with their strokes, the linkage's and barrels' joints within (-pi, pi]."""
    from manipulator_kinematics.urdf import Robot  # the XML writer (numpy only, no registry cycle)

    h = model.hydraulic
    d = h.description
    layout = _layout(d)
    size = _size(model)
    radius = LINK_SHARE * size
    robot = Robot(model.name, f"generated by mk_urdf from the {model.name} machine file: do not edit")
    robot.link("base_link")
    robot.link(d.ground)
    if h.swing:
        limits = (float(h.lower[0]), float(h.upper[0]))
        robot.joint(h.actuator_names[0], "revolute", "base_link", d.ground, axis=(0, 0, 1), limits=limits)
    else:
        robot.joint(f"{d.ground}_fixed", "fixed", "base_link", d.ground)

    def local(body: str, xz: np.ndarray) -> np.ndarray:
        a = xz - layout.anchors[body]
        return np.array([a[0], 0.0, a[1]])

    def translation(xyz: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = xyz
        return T

    chain = {j.name: j for j in d.joints}
    for hang in layout.hangs:
        robot.link(hang.child)
        limits = (chain[hang.joint].lower, chain[hang.joint].upper) if hang.chain else (-np.pi, np.pi)
        if hang.pin is None:
            slide = chain[hang.joint].slide
            origin = translation(local(hang.parent, np.asarray(slide.axis_point, dtype=float)))
            robot.joint(
                hang.joint, "prismatic", hang.parent, hang.child, origin, axis=(1, 0, 0), limits=limits
            )
        else:
            # The joint frame: at the pin, turned so that the child's x axis is along its own
            # x axis at joint value 0 (the child's anchor frame has the parent's orientation then).
            origin = translation(local(hang.parent, d.bodies[hang.parent][hang.pin]))
            robot.joint(hang.joint, "revolute", hang.parent, hang.child, origin, axis=_Y, limits=limits)
    for body, pin_map in d.bodies.items():
        first, *rest = pin_map
        material = "steel" if body == d.ground else "structure"
        for pin in rest:
            robot.segment(body, local(body, pin_map[first]), local(body, pin_map[pin]), radius, material)
        for xz in pin_map.values():
            robot.sphere(body, local(body, xz), JOINT_FACTOR * radius, "pin")
    for joint in d.joints:  # a telescope's sleeve, as in the scene
        if joint.slide is not None:
            first = d.bodies[joint.parent][next(iter(d.bodies[joint.parent]))]
            axis = np.asarray(joint.slide.axis_point, dtype=float)
            robot.segment(
                joint.parent, local(joint.parent, first), local(joint.parent, axis), radius, "structure"
            )
    for (name, body, _), c in zip(layout.cylinders, d.cylinders, strict=True):
        barrel, rod = f"{name}_barrel", f"{name}_rod"
        robot.link(barrel)
        robot.link(rod)
        origin = translation(local(body, d.bodies[body][c.base]))
        robot.joint(f"{name}_barrel_joint", "revolute", body, barrel, origin, axis=_Y, limits=(-np.pi, np.pi))
        robot.joint(name, "prismatic", barrel, rod, axis=(1, 0, 0), limits=(c.lower, c.upper))
        robot.segment(barrel, np.zeros(3), [BARREL_SHARE * c.lower, 0.0, 0.0], 1.2 * radius, "steel")
        robot.segment(rod, [-c.lower, 0.0, 0.0], np.zeros(3), 0.6 * radius, "chrome")
    tool = translation(local(d.tool_body, d.bodies[d.tool_body][d.tool_pin]))
    if d.has_angle:
        robot.fixed("tool", d.tool_body, tool)
    else:  # a hanging tool (the crane's rotator) stays level: a passive joint of its own
        robot.link("tool")
        robot.joint(TOOL_JOINT, "revolute", d.tool_body, "tool", tool, axis=_Y, limits=(-np.pi, np.pi))
    return robot.xml()
