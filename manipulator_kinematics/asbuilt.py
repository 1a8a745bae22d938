"""As-built surface: the lowest elevation a cutting edge reached, per grid cell (numpy, no rclpy).

A machine-control system maps what a bucket actually dug as the lowest elevation its cutting
edge reached over each cell of a grid in the site frame (x easting, y northing, z elevation,
metres), the "minimum elevation mapping" of the vendors' as-built tools. Input is the edge at
each sample: its two corners ``left`` and ``right`` (N, 3), in time order.

* **Along the edge, exact.** The edge of one sample is a straight segment; its height is linear
  along it, so the lowest point of the piece of it inside a cell is one end of that piece. Each
  segment is cut where it crosses the grid lines (x = x0 + i c, y = y0 + j c) and every piece
  gives its cell the lower of its two end heights: no sampling step along the edge, nothing
  missed between sample points.
* **Along the motion, densified.** Between two samples the edge moves; where a corner moves more
  than ``max_step`` (default 1 cm, or half a cell if smaller; 3-D distance) the motion is filled in with edges
  interpolated linearly between the two samples, so a fast sweep leaves no unvisited cells
  between samples and a cell's value comes within about ``max_step`` times the sheet's slope of its
  lowest point there (a grazing pass can otherwise stand for a deep one). At 100 Hz a
  bucket's edge moves about 1 cm a sample: little or nothing is filled in.
* Grids are aligned to multiples of the cell size from the site origin, so grids of several runs
  (a fleet, several bags of one site) combine cell by cell: :meth:`AsBuilt.merge` keeps the lower
  value. A long run is mapped part by part (:class:`LowestElevation`) to the same grid: cells are
  counted from the site origin and each piece depends on its own segment only.

Cells the edge never reached are NaN. The result is checked against a brute-force reference
(every sample's segment rasterised at a fine step) in ``test/test_asbuilt.py``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.landxml import write_tin

#: Segments cut into cell pieces at once: bounds the temporaries (pieces x crossings x 8 bytes).
_CHUNK = 8192


@dataclass(frozen=True)
class AsBuilt:
    """Lowest elevation per cell: ``z[j, i]`` over the cell ``[x0 + i c, x0 + (i+1) c) x
    [y0 + j c, y0 + (j+1) c)``, NaN where the edge never was; ``hits`` counts the pieces (of
    positive length) of edges in the cell."""

    x0: float
    y0: float
    cell: float
    z: np.ndarray  # (ny, nx), m
    hits: np.ndarray  # (ny, nx), int64

    @property
    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell centres' x (nx,) and y (ny,)."""
        ny, nx = self.z.shape
        return self.x0 + (np.arange(nx) + 0.5) * self.cell, self.y0 + (np.arange(ny) + 0.5) * self.cell

    def points(self) -> np.ndarray:
        """(k, 3) centre x, y and lowest z of every reached cell, row by row (y, then x)."""
        xc, yc = self.centres
        j, i = np.nonzero(np.isfinite(self.z))
        return np.column_stack([xc[i], yc[j], self.z[j, i]])

    def on(self, x0: float, y0: float, shape: tuple[int, int]) -> AsBuilt:
        """The same values on a larger aligned grid (origin ``x0, y0``, ``shape`` (ny, nx))."""
        di, dj = round((self.x0 - x0) / self.cell), round((self.y0 - y0) / self.cell)
        z = np.full(shape, np.nan)
        hits = np.zeros(shape, np.int64)
        ny, nx = self.z.shape
        z[dj : dj + ny, di : di + nx] = self.z
        hits[dj : dj + ny, di : di + nx] = self.hits
        return AsBuilt(x0, y0, self.cell, z, hits)

    @staticmethod
    def merge(grids: Iterable[AsBuilt]) -> AsBuilt:
        """One grid of several of the same cell size: the lowest value per cell."""
        grids = [g for g in grids if g.z.size]
        if not grids:
            raise ValueError("no as-built grid to merge")
        cell = grids[0].cell
        if any(not math.isclose(g.cell, cell, rel_tol=1e-12) for g in grids):
            raise ValueError("as-built grids of different cell sizes cannot be merged")
        x0, y0 = min(g.x0 for g in grids), min(g.y0 for g in grids)
        nx = max(round((g.x0 - x0) / cell) + g.z.shape[1] for g in grids)
        ny = max(round((g.y0 - y0) / cell) + g.z.shape[0] for g in grids)
        placed = [g.on(x0, y0, (ny, nx)) for g in grids]
        z = np.fmin.reduce([p.z for p in placed])
        return AsBuilt(x0, y0, cell, z, np.sum([p.hits for p in placed], axis=0))

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """A TIN through the reached cells' centres: vertices (V, 3) as :meth:`points`, faces
        (F, 3), two triangles over every square of four reached neighbouring centres."""
        reached = np.isfinite(self.z)
        number = np.full(self.z.shape, -1)
        number[reached] = np.arange(int(reached.sum()))
        a, b = number[:-1, :-1], number[:-1, 1:]  # (j, i), (j, i+1)
        c, d = number[1:, :-1], number[1:, 1:]  # (j+1, i), (j+1, i+1)
        full = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
        faces = np.vstack(
            [np.column_stack([a[full], b[full], d[full]]), np.column_stack([a[full], d[full], c[full]])]
        )
        return self.points(), faces

    def write_landxml(self, path: str | Path, name: str = "as-built") -> None:
        """The reached cells as a LandXML 1.2 TIN surface (:meth:`triangles`)."""
        vertices, faces = self.triangles()
        write_tin(path, vertices, faces, name)

    def write_csv(self, path: str | Path) -> None:
        """``x,y,z`` of every reached cell's centre (site frame, m): a point cloud GIS tools import."""
        np.savetxt(path, self.points(), fmt="%.4f", delimiter=",", header="x,y,z", comments="")


