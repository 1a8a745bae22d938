"""The region table of the pump boom's IK (paper 001, section 2.2), as data.

The vertical pour plane (r, z) of the boom (r horizontal from the slew axis, z up from the
ground) is cut into squares. The paper's squares have side ``size`` with corners on the grid
``origin + size * (i, j)``; a square that no single triple serves is split into four, and so on
(a quadtree of the paper's method): square (i, j) of level l has side s_l = size / 2^l and spans
r in [r0 + i s_l, r0 + (i + 1) s_l], z in [z0 + j s_l, z0 + (j + 1) s_l]. Squares are closed:
a point on an edge or a corner belongs to every square that contains it (within ``EDGE`` m), so
the covered area is the union of the closed squares. Each square holds one triple
(theta2, theta3, theta4) (rad, paper convention) for which the last two sections reach every
point of the square inside the joint limits in positive-envelope shape.

Transition bands (section 2.2, step 3), for squares of any size: the triple at a point is the
mean of the piecewise-constant triple field over the covered part of a window of side ``band``
centred on the point (each square weighs the area it shares with the window). On a grid of equal
squares this is exactly the partition of unity of the paper's bands: along r the window's
share of square column k is ramp(u - k) - ramp(u - k - 1) with ramp(x) = clip((x + h) / 2h, 0, 1),
h = band / (2 s) (likewise along z), the product of the two for square (k, l). Where the window
lies inside the point's own square (more than band / 2 from its edges) the triple is the
square's own, unchanged; across a band it changes linearly, and by at most (the spread of the
triples under the window) / band per metre whatever the squares' sizes; missing squares drop out
(the mean is over the covered part only), so a square next to a gap keeps its own triple up to
the edge; squares of another shape family than the point's own square drop out the same way
(:func:`family`: sections folded back or not; a blend of the two is a shape of neither; the
builder keeps them from touching). The window mean is summed over the cells of the finest
squares under the window (at most 8 x 8 for a 1 m band on 0.156 m cells), each weighing the
window's length in it along r times that along z: exact for a piecewise-constant field, and
where every square of its family under the window holds the point's own triple, that triple
unchanged.

The table file (``config/pump_boom_regions.yaml``, a ROS parameters file) is written by
``pump_boom_regions`` (:mod:`.build_regions`) and records the geometry it was built for; loading
it for another geometry is an error (the boom then solves FK but no region IK).
"""

from __future__ import annotations

import base64
import binascii
import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike

from manipulator_kinematics.param_files import load_parameters, shown
from manipulator_kinematics.row_blocks import in_blocks
from manipulator_kinematics.schema import ConfigError, Number, Numbers, Text, require, validate

#: Section of the table file under ``/**: ros__parameters``.
TABLE_SECTION = "pump_boom_regions"

#: What a table file holds (the geometry it was built for, its grid, its squares, its coverage).
TABLE_SCHEMA = {
    "built_for": {
        "root": Numbers(2, Number(min=-100.0, max=100.0, unit="m")),
        "lengths": Numbers(5, Number(min=0.0, max=100.0, unit="m")),
        "joint_min": Numbers(6),
        "joint_max": Numbers(6),
        "origin": Numbers(2, Number(min=-100.0, max=100.0, unit="m")),
        "size": Number(min=0.0, max=100.0, unit="m"),
        "band": Number(min=0.0, max=100.0, unit="m"),
    },
    "search": {
        "step_deg": Number(min=0.1, max=30.0, unit="deg"),
        "min_margin": Number(min=0.0, max=10.0, unit="m"),
        "check_spacing": Number(min=0.01, max=5.0, unit="m"),
        "max_step": Number(min=0.0, max=math.pi, unit="rad"),
        "start": Numbers(2, Number(min=-1000, max=1000, integer=True)),
        "levels": Number(min=0, max=12, integer=True),
        "min_theta3": Number(min=0.0, max=2 * math.pi, unit="rad", default=0.0),
        # Tables from before this key had no fold rule (folded shapes wherever min_theta3 allowed): 1000 m.
        "fold_width": Number(min=0.0, max=1000.0, unit="m", default=1000.0),
    },
    "squares": Text(
        doc="base64 of the squares, little-endian: column, row (int32), level (uint8), "
        "theta2 theta3 theta4 (rad, float64), margin (m, float32)"
    ),
    "coverage": {
        "squares": Number(min=0, integer=True),
        "covered_area": Number(min=0.0, unit="m^2"),
        "reachable_area": Number(min=0.0, unit="m^2"),
        "envelope_area": Number(min=0.0, unit="m^2"),
        "covered_share": Number(min=0.0, max=1.0),
        "raster_cell": Number(min=0.0, unit="m"),
        "raster_samples": Number(min=0, integer=True),
        "band_failures": Number(min=0, integer=True),
        "checked_points": Number(min=0, integer=True),
        "largest_step": Number(min=0.0, unit="rad"),
    },
}


