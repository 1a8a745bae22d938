"""The packed zones of the avoidance zones' compiled check, declared once: what
:class:`manipulator_kinematics.zones.Monitor` packs and :mod:`manipulator_kinematics.zone_kernel`
reads (no numba is imported here).

A monitor's zones are one float64 table, a row per zone in the zone file's order, a column per
:data:`ZONE` field (``kind`` one of :data:`KIND`; a field a kind does not read is 0):

=========  ======================================================================================
kind       fields read
=========  ======================================================================================
plane      ``normal`` (3 columns from it) and ``offset``: clearance n . p + offset (ceilings,
           floors, walls; the margin in the offset, :meth:`manipulator_kinematics.zones.Zone.half_space`)
box        ``centre``, ``half`` (3 columns each), ``margin``
sector     ``start``, ``width`` (ccw, rad), ``margin``
surface    ``origin`` (3 columns), ``sign`` (1: side below, -1: above), ``margin``, ``tin`` (its row
           in the located-triangle table, int32 (TINs, P): matplotlib's point location, -1 off the
           TIN) and ``first`` (its first row in the planes table (triangles, 3) of every TIN's
           [a, b, c], one TIN after the other)
=========  ======================================================================================

and ``site`` 1 for a zone in the site frame (the points placed by the site pose first).

Numba's on-disk cache is keyed on the kernel's own source file, so a kernel compiled for an
older version of this layout would keep its old offsets: the kernel compiles :data:`SIGNATURE`
in and its loader refuses a kernel whose compiled signature differs (:func:`check_compiled`; the
numpy path answers meanwhile).
"""

from __future__ import annotations

import zlib
from types import ModuleType
from typing import NamedTuple

__all__ = ["KIND", "SIGNATURE", "WIDTH", "ZONE", "check_compiled"]


class _Kinds(NamedTuple):
    """The zone kinds as the kernel tells them apart."""

    plane: int
    box: int
    sector: int
    surface: int


class _Fields(NamedTuple):
    """The first column of each field of the zone table (module docstring)."""

    kind: int
    site: int
    normal: int
    offset: int
    centre: int
    half: int
    margin: int
    start: int
    width: int
    origin: int
    sign: int
    tin: int
    first: int


#: Each field's width in columns (the rest have one).
_WIDE = {"normal": 3, "centre": 3, "half": 3, "origin": 3}
_SIZES = [_WIDE.get(name, 1) for name in _Fields._fields]

#: Kind codes (ints; a namedtuple: a compile-time constant to numba).
KIND = _Kinds(*range(len(_Kinds._fields)))
#: First column of each field.
ZONE = _Fields(*(sum(_SIZES[:i]) for i in range(len(_SIZES))))
#: Columns of the zone table.
WIDTH = sum(_SIZES)
#: Changes with any name, order or width above (the compiled kernel's staleness check).
SIGNATURE = zlib.crc32(repr((_Kinds._fields, _Fields._fields, sorted(_WIDE.items()))).encode())


def check_compiled(kernel: ModuleType) -> None:
    """Refuse a kernel module whose compiled code (from numba's cache) was built for another
    layout than this one: RuntimeError saying what to do."""
    if kernel.layout_signature() != SIGNATURE:
        raise RuntimeError(
            f"{kernel.__name__}: numba's cache holds code compiled for another zone layout "
            "(manipulator_kinematics/zone_layout.py changed since): delete the kernel's cache "
            "(__pycache__/zone_kernel.*.nbi, *.nbc beside it) and run scripts/warm_kernels.py"
        )