def densify(left: ArrayLike, right: ArrayLike, max_step: float) -> tuple[np.ndarray, np.ndarray]:
    """The edge (N, 3) twice, with edges interpolated between samples where a corner moves more
    than ``max_step`` (m): each sample gap split into equal steps of at most that (in 3-D, so a
    plunging edge is filled in as well as a sweeping one)."""
    left, right = np.asarray(left, float), np.asarray(right, float)
    if len(left) < 2:
        return left, right
    move = np.maximum(
        np.linalg.norm(np.diff(left, axis=0), axis=1), np.linalg.norm(np.diff(right, axis=0), axis=1)
    )
    steps = np.maximum(np.ceil(move / max_step), 1).astype(np.int64)
    # Sample k, then steps[k] - 1 interpolated edges before sample k + 1; the last sample once.
    start = np.repeat(np.arange(len(steps)), steps)
    frac = (np.arange(len(start)) - np.repeat(np.cumsum(steps) - steps, steps)) / np.repeat(steps, steps)
    frac = frac[:, None]

    def fill(p: np.ndarray) -> np.ndarray:
        return np.vstack([p[start] + frac * (p[start + 1] - p[start]), p[-1:]])

    return fill(left), fill(right)


def _pieces(a: np.ndarray, b: np.ndarray, cell: float) -> tuple[np.ndarray, ...]:
    """Segments a -> b (n, 3) cut at the grid lines: global cell i, j (counted from the site
    origin) and the lower end height of each piece of positive length (flattened). Every number
    depends on its own segment only, so a run cut into pieces gives the same cells and heights."""
    ga = a[:, :2] / cell  # grid units from the site origin, whichever part of a run this is
    gb = b[:, :2] / cell
    d = gb - ga
    lo, hi = np.floor(np.minimum(ga, gb)), np.floor(np.maximum(ga, gb))
    count = (hi - lo).astype(np.int64)  # grid lines crossed, per axis
    k = int(count.max(initial=0))
    t = [np.zeros((len(a), 1)), np.ones((len(a), 1))]
    if k:
        line = lo[:, None, :] + 1 + np.arange(k)[None, :, None]  # (n, k, 2): lines above lo
        with np.errstate(divide="ignore", invalid="ignore"):
            tc = (line - ga[:, None, :]) / d[:, None, :]
        valid = np.arange(k)[None, :, None] < count[:, None, :]
        t.append(np.where(valid, tc, 1.0).reshape(len(a), 2 * k))
    t = np.sort(np.clip(np.hstack(t), 0.0, 1.0), axis=1)
    # Padding and a crossing of a grid corner give pieces of zero length: left out, so the pieces
    # of a segment do not depend on the segments it is cut with.
    real = t[:, 1:] > t[:, :-1]
    mid = 0.5 * (t[:, 1:] + t[:, :-1])
    cell_i = np.floor(ga[:, None, 0] + mid * d[:, None, 0]).astype(np.int64)
    cell_j = np.floor(ga[:, None, 1] + mid * d[:, None, 1]).astype(np.int64)
    z = a[:, None, 2] + t * (b[:, None, 2] - a[:, None, 2])
    z_low = np.minimum(z[:, 1:], z[:, :-1])
    return cell_i[real], cell_j[real], z_low[real]