#: A square in the table file's ``squares``: (i, j, level), its triple (rad) and its margin (m),
#: packed little-endian (37 bytes), the squares' bytes deflated (zlib, level 9) and in base64
#: (lines of SQUARE_LINE characters): exact. Deflated because libyaml's scan of the block was most
#: of the load: for 2470 squares 122 KB of base64 took it 1.4 ms, the 31 KB of the deflated bytes
#: 0.4 ms, and inflating them 0.25 ms. As text, 7 numbers a square, Python took 1.5-2.3 ms to read
#: 1500 squares and libyaml 1.5 ms more for the listing in the comments;
#: ``pump_boom_regions --list`` prints that listing.
SQUARE_DTYPE = np.dtype(
    [("column", "<i4"), ("row", "<i4"), ("level", "u1"), ("triple", "<f8", 3), ("margin", "<f4")]
)
SQUARE_LINE = 100
INDEX_RANGE = 100_000  # |column|, |row| at most this
MAX_LEVEL = 12
MAX_SQUARES = 1_000_000
MAX_CELLS = 1 << 24  # the lookup raster's cells (int32: 64 MB); the shipped table's: 138,240

#: A point this close (m) to a square's edge lies on it (closed squares, see the module docstring).
EDGE = 1e-9

#: rad: a section whose unfolding angle is below this is folded back onto the one before it (the
#: shape families of :func:`family`).
FOLDED = math.radians(15.0)


def family(triples: ArrayLike) -> np.ndarray:
    """The shape family (...,) of triples (..., 3): 1 if section 2 is folded back onto section 1
    (theta3 < FOLDED), plus 2 if section 3 is folded back onto section 2 (theta4 < FOLDED), else 0.
    Between the families no shape keeps the envelope within the joint limits near the truck (no
    theta3 in 15-90 deg reaches the points above the root pin in positive envelope), so the band
    never blends squares of two families: a blend of a folded and an unfolded shape is neither."""
    t = np.asarray(triples, dtype=float)
    return (t[..., 1] < FOLDED).astype(np.int8) + 2 * (t[..., 2] < FOLDED).astype(np.int8)


@dataclass(frozen=True)
class Grid:
    """The square grid of the pour plane: corner ``origin`` (r0, z0) m, side ``size`` m of the
    level-0 squares, transition band ``band`` m (the side of the blending window)."""

    origin: tuple[float, float]
    size: float
    band: float

    def __post_init__(self) -> None:
        if not (self.size > 0.0 and 0.0 < self.band < self.size):
            raise ValueError(f"need size > 0 and 0 < band < size, got size {self.size}, band {self.band}")

    def side(self, level: ArrayLike = 0) -> np.ndarray:
        """Side (m) of the squares of ``level``: size / 2^level."""
        return self.size / 2.0 ** np.asarray(level)

    def corner(self, i: ArrayLike, j: ArrayLike, level: ArrayLike = 0) -> tuple[np.ndarray, np.ndarray]:
        """Lower-left corner (r, z) of squares (i, j) of ``level``."""
        side = self.side(level)
        return (self.origin[0] + np.asarray(i) * side, self.origin[1] + np.asarray(j) * side)

    def square(self, r: float, z: float) -> tuple[int, int]:
        """Level-0 square (i, j) whose half-open extent holds the finite point (r, z)."""
        return (math.floor((r - self.origin[0]) / self.size), math.floor((z - self.origin[1]) / self.size))


