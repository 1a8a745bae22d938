"""The packed constants of the excavator's compiled kernels, each layout declared once: the packers
(:class:`excavator_kinematics.core.kinematics.Excavator` for :mod:`.state_kernel`,
:class:`excavator_kinematics.core.inverse.Constants` for :mod:`.ik_kernel`) pack by field name
and the kernels read by field offset, both from here (no numba is imported here).

A kernel reads an offset as ``k[STATE.at.boom + TRIANGLE.at.c0]``: ``at`` is a namedtuple of ints,
a compile-time constant to numba. Numba's on-disk cache (``cache=True``) is keyed on the kernel's
own source file, so a kernel compiled for another layout would keep its old offsets: each kernel
compiles its layout's :attr:`Layout.signature` in, and its loader refuses a kernel whose signature
is not the current one (the numpy path answers; ``scripts/warm_kernels.py`` after clearing the
kernel's cache recompiles it).
"""

from __future__ import annotations

import zlib
from collections import namedtuple
from collections.abc import Mapping
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np


class Layout:
    """Named fields of one float64 array, in order, each of a fixed size."""

    def __init__(self, name: str, sizes: Mapping[str, int]) -> None:
        self.name = name
        self.sizes = dict(sizes)
        offsets, at = [], 0
        for size in self.sizes.values():
            offsets.append(at)
            at += size
        #: Offset of each field (a namedtuple of ints: numba reads it as a constant).
        record: Any = namedtuple(name, list(self.sizes))  # type: ignore[misc]  # names known at run time
        self.at = record(*offsets)
        self.size = at
        #: A number that changes with any field's name, order or size (the kernels' cache check).
        self.signature = zlib.crc32(repr(list(self.sizes.items())).encode())

    @classmethod
    def of(cls, record: Any) -> Layout:
        """The layout of a NamedTuple class of floats: one entry per field, in its order."""
        return cls(record.__name__, dict.fromkeys(record._fields, 1))

    def pack(self, values: Mapping[str, Any]) -> np.ndarray:
        """The fields' values in one float array; a field missing, unknown or of another size is a
        ValueError naming it."""
        missing, unknown = self.sizes.keys() - values.keys(), values.keys() - self.sizes.keys()
        if missing or unknown:
            raise ValueError(f"{self.name}: fields missing {sorted(missing)}, unknown {sorted(unknown)}")
        parts = []
        for field, size in self.sizes.items():
            part = np.asarray(values[field], dtype=float).reshape(-1)
            if part.size != size:
                raise ValueError(f"{self.name}.{field}: {part.size} values, the layout has {size}")
            parts.append(part)
        return np.concatenate(parts)


class TriangleConstants(NamedTuple):
    """A cylinder triangle's constants (eq. 1), folded: cos(gamma) = (a^2 + b^2 - d^2) / (2ab) =
    c0 - c1 d^2 (:class:`excavator_kinematics.core.geometry.Triangle`)."""

    c0: float  # (a^2 + b^2) / (2ab)
    c1: float  # 1 / (2ab)
    ab: float
    o: float  # the orientation, -1.0 or 1.0
    cos_offset: float  # radius cos(offset)
    sin_offset: float  # radius sin(offset)
    offset: float


class FourBarConstants(NamedTuple):
    """The bucket four-bar's constants (eq. 2; :class:`excavator_kinematics.core.geometry.Linkages`):
    the H angle's cosine is (e^2 + b^2 - a^2) / (2 b e) (law of cosines, e = |R - bucket pin|, b
    the H-link pin's radius about the bucket pin, a the H-link); cos and sin of the H phase over b
    turn (H - bucket pin) back to the bucket direction (cos, sin theta4)."""

    b: float
    bb: float  # b^2
    o: float  # the orientation, -1.0 or 1.0
    bb_aa: float  # b^2 - a^2
    two_b: float
    cos_phase: float  # cos(H phase) / b
    sin_phase: float  # sin(H phase) / b
    phase: float  # the H-link pin's direction in the bucket frame


TRIANGLE = Layout.of(TriangleConstants)
FOUR_BAR = Layout.of(FourBarConstants)

#: The state kernel's constants (``Excavator.packed``): the link lengths, the boom, arm and
#: side-link triangles, the side-link pivot from the bucket pin (arm frame), the bucket four-bar,
#: and D's limits widened by the stroke tolerance.
STATE = Layout(
    "StateLayout",
    {
        "l0": 1,
        "l1": 1,
        "l2": 1,
        "l3": 1,
        "l4": 1,
        "boom": TRIANGLE.size,
        "arm": TRIANGLE.size,
        "side": TRIANGLE.size,
        "pivot_from_bucket_pin": 2,
        "four_bar": FOUR_BAR.size,
        "lower": 4,
        "upper": 4,
    },
)

#: The IK kernel's constants (``inverse.Constants.packed``): the float fields of
#: :class:`~excavator_kinematics.core.inverse.Constants` it reads, D's limits widened by the
#: status tolerance, the seed weights and the strokes' ends.
IK = Layout(
    "IKLayout",
    {
        **dict.fromkeys(
            (
                "l0",
                "l1",
                "l2",
                "l3",
                "l4",
                "l2l2_l3l3",
                "two_l2l3",
                "reach_max",
                "reach_min",
                "boom_o",
                "boom_offset",
                "boom_aa_bb",
                "boom_two_ab",
                "arm_o",
                "arm_offset",
                "arm_aa_bb",
                "arm_two_ab",
                "h_phase",
                "h_radius",
                "pin_from_pivot_x",
                "pin_from_pivot_y",
                "base_from_pivot_x",
                "base_from_pivot_y",
                "side",
                "side_hh",
                "two_side",
                "side_o",
                "h_o",
                "stroke_lo",
                "stroke_hi",
            ),
            1,
        ),
        "lower": 4,
        "upper": 4,
        "weights": 4,
        "stroke_min": 3,
        "stroke_max": 3,
    },
)


def check_compiled(kernel: ModuleType) -> None:
    """Refuse a kernel module whose compiled code (from numba's cache) was built for other layouts
    than the ones it imports now (module docstring): RuntimeError saying what to do."""
    if kernel.layout_signature() != kernel.LAYOUT_SIGNATURE:
        raise RuntimeError(
            f"{kernel.__name__}: numba's cache holds code compiled for another packed layout "
            "(excavator_kinematics/core/layouts.py changed since): delete the kernel's cache "
            "(__pycache__/*.nbi, *.nbc beside it) and run scripts/warm_kernels.py"
        )