def _rasterise(left: np.ndarray, right: np.ndarray, cell: float) -> AsBuilt:
    """The grid of the edges ``left[k] -> right[k]`` as they are (no densification)."""
    if not len(left):
        return AsBuilt(0.0, 0.0, cell, np.full((0, 0), np.nan), np.zeros((0, 0), np.int64))
    xy = np.vstack([left[:, :2], right[:, :2]])
    i0, j0 = np.floor(xy.min(axis=0) / cell).astype(np.int64).tolist()
    nx, ny = (np.floor(xy.max(axis=0) / cell).astype(np.int64) - (i0, j0) + 1).tolist()
    flat = np.full(ny * nx, np.inf)
    hits = np.zeros(ny * nx, np.int64)
    for start in range(0, len(left), _CHUNK):
        i, j, z = _pieces(left[start : start + _CHUNK], right[start : start + _CHUNK], cell)
        # A piece ending exactly on the far grid line of the last cell rounds into it.
        index = np.clip(j - j0, 0, ny - 1) * nx + np.clip(i - i0, 0, nx - 1)
        np.minimum.at(flat, index, z)
        hits += np.bincount(index, minlength=ny * nx)
    z = np.where(hits > 0, flat, np.nan).reshape(ny, nx)
    return AsBuilt(i0 * cell, j0 * cell, cell, z, hits.reshape(ny, nx))


class LowestElevation:
    """:func:`lowest_elevation` of a run given in parts, in time order (:meth:`add`), for a run
    too long to hold at once: :meth:`result` is the grid of the whole run. The last sample of a
    part is kept, so the sweep from it to the first sample of the next part (densified as any
    other) is not lost; each edge is rasterised once, the parts' grids merged by
    :meth:`AsBuilt.merge` (the lowest value per cell, the hits added)."""

    def __init__(self, cell: float, max_step: float | None = None) -> None:
        if not (math.isfinite(cell) and cell > 0.0):
            raise ValueError(f"cell size must be a positive number of metres, got {cell}")
        step = min(0.5 * cell, 0.01) if max_step is None else max_step
        if not (math.isfinite(step) and step > 0.0):
            raise ValueError(f"max_step must be a positive number of metres, got {max_step}")
        self.cell, self.max_step = cell, step
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self._grid: AsBuilt | None = None

    def add(self, left: ArrayLike, right: ArrayLike) -> None:
        """The next samples of the run: corners (n, 3) in the site frame, in time order."""
        left, right = np.asarray(left, float).reshape(-1, 3), np.asarray(right, float).reshape(-1, 3)
        keep = np.all(np.isfinite(left), axis=1) & np.all(np.isfinite(right), axis=1)
        left, right = left[keep], right[keep]
        if not len(left):
            return
        carried = self._last is not None
        if carried:
            left, right = np.vstack([self._last[0], left]), np.vstack([self._last[1], right])
        self._last = (left[-1:], right[-1:])
        edges_left, edges_right = densify(left, right, self.max_step)
        if carried:  # the carried sample's own edge is in the grid already
            edges_left, edges_right = edges_left[1:], edges_right[1:]
        grid = _rasterise(edges_left, edges_right, self.cell)
        self._grid = grid if self._grid is None else AsBuilt.merge([self._grid, grid])

    def result(self) -> AsBuilt:
        """The grid of everything added; an empty grid (0 x 0) if no finite sample was."""
        if self._grid is None:
            return _rasterise(np.empty((0, 3)), np.empty((0, 3)), self.cell)
        return self._grid


def lowest_elevation(
    left: ArrayLike, right: ArrayLike, cell: float, max_step: float | None = None
) -> AsBuilt:
    """The as-built grid of an edge's run (module docstring): ``left``, ``right`` (N, 3) the
    corners in the site frame in time order, ``cell`` the cell size (m), ``max_step`` the largest
    corner move between two edges used (default 1 cm or ``cell / 2``). Rows with a non-finite value are
    left out (a gap in the record, not a point)."""
    run = LowestElevation(cell, max_step)
    run.add(left, right)
    return run.result()
