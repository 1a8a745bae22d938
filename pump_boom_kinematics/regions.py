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
the edge. The window mean is evaluated from a summed-area table of the field on the finest
squares' cells (four bilinear look-ups, exact for a piecewise-constant field), so a band costs
the same for any number of small squares under the window.

The table file (``config/pump_boom_regions.yaml``, a ROS parameters file) is written by
``pump_boom_regions`` (:mod:`.build_regions`) and records the geometry it was built for; loading
it for another geometry is an error (the boom then solves FK but no region IK).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike

from manipulator_kinematics.config import ConfigError, Number, Numbers, Text, require, validate
from manipulator_kinematics.params import load_parameters, shown

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
    "squares": Text(doc="one line per square: column row level theta2 theta3 theta4 (rad) margin (m)"),
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


#: The columns of a line of the table file's ``squares`` text: the square (i, j, level), its triple
#: (rad) and its margin (m). One text block rather than seven lists of numbers: a YAML parser builds
#: each list item as a Python object (150 ms for 1500 squares), a block is one string (2 ms).
SQUARE_COLUMNS = ("column", "row", "level", "theta2", "theta3", "theta4", "margin")
INDEX_RANGE = 100_000  # |column|, |row| at most this
MAX_LEVEL = 12

#: A point this close (m) to a square's edge lies on it (closed squares, see the module docstring).
EDGE = 1e-9


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
        low = index[:, :2] * scale[:, None]
        high = low + scale[:, None]
        lower = low.min(axis=0) if len(index) else np.zeros(2, dtype=int)
        shape = tuple((high.max(axis=0) - lower).tolist()) if len(index) else (0, 0)
        # cell -> the square covering it, level by level (the squares of a level all span n x n
        # cells): one broadcast assignment per level, 0.5 ms for 1460 squares. (Not np.unique:
        # its first call in a process imports numpy.ma, 20 ms.)
        owner = np.full(shape, -1, dtype=np.int32)
        for n in sorted(set(scale.tolist())):
            k = np.flatnonzero(scale == n)
            span = np.arange(n)
            owner[(low[k, 0] - lower[0])[:, None, None] + span[:, None],
                  (low[k, 1] - lower[1])[:, None, None] + span] = k[:, None, None]
        if np.count_nonzero(owner >= 0) != int(np.sum(scale**2)):  # a cell claimed twice
            a, b = _overlap(low - lower, scale, shape)
            raise ValueError(f"region table: square {tuple(index[a].tolist())} overlaps square "
                             f"{tuple(index[b].tolist())}")
        object.__setattr__(self, "_cell", cell)
        object.__setattr__(self, "_lower", lower)
        object.__setattr__(self, "_owner", owner)
        object.__setattr__(self, "_bounds", np.concatenate([low - lower, high - lower], axis=1).astype(float))

    # Built on first use, not at load (the load is the file and the cell owners): the tables of
    # the blend in the transition bands and of the nearest covered point. functools.cached_property:
    # Python 3.11's holds a lock while it builds; from 3.12 two threads (a node's executor) may both
    # build one, and both get the same array.
    @cached_property
    def _summed(self) -> np.ndarray:
        """The summed-area table (n_u + 1, n_v + 1, 4) of the field (triple, 1) on the lookup cells
        (0 where no square), for :meth:`blend` in the bands and the compiled kernel
        (:attr:`lookup`): built by the first blend that has a point in a band or by the first
        :attr:`lookup` (the pump boom's first ``region_ik_point`` or ``solve_ik`` of one target,
        before its kernel loads), 3-4 ms for 1460 squares (265 x 468 cells of 0.156 m, 4 MB),
        5-10 ms in a new process (page faults)."""
        values = np.zeros((len(self) + 1, 4))  # the row of owner -1 (no square) stays 0
        values[:-1, :3], values[:-1, 3] = self.triples, 1.0
        n_u, n_v = self._owner.shape
        summed = np.zeros((n_u + 1, n_v + 1, 4))
        # The sums of field.cumsum(axis=0).cumsum(axis=1), in the same order (the same bits), into
        # the table itself: down the cell columns one row of cells at a time, then along each row
        # in place. No field array (4 MB for 1460 squares): its page faults made the build twice
        # as long in a new process (9 ms -> 5 ms).
        for a in range(n_u):
            np.add(summed[a, 1:], np.take(values, self._owner[a], axis=0), out=summed[a + 1, 1:])
        np.cumsum(summed[1:, 1:], axis=1, out=summed[1:, 1:])
        return summed

    @cached_property
    def _extent(self) -> np.ndarray:
        """Per square its extent (m, 4) (r low, z low, r high, z high) m, for :meth:`nearest`."""
        side = self.grid.side(self.index[:, 2])
        corner = np.stack(self.grid.corner(self.index[:, 0], self.index[:, 1], self.index[:, 2]),
                          axis=-1).reshape(-1, 2)
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
        u, v = np.where(inside, u, 0.0), np.where(inside, v, 0.0)
        half = 0.5 * self.grid.band / self._cell
        low_u, low_v, high_u, high_v = np.moveaxis(self._bounds[k], -1, 0)
        core = (u - half >= low_u) & (u + half <= high_u) & (v - half >= low_v) & (v + half <= high_v)
        triple = self.triples[k]
        if not core.all():  # a point in a band: the window mean (the summed-area table, built once)
            n_u, n_v = self._owner.shape
            u0, u1 = np.clip(u - half, 0.0, n_u), np.clip(u + half, 0.0, n_u)
            v0, v1 = np.clip(v - half, 0.0, n_v), np.clip(v + half, 0.0, n_v)
            window = (
                self._summed_at(u1, v1)
                - self._summed_at(u0, v1)
                - self._summed_at(u1, v0)
                + self._summed_at(u0, v0)
            )
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = window[..., :3] / window[..., 3:]
            triple = np.where(core[..., None], triple, mean)
        return np.where(inside[..., None], triple, np.nan), inside

    def _summed_at(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The summed-area table (..., 4) at cell coordinates in [0, n]: bilinear in each cell."""
        a = np.minimum(np.floor(u), self._owner.shape[0] - 1).astype(int)
        b = np.minimum(np.floor(v), self._owner.shape[1] - 1).astype(int)
        f, g = (u - a)[..., None], (v - b)[..., None]
        s = self._summed
        low = s[a, b] * (1.0 - f) + s[a + 1, b] * f
        high = s[a, b + 1] * (1.0 - f) + s[a + 1, b + 1] * f
        return low * (1.0 - g) + high * g

    @cached_property
    def lookup(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The lookup arrays of :meth:`owner` and :meth:`blend` for the compiled single-point IK
        (:mod:`.ik_kernel`): the constants (grid origin r, z; the cell; the arrays' lower cell
        column, row; half the band and EDGE in cells), the cell owners (int32), the summed-area
        table (built on first use, :attr:`_summed`: the pump boom's first single-point call,
        which hands these to the kernel's loader) and per square its bounds in cells and its
        triple (m, 7)."""
        constants = np.array([*self.grid.origin, self._cell, *self._lower, 0.5 * self.grid.band / self._cell,
                              EDGE / self._cell], dtype=float)
        return constants, self._owner, self._summed, np.concatenate([self._bounds, self.triples], axis=1)

    def random_lines(self, count: int, rng: np.random.Generator, steps: int = 40,
                     step: float = 0.1) -> np.ndarray:
        """Straight lines (k, steps + 1, 2) of (r, z) points ``step`` apart inside the covered area:
        of ``count`` lines in random directions, half starting in squares drawn by count (mostly
        the small squares at the rim), half by area, the k that stay inside (continuity checks)."""
        side = self.grid.side(self.index[:, 2])
        rows = np.concatenate([rng.integers(0, len(self), count // 2),
                               rng.choice(len(self), count - count // 2, p=side**2 / np.sum(side**2))])
        corner = np.stack(self.grid.corner(*self.index[rows].T), axis=-1)
        start = corner + side[rows, None] * rng.random((count, 2))
        angle = rng.uniform(0.0, 2.0 * math.pi, count)
        direction = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
        lines = start[:, None] + step * np.arange(steps + 1)[None, :, None] * direction[:, None]
        return lines[self.contains(lines[..., 0], lines[..., 1]).all(axis=1)]

    def nearest(self, r: float, z: float) -> tuple[float, float]:
        """The point of the covered area nearest to the finite plane point (r, z) (m)."""
        extent = self._extent
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
        rows = _squares(p["squares"], f"{TABLE_SECTION}.squares")
        built = p["built_for"]
        if expected is not None:
            for key, value in expected.items():
                have = np.asarray(built[key], dtype=float)
                require(
                    have.shape == np.shape(value) and np.allclose(have, value, rtol=0.0, atol=1e-9),
                    f"{TABLE_SECTION}.built_for.{key}",
                    f"the table in {path} was built for {built[key]}, the machine has {value}",
                )
        grid = Grid(tuple(built["origin"]), built["size"], built["band"])
        return cls(
            grid=grid,
            index=rows[:, :3].astype(int),
            triples=rows[:, 3:6],
            margin=rows[:, 6],
            built_for=built,
            search=p["search"],
            coverage=p["coverage"],
        )

    def dump(self, path: str | Path, header: Sequence[str] = ()) -> None:
        """Write the table as a ROS parameters file (deterministic text: same table, same bytes)."""
        section = {
            "built_for": {k: _plain(v) for k, v in self.built_for.items()},
            "search": {k: _plain(v) for k, v in self.search.items()},
            "coverage": {k: _plain(v) for k, v in self.coverage.items()},
        }
        lines = [f"# {line}" if line else "#" for line in header]
        lines += [
            "#",
            "# square (i, j, level)   r (m)          z (m)          theta2  theta3  theta4 (deg)  margin (m)",
        ]
        for (i, j, level), t, m in zip(self.index.tolist(), self.triples, self.margin):
            r, z = self.grid.corner(i, j, level)
            s = float(self.grid.side(level))
            deg = [math.degrees(x) for x in t]
            lines.append(
                f"# ({i:4d}, {j:4d}, {level})   {r:7.3f}-{r + s:7.3f}  {z:8.3f}-{z + s:8.3f}"
                f"  {deg[0]:6.1f}  {deg[1]:6.1f}  {deg[2]:6.1f}       {m:.3f}"
            )
        text = yaml.safe_dump(
            {"/**": {"ros__parameters": {TABLE_SECTION: section}}},
            default_flow_style=None,
            sort_keys=False,
            width=100,
        )
        # The squares last, as a literal block (its lines indented under the section's keys).
        indent = " " * 8
        text += f"      squares: |  # {' '.join(SQUARE_COLUMNS)}\n"
        for (i, j, level), t, m in zip(self.index.tolist(), self.triples.tolist(), self.margin.tolist()):
            text += f"{indent}{i} {j} {level} {t[0]!r} {t[1]!r} {t[2]!r} {round(m, 6)!r}\n"
        Path(path).write_text("\n".join(lines) + "\n" + text, encoding="utf-8")


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


def _squares(text: str, key: str) -> np.ndarray:
    """The rows (m, 7) of a table file's ``squares`` text (SQUARE_COLUMNS); ConfigError names the
    key and the first bad line."""
    tokens = text.split()  # the words of all lines (line breaks are white space)
    try:
        # The words per line (0: a blank line), each line's list dropped at once: 1460 lists kept
        # would wake the garbage collector, whose first rounds in a new process took 2-7 ms.
        if not set(map(len, map(str.split, text.splitlines()))) <= {0, len(SQUARE_COLUMNS)}:
            raise ValueError
        # Each distinct word converted once: the triples repeat (a grid of step_deg), 1837 distinct
        # words of 10,220 for 1460 squares (float() of every word: 2.2 ms, this 1.1 ms).
        value = {word: float(word) for word in set(tokens)}
    except ValueError:
        lines = [line for line in text.splitlines() if line.strip()]
        bad = next((n for n, line in enumerate(lines)
                    if len(line.split()) != len(SQUARE_COLUMNS) or not _numbers(line)), 0)
        raise ConfigError(
            f"{key}, line {bad + 1}: expected {len(SQUARE_COLUMNS)} numbers ({' '.join(SQUARE_COLUMNS)}), "
            f"got {shown(lines[bad])}"
        ) from None
    rows = np.fromiter(map(value.__getitem__, tokens), dtype=float, count=len(tokens))
    rows = rows.reshape(-1, len(SQUARE_COLUMNS))
    index = rows[:, :3]
    bad = ~np.isfinite(rows).all(axis=1) | np.any(index != np.round(index), axis=1)
    bad |= np.any(np.abs(index[:, :2]) > INDEX_RANGE, axis=1) | (index[:, 2] < 0) | (index[:, 2] > MAX_LEVEL)
    if bad.any():
        n = int(np.argmax(bad))
        lines = [line for line in text.splitlines() if line.strip()]
        raise ConfigError(
            f"{key}, line {n + 1}: need finite numbers, whole column and row within +-{INDEX_RANGE} and a "
            f"level in [0, {MAX_LEVEL}], got {shown(lines[n])}"
        )
    return rows


def _numbers(line: str) -> bool:
    try:
        [float(word) for word in line.split()]
    except ValueError:
        return False
    return True


def _plain(value: Any) -> Any:
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(value)
