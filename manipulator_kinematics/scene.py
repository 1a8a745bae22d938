"""A machine drawn as simple solids in its base frame, for markers, bags and animations (numpy only).

A :class:`Scene` is what every display of the package draws: segments with a radius (links,
cylinder barrels and rods; a cylinder marker in RViz/Foxglove, a thick line in a side view),
spheres (joints and pins) and named frames (for /tf), each over a batch of states (leading
shape ``...``). Each machine says how to build its scene through the ``scene`` hook of its
:class:`manipulator_kinematics.registry.Machine` record; every serial machine (the
:class:`manipulator_kinematics.model.SerialModel` protocol) uses :func:`serial_scene`, which
draws the chain of ``model.frames(q)``.

Sizes come from the machine itself: radii are fractions of its size (:func:`chain_size`), never
numbers copied from a drawing; the fractions below only set how heavy the picture looks.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Link radius as a fraction of the machine's size (sum of its link lengths).
LINK_SHARE = 0.01
#: Joint spheres are this much thicker than the links they join.
JOINT_FACTOR = 1.5
#: Consecutive frames closer than this share one origin (no link drawn between them), m.
SAME_ORIGIN = 1e-9

#: RGBA colour of each kind of solid (markers and animations use the same).
COLORS: dict[str, tuple[float, float, float, float]] = {
    "base": (0.35, 0.35, 0.38, 1.0),
    "link": (0.95, 0.70, 0.10, 1.0),
    "barrel": (0.20, 0.22, 0.25, 1.0),
    "rod": (0.80, 0.82, 0.85, 1.0),
    "linkage": (0.55, 0.40, 0.10, 1.0),
    "joint": (0.10, 0.10, 0.12, 1.0),
    "tool": (0.85, 0.15, 0.10, 1.0),
}


@dataclass(frozen=True)
class Segment:
    """A solid cylinder from ``start`` to ``end`` (..., 3) with ``radius`` (m)."""

    name: str
    kind: str
    start: np.ndarray
    end: np.ndarray
    radius: float

    @property
    def length(self) -> np.ndarray:
        return np.linalg.norm(self.end - self.start, axis=-1)


@dataclass(frozen=True)
class Sphere:
    """A sphere at ``center`` (..., 3) with ``radius`` (m)."""

    name: str
    kind: str
    center: np.ndarray
    radius: float


@dataclass(frozen=True)
class Scene:
    """Everything drawn of a batch of machine states, in the base frame.

    ``frames`` maps a frame name (a /tf child frame of the base frame) to its pose (..., 4, 4);
    ``tool`` names the frame of the tool point (the bucket tip, the TCP) that a trace follows;
    ``joints`` maps every moving joint of the machine's URDF (``Machine.urdf``) to its values
    (...,), so /tf can follow the URDF (mimic joints excepted: the URDF says how they follow).
    """

    segments: tuple[Segment, ...]
    spheres: tuple[Sphere, ...]
    frames: Mapping[str, np.ndarray] = field(default_factory=dict)
    tool: str = ""
    joints: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, ...]:
        """The batch shape ``...``."""
        first = self.segments[0].start if self.segments else self.spheres[0].center
        return first.shape[:-1]

    def take(self, index: Any) -> Scene:
        """The scene of some states: ``index`` applied to the batch axes (``scene.take(slice(0, 10))``)."""
        return Scene(
            tuple(Segment(s.name, s.kind, s.start[index], s.end[index], s.radius) for s in self.segments),
            tuple(Sphere(s.name, s.kind, s.center[index], s.radius) for s in self.spheres),
            {name: pose[index] for name, pose in self.frames.items()},
            self.tool,
            {name: value[index] for name, value in self.joints.items()},
        )

    def tool_point(self) -> np.ndarray:
        """(..., 3) origin of the tool frame."""
        return self.frames[self.tool][..., :3, 3]

    def points(self) -> np.ndarray:
        """(..., m, 3) every segment end and sphere centre (for the extent of a plot)."""
        pts = [p for s in self.segments for p in (s.start, s.end)] + [s.center for s in self.spheres]
        return np.stack(pts, axis=-2)


def chain_size(points: np.ndarray) -> float:
    """Sum of the distances between consecutive points (m, k, 3) of a chain, largest over states."""
    return float(np.max(np.sum(np.linalg.norm(np.diff(points, axis=-2), axis=-1), axis=-1)))


def middle_state(model: Any) -> np.ndarray:
    """The middle of every joint range: the state a machine's proportions are measured at."""
    limits = model.limits
    return 0.5 * (np.asarray(limits.lower, dtype=float) + np.asarray(limits.upper, dtype=float))


