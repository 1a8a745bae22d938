"""The region table of the pump boom's IK (paper 001, section 2.2), as data.

The vertical pour plane (r, z) of the boom (r horizontal from the slew axis, z up from the
ground) is cut into squares of side ``size`` whose corners lie on the grid
``origin + size * (i, j)``; square (i, j) spans r in [r0 + i s, r0 + (i + 1) s], z in
[z0 + j s, z0 + (j + 1) s]. Each square of the table holds one triple (theta2, theta3, theta4)
(rad, paper convention) for which the last two sections reach every point of the square inside
the joint limits in positive-envelope shape.

Transition bands (section 2.2, step 3): a band of width ``band`` centred on every edge between
two squares, in which the triple is the blend of the neighbouring squares' triples. The blend is a
partition of unity: along r, square column k weighs a_k(u) = ramp(u - k) - ramp(u - k - 1) with
u = (r - r0) / s and ramp(x) = clip((x + h) / (2 h), 0, 1), h = band / (2 s) (likewise b_l(v)
along z); square (k, l) weighs a_k b_l. Away from every edge (more than band / 2) one weight is 1
and the triple is the square's own; across a band it changes linearly (bilinearly near a
corner). Squares missing from the table drop out and the rest are renormalised, so a point of a
table square next to a missing one keeps its own square's triple up to the edge. A point whose
own square is not in the table is outside the automatic pour workspace.

The table file (``config/pump_boom_regions.yaml``, a ROS parameters file) is written by
``pump_boom_regions`` (:mod:`.build_regions`) and records the geometry it was built for; loading
it for another geometry is an error (the boom then solves FK but no region IK).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike

from manipulator_kinematics.config import ConfigError, Number, Numbers, require, validate
from manipulator_kinematics.params import load_parameters

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
    },
    "column": Numbers(item=Number(min=-1000, max=1000, integer=True)),
    "row": Numbers(item=Number(min=-1000, max=1000, integer=True)),
    "theta2": Numbers(),
    "theta3": Numbers(),
    "theta4": Numbers(),
    "margin": Numbers(item=Number(unit="m")),
    "coverage": {
        "squares": Number(min=0, integer=True),
        "covered_area": Number(min=0.0, unit="m^2"),
        "reachable_area": Number(min=0.0, unit="m^2"),
        "envelope_area": Number(min=0.0, unit="m^2"),
        "band_failures": Number(min=0, integer=True),
        "checked_points": Number(min=0, integer=True),
    },
}


@dataclass(frozen=True)
class Grid:
    """The square grid of the pour plane: corner ``origin`` (r0, z0) m, side ``size`` m, ``band`` m."""

    origin: tuple[float, float]
    size: float
    band: float

    def __post_init__(self) -> None:
        if not (self.size > 0.0 and 0.0 < self.band < self.size):
            raise ValueError(f"need size > 0 and 0 < band < size, got size {self.size}, band {self.band}")

    def cell(self, r: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Grid coordinates (u, v) of plane points: square (floor(u), floor(v))."""
        return (
            (np.asarray(r, dtype=float) - self.origin[0]) / self.size,
            (np.asarray(z, dtype=float) - self.origin[1]) / self.size,
        )

    def corner(self, i: ArrayLike, j: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Lower-left corner (r, z) of squares (i, j)."""
        return (self.origin[0] + np.asarray(i) * self.size, self.origin[1] + np.asarray(j) * self.size)

    def weights(self, u: np.ndarray) -> np.ndarray:
        """(..., 3) blend weights of squares floor(u) - 1, floor(u), floor(u) + 1 along one axis."""
        h = self.band / (2.0 * self.size)
        k = np.floor(u)[..., None] + np.array([-1.0, 0.0, 1.0])
        x = u[..., None] - k
        return np.clip((x + h) / (2.0 * h), 0.0, 1.0) - np.clip((x - 1.0 + h) / (2.0 * h), 0.0, 1.0)


@dataclass(frozen=True)
class RegionTable:
    """Squares (i, j) with their triples (theta2, theta3, theta4) and the geometry they fit."""

    grid: Grid
    index: np.ndarray  # (m, 2) int: column i, row j
    triples: np.ndarray  # (m, 3) rad
    margin: np.ndarray  # (m,) m: the smallest clearance of the square's check (see build_regions)
    built_for: Mapping[str, Any]
    search: Mapping[str, Any]
    coverage: Mapping[str, Any]

    def __post_init__(self) -> None:
        index = np.asarray(self.index, dtype=int).reshape(-1, 2)
        object.__setattr__(self, "index", index)
        object.__setattr__(self, "triples", np.asarray(self.triples, dtype=float).reshape(-1, 3))
        object.__setattr__(self, "margin", np.asarray(self.margin, dtype=float).reshape(-1))
        if len({tuple(row) for row in index.tolist()}) != len(index):
            raise ValueError("region table lists a square twice")
        lower = index.min(axis=0) if len(index) else np.zeros(2, dtype=int)
        upper = index.max(axis=0) if len(index) else -np.ones(2, dtype=int)
        # Dense lookup array with a one-square NaN border, so the 3x3 neighbourhood of any table
        # square is inside it.
        shape = tuple(upper - lower + 3)
        dense = np.full(shape + (3,), np.nan)
        dense[index[:, 0] - lower[0] + 1, index[:, 1] - lower[1] + 1] = self.triples
        object.__setattr__(self, "_lower", lower - 1)
        object.__setattr__(self, "_dense", dense)
        squares = {(i, j): (t[0], t[1], t[2]) for (i, j), t in zip(index.tolist(), self.triples.tolist())}
        object.__setattr__(self, "_squares", squares)

    def __len__(self) -> int:
        return len(self.index)

    def contains(self, r: ArrayLike, z: ArrayLike) -> np.ndarray:
        """(...,) True where the point's own square is in the table (NaN: False)."""
        return ~np.isnan(self._own(*self.grid.cell(r, z))[..., 0])

    def square(self, r: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Column and row (i, j) of the square holding each point (int; -10^9 for NaN)."""
        u, v = self.grid.cell(r, z)
        fill = -(10**9)
        return (
            np.where(np.isfinite(u), np.floor(np.nan_to_num(u)), fill).astype(int),
            np.where(np.isfinite(v), np.floor(np.nan_to_num(v)), fill).astype(int),
        )

    def blend(self, r: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The triple (..., 3) at plane points (section 2.2 step 3; module docstring) and
        ``inside`` (...,): NaN triples where the point's own square is not in the table."""
        u, v = self.grid.cell(r, z)
        u, v = np.broadcast_arrays(u, v)
        inside = ~np.isnan(self._own(u, v)[..., 0])
        # Points outside the table (NaN included) get a harmless stand-in; their triple is NaN.
        ok_u = np.where(inside, u, 0.0)
        ok_v = np.where(inside, v, 0.0)
        iu = np.floor(ok_u).astype(int) - self._lower[0]
        iv = np.floor(ok_v).astype(int) - self._lower[1]
        iu = np.clip(iu, 1, self._dense.shape[0] - 2)
        iv = np.clip(iv, 1, self._dense.shape[1] - 2)
        offsets = np.array([-1, 0, 1])
        neighbours = self._dense[
            (iu[..., None] + offsets)[..., :, None], (iv[..., None] + offsets)[..., None, :]
        ]
        weight = self.grid.weights(ok_u)[..., :, None] * self.grid.weights(ok_v)[..., None, :]
        present = ~np.isnan(neighbours[..., 0])
        weight = np.where(present, weight, 0.0)
        total = weight.sum(axis=(-2, -1))
        with np.errstate(invalid="ignore", divide="ignore"):
            triple = np.einsum("...kl,...klc->...c", weight, np.nan_to_num(neighbours)) / total[..., None]
        return np.where(inside[..., None], triple, np.nan), inside

    def blend_point(self, r: float, z: float) -> tuple[tuple[float, float, float], bool] | None:
        """:meth:`blend` of one finite plane point in plain floats (no numpy: a controller's single
        point costs microseconds, not numpy's per-call overhead): ((theta2, theta3, theta4),
        blended) or None where the point's own square is not in the table. Same weights as
        :meth:`Grid.weights`: at a fraction f of its square the point weighs the previous square
        max(0, (h - f) / 2h), the next max(0, (f - 1 + h) / 2h), its own the rest."""
        size, origin = self.grid.size, self.grid.origin
        u, v = (r - origin[0]) / size, (z - origin[1]) / size
        i, j = math.floor(u), math.floor(v)
        own = self._squares.get((i, j))
        if own is None:
            return None
        h2 = self.grid.band / size
        f, g = u - i, v - j
        wu = (max(0.0, (0.5 * h2 - f) / h2), 0.0, max(0.0, (f - 1.0 + 0.5 * h2) / h2))
        wv = (max(0.0, (0.5 * h2 - g) / h2), 0.0, max(0.0, (g - 1.0 + 0.5 * h2) / h2))
        if wu[0] == wu[2] == wv[0] == wv[2] == 0.0:
            return own, False  # the square's core: its own triple
        wu = (wu[0], 1.0 - wu[0] - wu[2], wu[2])
        wv = (wv[0], 1.0 - wv[0] - wv[2], wv[2])
        total, a, b, c = 0.0, 0.0, 0.0, 0.0
        for du in (-1, 0, 1):
            for dv in (-1, 0, 1):
                weight = wu[du + 1] * wv[dv + 1]
                triple = self._squares.get((i + du, j + dv)) if weight else None
                if triple is not None:
                    total += weight
                    a += weight * triple[0]
                    b += weight * triple[1]
                    c += weight * triple[2]
        blended = (a / total, b / total, c / total)
        return blended, blended != own

    def own_triple(self, r: ArrayLike, z: ArrayLike) -> np.ndarray:
        """The triple of the point's own square (..., 3), no blending; NaN outside the table."""
        return self._own(*self.grid.cell(r, z))

    def _own(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        finite = np.isfinite(u) & np.isfinite(v)
        iu = np.floor(np.where(finite, u, 0.0)).astype(int) - self._lower[0]
        iv = np.floor(np.where(finite, v, 0.0)).astype(int) - self._lower[1]
        hit = finite & (iu >= 0) & (iu < self._dense.shape[0]) & (iv >= 0) & (iv < self._dense.shape[1])
        out = self._dense[np.where(hit, iu, 0), np.where(hit, iv, 0)]
        return np.where(hit[..., None], out, np.nan)

    # ---- file ---------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path, expected: Mapping[str, Any] | None = None) -> RegionTable:
        """Read a table file; with ``expected`` (the ``built_for`` values of the machine using
        it) a table built for another geometry or grid raises ConfigError naming the key."""
        params = load_parameters(path)
        if TABLE_SECTION not in params:
            raise ConfigError(f"{path}: no {TABLE_SECTION!r} section under /**: ros__parameters")
        p = validate(params[TABLE_SECTION], TABLE_SCHEMA, TABLE_SECTION)
        m = len(p["column"])
        for key in ("row", "theta2", "theta3", "theta4", "margin"):
            require(len(p[key]) == m, f"{TABLE_SECTION}.{key}", f"has {len(p[key])} entries, column has {m}")
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
            index=np.stack([p["column"], p["row"]], axis=-1),
            triples=np.stack([p["theta2"], p["theta3"], p["theta4"]], axis=-1),
            margin=np.array(p["margin"]),
            built_for=built,
            search=p["search"],
            coverage=p["coverage"],
        )

    def dump(self, path: str | Path, header: Sequence[str] = ()) -> None:
        """Write the table as a ROS parameters file (deterministic text: same table, same bytes)."""
        section = {
            "built_for": {k: _plain(v) for k, v in self.built_for.items()},
            "search": {k: _plain(v) for k, v in self.search.items()},
            "column": [int(i) for i in self.index[:, 0]],
            "row": [int(j) for j in self.index[:, 1]],
            "theta2": [float(t) for t in self.triples[:, 0]],
            "theta3": [float(t) for t in self.triples[:, 1]],
            "theta4": [float(t) for t in self.triples[:, 2]],
            "margin": [round(float(m), 6) for m in self.margin],
            "coverage": {k: _plain(v) for k, v in self.coverage.items()},
        }
        lines = [f"# {line}" if line else "#" for line in header]
        lines += ["#", "# square (i, j)   r (m)      z (m)      theta2  theta3  theta4 (deg)   margin (m)"]
        for (i, j), t, m in zip(self.index, self.triples, self.margin):
            r, z = self.grid.corner(i, j)
            s = self.grid.size
            deg = [math.degrees(x) for x in t]
            lines.append(
                f"# ({i:3d}, {j:3d})   {r:5.2f}-{r + s:5.2f}  {z:6.2f}-{z + s:6.2f}"
                f"  {deg[0]:6.1f}  {deg[1]:6.1f}  {deg[2]:6.1f}        {m:.3f}"
            )
        text = yaml.safe_dump(
            {"/**": {"ros__parameters": {TABLE_SECTION: section}}},
            default_flow_style=None,
            sort_keys=False,
            width=100,
        )
        Path(path).write_text("\n".join(lines) + "\n" + text, encoding="utf-8")


def _plain(value: Any) -> Any:
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(value)