@dataclass(frozen=True)
class RegionTable:
    """Squares (i, j, level) with their triples (theta2, theta3, theta4) and the geometry they fit."""

    grid: Grid
    index: np.ndarray  # (m, 3) int: column i, row j, level l (side size / 2^l)
    triples: np.ndarray  # (m, 3) rad
    margin: np.ndarray  # (m,) m: the smallest clearance of the square's check (see build_regions)
    built_for: Mapping[str, Any]
    search: Mapping[str, Any]
    coverage: Mapping[str, Any]

    def __post_init__(self) -> None:
        index = np.asarray(self.index, dtype=int).reshape(-1, 3)
        triples = np.asarray(self.triples, dtype=float).reshape(-1, 3)
        object.__setattr__(self, "index", index)
        object.__setattr__(self, "triples", triples)
        object.__setattr__(self, "margin", np.asarray(self.margin, dtype=float).reshape(-1))
        if np.any(index[:, 2] < 0):
            raise ValueError("region table: a square level is negative")
        depth = int(index[:, 2].max()) if len(index) else 0
        cell = self.grid.size / 2**depth  # the finest squares' side: the cells of the lookup arrays
        scale = 2 ** (depth - index[:, 2])
        # The lookup arrays span whole level-0 squares (lower0: the first one's (i, j)). Cell ->
        # the square covering it: level by level, the raster seen as blocks of the level's side
        # (a reshaped view) and the level's squares written on their blocks: 0.7 ms for 2470
        # squares; the raster split into four level by level (np.repeat) took 0.8 ms, the cells
        # of each square drawn at once 0.9 ms (1598 squares).
        top = index[:, :2] >> index[:, 2:]  # the level-0 square holding each square (floor)
        lower0 = top.min(axis=0) if len(index) else np.zeros(2, dtype=int)
        rows, columns = ((top.max(axis=0) - lower0 + 1) << depth).tolist() if len(index) else (0, 0)
        if rows * columns > MAX_CELLS:  # squares far apart, or a deep level: refused, not a MemoryError
            raise ValueError(
                f"region table: the squares span {rows} x {columns} cells of {cell:g} m, "
                f"more than {MAX_CELLS} (columns or rows far apart, or levels too deep)"
            )
        owner = np.full((rows, columns), -1, dtype=np.int32)
        for level in range(depth + 1):
            side = 1 << (depth - level)
            blocks = owner.reshape(rows // side, side, columns // side, side)
            k = np.flatnonzero(index[:, 2] == level)
            i, j = (index[k, :2] - (lower0 << level)).T
            blocks[i, :, j, :] = k[:, None, None]
        lower = lower0 << depth
        low = index[:, :2] * scale[:, None] - lower
        if np.count_nonzero(owner >= 0) != int(np.sum(scale**2)):  # a cell claimed twice
            a, b = _overlap(low, scale, owner.shape)
            raise ValueError(
                f"region table: square {tuple(index[a].tolist())} overlaps square {tuple(index[b].tolist())}"
            )
        # Per square (triple, 1), and a row of zeros for the cells of no square (owner -1): the
        # window sums of the blend; per square its family, -1 for no square.
        values = np.zeros((len(index) + 1, 4))
        values[:-1, :3], values[:-1, 3] = triples, 1.0
        families = np.append(family(triples), -1).astype(np.intp)
        object.__setattr__(self, "_cell", cell)
        object.__setattr__(self, "_lower", lower)
        object.__setattr__(self, "_owner", owner)
        object.__setattr__(self, "_values", values)
        object.__setattr__(self, "_family", families)
        object.__setattr__(self, "_bounds", np.concatenate([low, low + scale[:, None]], axis=1).astype(float))

    # Built on first use, not at load: the squares' extents of the nearest covered point.
    # functools.cached_property: Python 3.11's holds a lock while it builds; from 3.12 two threads
    # (a node's executor) may both build one, and both get the same array.
    @cached_property
    def extent(self) -> np.ndarray:
        """Per square its extent (m, 4) (r low, z low, r high, z high) m, for :meth:`nearest`."""
        side = self.grid.side(self.index[:, 2])
        corner = np.stack(
            self.grid.corner(self.index[:, 0], self.index[:, 1], self.index[:, 2]), axis=-1
        ).reshape(-1, 2)
        return np.concatenate([corner, corner + side[:, None]], axis=1)

    def __len__(self) -> int:
        return len(self.index)

    @property
    def covered_area(self) -> float:
        """Area (m^2) of the union of the squares."""
        return float(np.sum(self.grid.side(self.index[:, 2]) ** 2))

    def _cells(self, r: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Plane points in cells of the lookup arrays (cell (a, b) is [a, a + 1) x [b, b + 1))."""
        r, z = np.broadcast_arrays(np.asarray(r, dtype=float), np.asarray(z, dtype=float))
        return (
            (r - self.grid.origin[0]) / self._cell - self._lower[0],
            (z - self.grid.origin[1]) / self._cell - self._lower[1],
        )

    def owner(self, r: ArrayLike, z: ArrayLike) -> np.ndarray:
        """(...,) row of the table of a square holding each point, -1 where none (NaN: -1). On an
        edge (within EDGE) the square above/right of it if covered, else the one below/left."""
        u, v = self._cells(r, z)
        finite = np.isfinite(u) & np.isfinite(v)
        u, v = np.where(finite, u, -1.0), np.where(finite, v, -1.0)
        edge = EDGE / self._cell
        found = np.full(u.shape, -1, dtype=np.int32)
        for b in (np.floor(v + edge), np.floor(v - edge)):
            for a in (np.floor(u + edge), np.floor(u - edge)):
                hit = (a >= 0) & (a < self._owner.shape[0]) & (b >= 0) & (b < self._owner.shape[1])
                if not hit.any():
                    continue
                k = self._owner[np.where(hit, a, 0).astype(int), np.where(hit, b, 0).astype(int)]
                found = np.where((found < 0) & hit, k, found)
        return found

    def contains(self, r: ArrayLike, z: ArrayLike) -> np.ndarray:
        """(...,) True where the point lies in a square of the table (edges included; NaN: False)."""
        return self.owner(r, z) >= 0

    def square(self, r: ArrayLike, z: ArrayLike) -> np.ndarray:
        """(..., 3) (i, j, level) of the square holding each point (:meth:`owner`); -1 outside."""
        k = self.owner(r, z)
        return np.where((k >= 0)[..., None], self.index[np.maximum(k, 0)] if len(self) else -1, -1)

    def own_triple(self, r: ArrayLike, z: ArrayLike) -> np.ndarray:
        """The triple of the point's own square (..., 3), no blending; NaN outside the table."""
        k = self.owner(r, z)
        return np.where((k >= 0)[..., None], self.triples[np.maximum(k, 0)] if len(self) else np.nan, np.nan)

    def blend(self, r: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The triple (..., 3) at plane points (section 2.2 step 3; module docstring) and
        ``inside`` (...,): NaN triples where the point is in no square of the table."""
        u, v = self._cells(r, z)
        k = self.owner(r, z)
        inside = k >= 0
        if not len(self):
            return np.full(u.shape + (3,), np.nan), inside
        k = np.maximum(k, 0)
        half = 0.5 * self.grid.band / self._cell
        low_u, low_v, high_u, high_v = np.moveaxis(self._bounds[k], -1, 0)
        core = (u - half >= low_u) & (u + half <= high_u) & (v - half >= low_v) & (v + half <= high_v)
        triple = self.triples[k.reshape(-1)]  # a copy (an index of one point would be a view)
        band = np.flatnonzero(inside & ~core)
        if len(band):  # points in a band: the window mean, in blocks (its cells' temporaries)
            triple[band] = in_blocks(
                self._window_mean, u.reshape(-1)[band], v.reshape(-1)[band], k.reshape(-1)[band], block=1024
            )
        return np.where(inside[..., None], triple.reshape(u.shape + (3,)), np.nan), inside

    def _window_mean(self, u: np.ndarray, v: np.ndarray, own: np.ndarray) -> np.ndarray:
        """The mean (n, 3) of the triple field over the covered part of the band windows centred
        on the points (n,) in cells (module docstring), in the squares of rows ``own`` (n,): the
        sum over the cells under the window of the window's length in the cell along r times that
        along z times (triple, 1) of the cell's square if it is of the family of the point's own
        (:func:`family`; the others drop out like missing squares); the square's own triple where
        every square of its family under the window holds it."""
        half = 0.5 * self.grid.band / self._cell
        span = math.ceil(2.0 * half) + 1  # cells a window covers along an axis, at most
        cells, lengths = [], []
        for x, n in zip((u, v), self._owner.shape):
            first = np.floor(x - half)[:, None] + np.arange(span)  # (n, span)
            length = np.minimum(x[:, None] + half, first + 1.0) - np.maximum(x[:, None] - half, first)
            outside = (first < 0) | (first >= n)
            cells.append(np.where(outside, 0, first).astype(np.intp))
            lengths.append(np.where(outside, 0.0, np.maximum(length, 0.0)))
        weight = (lengths[0][:, :, None] * lengths[1][:, None, :]).reshape(len(u), -1)  # (n, span^2)
        flat = (cells[0][:, :, None] * self._owner.shape[1] + cells[1][:, None, :]).reshape(len(u), -1)
        owner = self._owner.reshape(-1)[flat]
        owner = np.where((weight > 0.0) & (self._family[owner] == self._family[own][:, None]), owner, -1)
        total = (weight[:, None, :] @ self._values[owner])[:, 0]  # (n, 4); owner -1: the row of zeros
        ids = self._triple_ids
        same = ((owner < 0) | (ids[owner] == ids[own][:, None])).all(axis=1)
        return np.where(same[:, None], self.triples[own], total[:, :3] / total[:, 3:])

    @cached_property
    def _triple_ids(self) -> np.ndarray:
        """(m + 1,) per square a number of its triple (equal triples, equal numbers), -1 last (the
        cells of no square): built by the first blend in a band. (Not np.unique: its first call
        in a process imports numpy.ma, 20 ms.)"""
        order = np.lexsort(self.triples.T[::-1])
        ordered = self.triples[order]
        new = np.ones(len(order), dtype=bool)
        new[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
        ids = np.full(len(order) + 1, -1, dtype=np.intp)
        ids[order] = np.cumsum(new) - 1
        return ids

    @property
    def lookup(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lookup arrays of :meth:`owner` and :meth:`blend` for the compiled single-point IK
        (:mod:`.ik_kernel`): the constants (grid origin r, z; the cell; the arrays' lower cell
        column, row; half the band and EDGE in cells), the cell owners (int32) and per square its
        bounds in cells, its triple and its family (m, 8)."""
        constants = np.array(
            [
                *self.grid.origin,
                self._cell,
                *self._lower,
                0.5 * self.grid.band / self._cell,
                EDGE / self._cell,
            ],
            dtype=float,
        )
        return (
            constants,
            self._owner,
            np.concatenate([self._bounds, self.triples, self._family[:-1, None]], axis=1),
        )

    def random_lines(
        self, count: int, rng: np.random.Generator, steps: int = 40, step: float = 0.1
    ) -> np.ndarray:
        """Straight lines (k, steps + 1, 2) of (r, z) points ``step`` apart inside the covered area:
        of ``count`` lines in random directions, half starting in squares drawn by count (mostly
        the small squares at the rim), half by area, the k that stay inside (continuity checks)."""
        side = self.grid.side(self.index[:, 2])
        rows = np.concatenate(
            [
                rng.integers(0, len(self), count // 2),
                rng.choice(len(self), count - count // 2, p=side**2 / np.sum(side**2)),
            ]
        )
        corner = np.stack(self.grid.corner(*self.index[rows].T), axis=-1)
        start = corner + side[rows, None] * rng.random((count, 2))
        angle = rng.uniform(0.0, 2.0 * math.pi, count)
        direction = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
        lines = start[:, None] + step * np.arange(steps + 1)[None, :, None] * direction[:, None]
        return lines[self.contains(lines[..., 0], lines[..., 1]).all(axis=1)]

    def nearest(self, r: float, z: float) -> tuple[float, float]:
        """The point of the covered area nearest to the finite plane point (r, z) (m)."""
        extent = self.extent
        closest = np.clip([r, z], extent[:, :2], extent[:, 2:])
        k = int(np.argmin(np.hypot(closest[:, 0] - r, closest[:, 1] - z)))
        return float(closest[k, 0]), float(closest[k, 1])

    # ---- file ---------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path, expected: Mapping[str, Any] | None = None) -> RegionTable:
        """Read a table file; with ``expected`` (the ``built_for`` values of the machine using
        it) a table built for another geometry or grid raises ConfigError naming the key."""
        params = load_parameters(path)
        if TABLE_SECTION not in params:
            raise ConfigError(f"{path}: no {TABLE_SECTION!r} section under /**: ros__parameters")
        p = validate(params[TABLE_SECTION], TABLE_SCHEMA, TABLE_SECTION)
        squares = decode_squares(p["squares"], f"{TABLE_SECTION}.squares")
        built = p["built_for"]
        if expected is not None:
            for key, value in expected.items():
                have = np.asarray(built[key], dtype=float)
                # Within 1e-9 m or rad (np.allclose took 4 times as long, a tenth of the load).
                close = have.shape == np.shape(value) and np.max(np.abs(have - value), initial=0.0) <= 1e-9
                require(
                    close,
                    f"{TABLE_SECTION}.built_for.{key}",
                    f"the table in {path} was built for {built[key]}, the machine has {value}",
                )
        grid = Grid(tuple(built["origin"]), built["size"], built["band"])
        try:
            return cls(
                grid=grid,
                index=np.stack([squares["column"], squares["row"], squares["level"]], axis=-1),
                triples=squares["triple"],
                margin=squares["margin"],
                built_for=built,
                search=p["search"],
                coverage=p["coverage"],
            )
        except ValueError as error:  # overlapping squares, too large a raster
            raise ConfigError(f"{TABLE_SECTION}.squares: {error}") from None

    def dump(self, path: str | Path, header: Sequence[str] = ()) -> None:
        """Write the table as a ROS parameters file (deterministic: same table, same bytes)."""
        section = {
            "built_for": {k: _plain(v) for k, v in self.built_for.items()},
            "search": {k: _plain(v) for k, v in self.search.items()},
            "coverage": {k: _plain(v) for k, v in self.coverage.items()},
        }
        text = "".join(f"# {line}\n" if line else "#\n" for line in header)
        text += yaml.safe_dump(
            {"/**": {"ros__parameters": {TABLE_SECTION: section}}},
            default_flow_style=None,
            sort_keys=False,
            width=100,
        )
        # The squares last, as a literal block (its lines indented under the section's keys).
        squares = np.empty(len(self), dtype=SQUARE_DTYPE)
        squares["column"], squares["row"], squares["level"] = self.index.T
        squares["triple"], squares["margin"] = self.triples, self.margin
        encoded = base64.b64encode(zlib.compress(squares.tobytes(), 9)).decode("ascii")
        text += (
            f"      squares: |  # base64 of zlib: {', '.join(SQUARE_DTYPE.names)} "
            "(pump_boom_regions --list)\n"
        )
        for start in range(0, len(encoded), SQUARE_LINE):
            text += f"        {encoded[start : start + SQUARE_LINE]}\n"
        Path(path).write_text(text, encoding="utf-8")

    def listing(self) -> list[str]:
        """The squares as a person reads them: a line each with its extent in r and z (m), its
        triple (deg) and its margin (m), after a line of column titles."""
        lines = [
            "square (i, j, level)  r from, to (m)    z from, to (m)    theta2  theta3  theta4 (deg)"
            "  margin (m)"
        ]
        degrees = np.degrees(self.triples).tolist()
        for (i, j, level), t, m in zip(self.index.tolist(), degrees, self.margin.tolist()):
            r, z = (float(c) for c in self.grid.corner(i, j, level))
            s = float(self.grid.side(level))
            lines.append(
                f"({i:4d}, {j:4d}, {level})     {r:7.3f} {r + s:7.3f}  {z:8.3f} {z + s:8.3f}"
                f"  {t[0]:6.1f}  {t[1]:6.1f}  {t[2]:6.1f}       {m:.3f}"
            )
        return lines


def _overlap(low: np.ndarray, scale: np.ndarray, shape: tuple[int, int]) -> tuple[int, int]:
    """Rows of two squares sharing a cell (squares' lower cells ``low``, sides ``scale`` cells):
    of the first cell claimed twice, the squares' cells taken level by level, the first two
    squares claiming it. Only for the error: the load counts the cells claimed."""
    cells, rows = [], []
    for n in np.unique(scale).tolist():
        k = np.flatnonzero(scale == n)
        offset = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), axis=-1).reshape(-1, 2)
        at = low[k][:, None, :] + offset[None]
        cells.append((at[..., 0] * shape[1] + at[..., 1]).ravel())
        rows.append(np.repeat(k, len(offset)))
    cells, rows = np.concatenate(cells), np.concatenate(rows)
    count = np.bincount(cells, minlength=int(np.prod(shape)))
    clash = np.flatnonzero(count[cells] > 1)
    first, other = rows[clash[cells[clash] == cells[clash[0]]]][:2]
    return int(first), int(other)


def decode_squares(text: str, key: str) -> np.ndarray:
    """The squares (m,) (SQUARE_DTYPE) of a table file's ``squares``; ConfigError names the key and
    the first bad square."""
    inflate = zlib.decompressobj()
    try:
        # At most MAX_SQUARES squares: a few KB of deflated zeros would inflate to gigabytes.
        data = inflate.decompress(
            binascii.a2b_base64(text.replace("\n", ""), strict_mode=True), MAX_SQUARES * SQUARE_DTYPE.itemsize
        )  # base64.b64decode: a regex
        if inflate.unconsumed_tail:
            raise ConfigError(f"{key}: more than {MAX_SQUARES} squares")
        if not inflate.eof:
            raise zlib.error("the stream is cut short")
    except (binascii.Error, zlib.error):
        data = b"?"  # not base64 of a whole zlib stream (a table of an older version: text, or not deflated)
    if len(data) % SQUARE_DTYPE.itemsize:
        raise ConfigError(
            f"{key}: expected base64 of the zlib-deflated squares of {SQUARE_DTYPE.itemsize} bytes "
            f"({', '.join(SQUARE_DTYPE.names)}), got {shown(text)}; a table from an older version: "
            "rebuild it with pump_boom_regions"
        )
    squares = np.frombuffer(data, dtype=SQUARE_DTYPE)
    bad = ~np.isfinite(squares["triple"]).all(axis=1) | ~np.isfinite(squares["margin"])
    bad |= (np.abs(squares["column"]) > INDEX_RANGE) | (np.abs(squares["row"]) > INDEX_RANGE)
    bad |= squares["level"] > MAX_LEVEL
    if bad.any():
        n = int(np.argmax(bad))
        raise ConfigError(
            f"{key}, square {n + 1}: need finite numbers, column and row within +-{INDEX_RANGE} and a level "
            f"in [0, {MAX_LEVEL}], got {squares[n]}"
        )
    return squares


def _plain(value: Any) -> Any:
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(value)