def serial_scene(model: Any, q: np.ndarray) -> Scene:
    """Scene of a serial machine (:class:`~manipulator_kinematics.model.SerialModel`) at joint
    states ``q`` (..., n): a link between each two consecutive origins of ``model.frames(q)``
    (base, every joint frame, tool), a sphere at every joint frame origin, the base and tool as
    spheres of their own kinds. Frames ``frame_1``..``frame_k`` and ``tool`` for /tf (the names
    of :func:`manipulator_kinematics.urdf.serial_urdf`'s frames); ``joints``: the model's joints.

    Which consecutive frames share an origin (no link between them) and the radii are read at
    the middle of the joint ranges, so they do not change from state to state."""
    frames = model.frames(np.asarray(q, dtype=float))
    reference = model.frames(middle_state(model))[..., :3, 3]
    size = chain_size(reference[None])
    link, joint = LINK_SHARE * size, LINK_SHARE * JOINT_FACTOR * size
    origins = frames[..., :3, 3]
    k = origins.shape[-2]
    segments = tuple(
        Segment(f"link_{i}", "link", origins[..., i - 1, :], origins[..., i, :], link)
        for i in range(1, k)
        if np.linalg.norm(reference[i] - reference[i - 1]) > SAME_ORIGIN
    )
    spheres = (
        Sphere("base", "base", origins[..., 0, :], 2.0 * joint),
        *(Sphere(f"joint_{i}", "joint", origins[..., i, :], joint) for i in range(1, k - 1)),
        Sphere("tool", "tool", origins[..., k - 1, :], joint),
    )
    named = {f"frame_{i}": frames[..., i, :, :] for i in range(1, k - 1)}
    named["tool"] = frames[..., k - 1, :, :]
    q = np.broadcast_to(np.asarray(q, dtype=float), origins.shape[:-2] + (len(model.joint_names),))
    joints = dict(zip(model.joint_names, np.moveaxis(q, -1, 0), strict=True))
    return Scene(segments, spheres, named, "tool", joints)


def cylinder_pose(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre (..., 3), quaternion (..., 4) (x, y, z, w) turning z onto ``end - start``, and
    length (...,) of a segment: a cylinder marker's pose and height. A zero-length segment gets
    the identity; one pointing along -z a half turn about x."""
    d = end - start
    length = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(length[..., None] > 0, d / length[..., None], np.array([0.0, 0.0, 1.0]))
    # The half-way quaternion between z and u: (z x u, 1 + z.u), normalised.
    q = np.stack((-u[..., 1], u[..., 0], np.zeros_like(length), 1.0 + u[..., 2]), axis=-1)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    flipped = norm < 1e-9
    q = np.where(flipped, np.array([1.0, 0.0, 0.0, 0.0]), q / np.where(flipped, 1.0, norm))
    return 0.5 * (start + end), q, length


@dataclass(frozen=True)
class Solids:
    """A scene as marker-ready solids: one row per segment (cylinder) then per sphere.

    ``position`` (..., m, 3) centres, ``orientation`` (..., m, 4) quaternions (x, y, z, w) that
    turn a cylinder's z axis onto its segment, ``scale`` (..., m, 3) diameters and height (a
    visualization_msgs/Marker's scale), ``color`` (m, 4) RGBA of each solid's kind.
    """

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    cylinder: np.ndarray  # (m,) True for a cylinder, False for a sphere
    position: np.ndarray
    orientation: np.ndarray
    scale: np.ndarray
    color: np.ndarray


def solids(scene: Scene) -> Solids:
    """Every segment and sphere of ``scene`` as a posed, scaled solid (:class:`Solids`)."""
    batch = scene.shape
    parts = []
    for s in scene.segments:
        centre, quaternion, length = cylinder_pose(s.start, s.end)
        diameter = np.full(batch, 2.0 * s.radius)
        parts.append((centre, quaternion, np.stack((diameter, diameter, length), axis=-1)))
    identity = np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), batch + (4,))
    for s in scene.spheres:
        parts.append((s.center, identity, np.full(batch + (3,), 2.0 * s.radius)))
    every = (*scene.segments, *scene.spheres)
    return Solids(
        tuple(e.name for e in every),
        tuple(e.kind for e in every),
        np.array([True] * len(scene.segments) + [False] * len(scene.spheres)),
        *(np.stack([part[k] for part in parts], axis=-2) for k in range(3)),
        np.array([COLORS[e.kind] for e in every]),
    )


__all__ = [
    "COLORS",
    "Scene",
    "Segment",
    "Solids",
    "Sphere",
    "chain_size",
    "cylinder_pose",
    "middle_state",
    "serial_scene",
    "solids",
]
