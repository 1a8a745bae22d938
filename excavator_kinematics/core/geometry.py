"""The excavator's cylinder linkages, folded once from its machine description (paper 000, eqs.
1-2): the constants the pose IK (:mod:`excavator_kinematics.core.inverse`) and the compiled
kernels (:mod:`excavator_kinematics.core.layouts`) read. The forward numpy path is the hydraulic
family's core (:attr:`excavator_kinematics.core.kinematics.Excavator.hydraulic`), which solves the
same linkages from the machine file's pins.

* :class:`Triangle`: a cylinder closing a triangle at a pivot (eq. 1), for the boom, the arm and
  the bucket cylinder's side link;
* :class:`Linkages`: the three triangles and the bucket four-bar's pins and links (eq. 2), in the
  frames of the bodies they sit on;
* :func:`cos_sin`: cos and sin by the tangent half-angle formulas (the IK's swing angle).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from excavator_kinematics.core.layouts import FourBarConstants, TriangleConstants
from excavator_kinematics.core.machine_file import Description


class StrokeError(ValueError):
    """A state outside the machine's strokes/limits, non-finite, or geometrically impossible."""


def direction(v: np.ndarray) -> float:
    """The direction of a planar vector [r, z], rad."""
    return math.atan2(v[1], v[0])


def cos_sin(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin by the tangent half-angle formulas, within 2.3e-16 of np.cos and np.sin (the
    IK's swing angle).

    Why not np.cos and np.sin: numpy runs float64 sin and cos element by element through libm
    but has a vectorised tan: one tan and a few products cost a quarter of the pair (measured
    5 vs 19.5 ns per angle), a fifth of a batch pose. t * t cannot overflow: |tan| of any double
    stays below 1e19.
    """
    t = np.tan(0.5 * angle)
    t2 = t * t
    scale = 1.0 / (1.0 + t2)
    return (1.0 - t2) * scale, 2.0 * t * scale


@dataclass(frozen=True)
class Triangle:
    """A cylinder of length d closing a triangle at a pivot (paper eq. 1).

    ``first`` and ``second`` are the pins at the cylinder's ends, relative to the pivot, each in
    the frame of the body it sits on; the joint angle is the rotation of the second body that
    makes the pin distance equal d: theta = ang(first) + orientation * gamma - ang(second), gamma
    the angle at the pivot (``constants``: its cosine's folded terms, for the kernel).
    """

    name: str
    a: float  # |first - pivot|
    b: float  # |second - pivot|
    offset: float  # ang(first) - ang(second)
    orientation: int
    radius: float = 1.0  # scale of the joint angle's cosine and sine (the kernel's)

    @property
    def constants(self) -> TriangleConstants:
        """Eq. 1's constants, folded (:class:`~excavator_kinematics.core.layouts.TriangleConstants`)."""
        ab = self.a * self.b
        return TriangleConstants(
            c0=(self.a * self.a + self.b * self.b) / (2.0 * ab),
            c1=0.5 / ab,
            ab=ab,
            o=float(self.orientation),
            cos_offset=self.radius * math.cos(self.offset),
            sin_offset=self.radius * math.sin(self.offset),
            offset=self.offset,
        )

    @classmethod
    def of(cls, name: str, first: np.ndarray, second: np.ndarray, orientation: int) -> Triangle:
        """The triangle of a cylinder whose pins are ``first`` and ``second`` from the pivot."""
        return cls(
            name,
            float(np.hypot(*first)),
            float(np.hypot(*second)),
            direction(first) - direction(second),
            orientation,
        )


@dataclass(frozen=True)
class Linkages:
    """The cylinder linkages of one machine (eqs. 1-2), points [r, z] in their bodies' frames
    (docs/excavator.md): the boom and arm triangles, the bucket cylinder's side-link triangle
    (Fig. 7b: its rod pin R at (side length, 0) of a frame turning with the side link, so its
    cosine and sine give R relative to the pivot) and the bucket four-bar (Fig. 7c): the H-link
    pin on a circle of ``h_radius`` about the bucket pin, linked to R by ``h_link``."""

    boom: Triangle
    arm: Triangle
    side: Triangle  # the bucket cylinder's side-link triangle, radius = side-link length
    bucket_pin: np.ndarray  # (2,) arm frame
    pivot: np.ndarray  # (2,) side-link pivot, arm frame
    side_link: float  # side-link length
    h_pin: np.ndarray  # (2,) H-link pin, bucket frame
    h_radius: float  # |bucket pin -> H-link pin|
    h_phase: float  # direction of the H-link pin in the bucket frame
    h_link: float  # H-link length
    h_orientation: int
    bucket_cylinder_base: np.ndarray  # (2,) arm frame
    pivot_from_bucket_pin: tuple[float, float]  # side-link pivot - bucket pin (arm frame)
    h_constants: FourBarConstants  # the bucket four-bar's, folded (eq. 2)

    @classmethod
    def of(cls, g: Description) -> Linkages:
        """The linkages of a machine description."""
        foot = np.array(g.foot)
        arm_pin = np.array([g.boom_length, 0.0])  # boom frame
        boom_orientation, arm_orientation, bucket_orientation, h_orientation = g.orientations
        boom_base, boom_rod = (np.array(p) for p in g.boom_cylinder_pins)
        arm_base, arm_rod = (np.array(p) for p in g.arm_cylinder_pins)
        bucket_base, pivot, h_pin = (
            np.array(g.bucket_cylinder_base),
            np.array(g.side_link_pivot),
            np.array(g.h_link_pin),
        )
        to_base = bucket_base - pivot
        bucket_pin = np.array([g.arm_length, 0.0])  # arm frame
        b, a, h_phase = float(np.hypot(*h_pin)), g.h_link_length, direction(h_pin)
        return cls(
            boom=Triangle.of("boom_cylinder", boom_base - foot, boom_rod, boom_orientation),
            arm=Triangle.of("arm_cylinder", arm_base - arm_pin, arm_rod, arm_orientation),
            # eq. 1 applied to Fig. 7b: the joint angle's cosine and sine give R relative to the pivot
            side=Triangle(
                "bucket_cylinder",
                float(np.hypot(*to_base)),
                g.side_link_length,
                direction(to_base),
                bucket_orientation,
                radius=g.side_link_length,
            ),
            bucket_pin=bucket_pin,
            pivot=pivot,
            side_link=g.side_link_length,
            h_pin=h_pin,
            h_radius=b,
            h_phase=h_phase,
            h_link=a,
            h_orientation=h_orientation,
            bucket_cylinder_base=bucket_base,
            pivot_from_bucket_pin=tuple((pivot - bucket_pin).tolist()),
            h_constants=FourBarConstants(
                b=b,
                bb=b * b,
                o=float(h_orientation),
                bb_aa=b * b - a * a,
                two_b=2.0 * b,
                cos_phase=math.cos(h_phase) / b,
                sin_phase=math.sin(h_phase) / b,
                phase=h_phase,
            ),
        )
