"""The packed plan of a hydraulic-family machine, declared once: what
:mod:`manipulator_kinematics.hydraulic.program` packs and :mod:`manipulator_kinematics.hydraulic.kernel`
reads (no numba is imported here).

A machine's plan (:class:`~manipulator_kinematics.hydraulic.description.Description`: dyads,
placements, slides, then the main chain's joints and the task vector, paper eqs. 1-3) becomes a
program of instructions, one row each in two arrays of equal length: ``code`` (int64, one column
per :data:`INT` field) and ``values`` (float64, one column per :data:`FLOAT` field). Every
instruction writes one *slot* of the kernel's work array: a jet (position, velocity,
acceleration, Jacobian d/dD; a point fills both components, a scalar the first).

Row 0 is the :data:`OP` ``head``: ``out`` the number of slots, ``p`` the first of the n + nq
result slots (theta, then Q: consecutive), ``act`` n, ``q`` nq, ``act2`` m. Rows 1..m are ``limit`` rows,
one per actuator in D's order (``x``, ``z``: its stroke box). The rest, in solve order:

=========  ======================================================================================
op         fields read (``out`` is the slot written)
=========  ======================================================================================
fixed      ``x``, ``z``: a constant point (a ground pin; (0, 0) for the ground's origin, angle)
actuator   ``act``: the jet of D[act] + ``length`` (the swing, a prismatic joint d = s + offset)
dyad       pins ``p`` (A), ``q`` (B); radii: D[``act``] (``act`` >= 0, ``length`` 0) or ``length``,
           D[``act2``] or ``length2`` alike; ``sign`` the branch (eqs. 1-2,
           :mod:`~manipulator_kinematics.hydraulic.dyads`)
place      pins ``p``, ``q`` (one, two); ``angle`` the body's angle slot (written too: its cos
           and sin); (``x``, ``z``) the body's local of ``p``; ``cos``, ``sin`` those of the
           direction of (local two - local one) in the body
point      body origin ``p``, body angle ``angle``; (``x``, ``z``) the point's local
slide      parent origin ``p``, parent angle ``angle``, stroke D[``act``] + ``length`` along the
           parent's x axis from (``x``, ``z``)
angle      theta = angle ``p`` - angle ``q`` in (-pi, pi] (a revolute joint: child minus parent)
task       x, y, z of Q into ``out``.. ``out`` + 2 from the tool point ``p``, turned by the swing
           D[``act``] (``act`` < 0: no swing)
add        slot ``out`` += slot ``p`` (alpha: the revolute joints' sum)
=========  ======================================================================================

The monitored points (:meth:`~manipulator_kinematics.hydraulic.model.HydraulicModel.monitored_motion`,
the avoidance zones') have a program of their own, in which every pin is made, then the tool
outline's points (``point``) and the tail's (``fixed``, at (-radius, height)), and a point table
(int64, one column per :data:`POINT` field, one row per point in the names' order): ``slot`` the
boom-plane point's slot, ``side`` 0 on the boom plane, 1 or -1 half the tool width to the left or
right of it (the tool corners, the outline's side faces).

Numba's on-disk cache is keyed on the kernel's own source file, so a kernel compiled for an
older version of this layout would keep its old constants: the kernel compiles
:data:`SIGNATURE` in and its loader refuses a kernel whose compiled signature differs
(:func:`check_compiled`; the numpy path answers meanwhile).
"""

from __future__ import annotations

import zlib
from types import ModuleType
from typing import NamedTuple

__all__ = ["FLOAT", "INT", "OP", "POINT", "SIGNATURE", "check_compiled"]


class _Ops(NamedTuple):
    """The instruction codes (module docstring)."""

    head: int
    limit: int
    fixed: int
    actuator: int
    dyad: int
    place: int
    point: int
    slide: int
    angle: int
    task: int
    add: int


class _Ints(NamedTuple):
    """The fields of ``code``, one column each."""

    op: int
    out: int
    p: int
    q: int
    angle: int
    act: int
    act2: int


class _Floats(NamedTuple):
    """The fields of ``values``, one column each."""

    x: int
    z: int
    length: int
    length2: int
    sign: int
    cos: int
    sin: int


class _Points(NamedTuple):
    """The fields of a monitored-point table, one column each (module docstring)."""

    slot: int
    side: int


#: Instruction codes (ints; a namedtuple: a compile-time constant to numba).
OP = _Ops(*range(len(_Ops._fields)))
#: Column of each field in ``code`` (int64).
INT = _Ints(*range(len(_Ints._fields)))
#: Column of each field in ``values`` (float64).
FLOAT = _Floats(*range(len(_Floats._fields)))
#: Column of each field in a monitored-point table (int64).
POINT = _Points(*range(len(_Points._fields)))
#: Changes with any name or order above (the compiled kernel's staleness check).
SIGNATURE = zlib.crc32(repr((_Ops._fields, _Ints._fields, _Floats._fields, _Points._fields)).encode())


def check_compiled(kernel: ModuleType) -> None:
    """Refuse a kernel module whose compiled code (from numba's cache) was built for another
    layout than this one: RuntimeError saying what to do."""
    if kernel.layout_signature() != SIGNATURE:
        raise RuntimeError(
            f"{kernel.__name__}: numba's cache holds code compiled for another program layout "
            "(manipulator_kinematics/hydraulic/layout.py changed since): delete the kernel's cache "
            "(__pycache__/kernel.*.nbi, *.nbc beside it) and run scripts/warm_kernels.py"
        )
