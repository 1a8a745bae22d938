"""Build the pump boom's region table (paper 001, section 2.2) from its geometry: ``pump_boom_regions``.

For every 5 m square of the pour plane (and, where no triple serves one, its quarters, down to
``levels`` splittings: a quadtree of the paper's method) the builder searches
(theta2, theta3, theta4) on a grid of ``step_deg`` over the joint limits (theta3 >= ``min_theta3``,
by default its lower limit), with section 2 folded back (theta3 < ``FOLDED``, 15 deg) only on the
squares within ``fold_width`` (1 m) of the positive-envelope points that no other shape reaches
(a strip by the truck above the root pin): the two families of shapes meet at seams no 1 m band
crosses within the step limit (above the root pin no theta3 between 15 and 90 deg keeps the
envelope, so the shape cannot change gradually), and this keeps the folded family, and its
seam, around the points that need it. Vectorised over all triples at once:

1. exact tests over the whole square, cheap: the farthest corner within L4 + L5 of section 3's
   end S, the square no closer than |L4 - L5| to S, and P_1..P_3 left of the chord root -> p for
   every corner (the chord's left side is a half plane through the root pin, so the corners
   decide for the whole square);
2. on the square sampled every 1 m (at least its corners): theta5 of the elbow-over 2R inside its
   limits and P_4 left of the chord; the triple's *margin* is the smallest clearance over the
   samples, in metres (a joint's distance from the chord, theta5's distance from a limit times
   L4, the distance from the 2R annulus' rims);
3. choice, deterministic, as one front: the squares from the 5 m square with the most valid
   triples outwards by distance (ties by (i, j, level)), a square that fails split at once into
   quarters that join the same queue; the first square takes its largest-margin triple, every
   later one the triple closest (sum of squared angle differences) to the mean of the triples
   its chosen neighbours blend in around it, among those whose margin is at least
   min(``min_margin``, half the square's best), so that transition bands move the joints little;
4. a choice is kept only if the region IK then solves every point of the check lattice (grid
   origin + ``check_spacing`` * integers) in the square widened by half a band and one lattice
   step on each side (every point whose blended triple it changes, and the steps from those to
   the points it does not change) and no joint changes by more than ``max_step``
   (7.5 deg) per 100 mm in any direction (the norm of its changes along r and z between lattice
   neighbours); the candidates are first checked alone on the square's own lattice points, many
   at once, then at most ``MAX_TRIES`` / 4^level with the neighbours; a square with no such
   triple is split into four (the quarters that hold a positive-envelope point of the coverage
   lattice are searched at the next level) or, at the last level, left out;
5. the finished table is checked the same way over its whole area, on a lattice half the check
   spacing apart and on every square's edges (off the lattices for small squares); where a point fails or a
   step exceeds ``max_step`` (the blend around gaps between small squares can change faster than
   their own checks saw), the smallest squares under the point's window are dropped and the check
   runs again, until it passes (``band_failures`` 0, ``largest_step`` <= ``max_step``);
6. the gaps are filled: every square of the smallest size holding an uncovered positive-envelope
   point of the coverage lattice is searched again as in steps 3-4, with ``FILL_TRIES``
   candidates (the front met it with other neighbours, or the final check dropped it; now it has
   neighbours on every side), then step 5 runs again, up to ``FILLS`` times.

Squares of two shape families (:func:`pump_boom_kinematics.regions.family`) never touch, not even
at a corner: the band does not blend them, so a line through a shared point would jump. A square
touching squares of one family takes a triple of that family, one touching two is split.

Coverage (:func:`reachable_area`): the lattice points every 0.1 m of the pour plane in front of
the slew axis that some joint state inside the limits reaches, and those it reaches in
positive-envelope shape, each with a certificate (a joint state with its tip exactly there):
8 * 10^6 random joint states (fixed seed) seed it, and every certified point lends its triple to
its neighbours until no point is added. ``covered_share`` is the share of those positive-envelope
points (with the covered ones) that the table covers and solves.
"""

from __future__ import annotations

import argparse
import heapq
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy import ndimage

from manipulator_kinematics.param_files import CONFIG_DIR, ConfigError, config_path, load_parameters
from manipulator_kinematics.planar import two_link_ik, wrap_angle
from manipulator_kinematics.row_blocks import in_blocks
from pump_boom_kinematics.kinematics import CONFIG_FILE, LIMIT_TOL, SECTION, PumpBoom
from pump_boom_kinematics.regions import FOLDED, Grid, RegionTable, family

STEP_DEG = 2.5
MIN_MARGIN = 0.3  # m
CHECK_SPACING = 0.1  # m
SCREEN_SPACING = 1.0  # m
LEVELS = 5  # a 5 m square is split down to squares of 5 / 2^5 = 0.156 m
RASTER = 0.1  # m, lattice of the reachable-area measure
SAMPLES = 8_000_000
CHUNK = 20_000
MAX_TRIES = 100  # candidates tried per 5 m square before it is split (a quarter of that per level down)
SCAN = 4  # candidates pre-checked per candidate tried
MAX_STEP = math.radians(7.5)  # rad per 100 mm of tip motion in any direction, on the check lattice
#: rad, the smallest theta3 searched (0: every theta3 within the limits).
MIN_THETA3 = 0.0
#: m, folded shapes are searched only on the squares this close to the points no other shape reaches
#: (with folded shapes allowed everywhere the front grew them 10 m beyond those points: 97.51 % covered
#: against 97.84 %, the longer seam lost the rest).
FOLD_WIDTH = 1.0
REPAIRS = 30  # passes of the final check that drop the squares around its failures, at most
#: Fill passes (step 6) at most, and the candidates each gap's square tries: a gap has neighbours on
#: every side, so more candidates pass alone than fit them.
FILLS = 3
FILL_TRIES = 200


@dataclass(frozen=True)
class Coverage:
    """Reachable points of the pour plane (r >= 0) on a lattice: cell (a, b) of the edges stands for
    its centre; ``reachable`` (na, nb) True where some joint state inside the limits has its tip
    there, ``envelope`` where one in positive-envelope shape has; ``samples`` random states seeded it."""

    r_edges: np.ndarray
    z_edges: np.ndarray
    reachable: np.ndarray
    envelope: np.ndarray
    samples: int

    @property
    def cell_area(self) -> float:
        return float((self.r_edges[1] - self.r_edges[0]) * (self.z_edges[1] - self.z_edges[0]))

    @property
    def centres(self) -> np.ndarray:
        """(na, nb, 2) the lattice points (r, z)."""
        r = 0.5 * (self.r_edges[:-1] + self.r_edges[1:])
        z = 0.5 * (self.z_edges[:-1] + self.z_edges[1:])
        return np.stack(np.meshgrid(r, z, indexing="ij"), axis=-1)


def candidate_triples(boom: PumpBoom, step_deg: float = STEP_DEG) -> np.ndarray:
    """(N, 3) the search grid of (theta2, theta3, theta4) over their limits (both ends included)."""
    axes = []
    for k in (1, 2, 3):
        lower, upper = boom.limits.lower[k], boom.limits.upper[k]
        count = math.floor((upper - lower) / math.radians(step_deg) + 1e-9) + 1
        axes.append(lower + math.radians(step_deg) * np.arange(count))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _shoulder(boom: PumpBoom, triples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P_1..P_3 (N, 3, 2) and phi_3 (N,) of triples."""
    q = np.concatenate([np.zeros((len(triples), 1)), triples, np.full((len(triples), 2), np.pi)], axis=-1)
    return boom.plane_points(q)[:, 1:4], boom.section_angles(q)[:, 2]


def square_margin(
    boom: PumpBoom,
    triples: np.ndarray,
    corner: np.ndarray,
    size: float,
    spacing: float,
    shoulder: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """(N,) margin (m) of each triple over the square with lower-left ``corner`` (module docstring,
    steps 1-2); -inf where a test fails, so margin >= 0 means valid on the samples."""
    l4, l5 = boom.lengths[3], boom.lengths[4]
    root = boom.root
    joints, phi3 = _shoulder(boom, triples) if shoulder is None else shoulder
    # The farthest corner is no nearer than the centre: only the triples whose shoulder reaches the
    # centre can pass step 1 (a pre-selection, same result: most of the grid is out of reach).
    within = np.flatnonzero(np.linalg.norm(joints[:, 2] - (corner + 0.5 * size), axis=-1) <= l4 + l5)
    shoulder = joints[within, 2]
    corners = corner + size * np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    far = np.linalg.norm(corners[None] - shoulder[:, None], axis=-1).max(axis=-1)
    near = np.linalg.norm(np.clip(shoulder, corner, corner + size) - shoulder, axis=-1)
    chord = corners - root  # (4, 2)
    rel = joints[within] - root  # (n, 3, 2)
    cross = chord[None, :, None, 0] * rel[:, None, :, 1] - chord[None, :, None, 1] * rel[:, None, :, 0]
    cheap = (far <= l4 + l5) & (near >= abs(l4 - l5)) & (cross >= 0.0).all(axis=(1, 2))
    margin = np.full(len(triples), -np.inf)
    survivors = within[cheap]
    offsets = np.linspace(0.0, size, max(2, math.ceil(size / spacing - 1e-9) + 1))
    samples = (corner + np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1)).reshape(-1, 2)
    lo5, hi5 = boom.limits.lower[4], boom.limits.upper[4]
    for start in range(0, len(survivors), CHUNK):
        idx = survivors[start : start + CHUNK]
        s = joints[idx, 2][:, None]  # (n, 1, 2)
        d_vec = samples[None] - s
        d = np.linalg.norm(d_vec, axis=-1)
        cos_beta = np.clip((l4 * l4 + d * d - l5 * l5) / (2.0 * l4 * np.maximum(d, 1e-12)), -1.0, 1.0)
        phi4 = np.arctan2(d_vec[..., 1], d_vec[..., 0]) + np.arccos(cos_beta)
        theta5 = (phi4 - phi3[idx][:, None] + np.pi) % (2.0 * np.pi)
        p4 = s + l4 * np.stack([np.cos(phi4), np.sin(phi4)], axis=-1)
        chord_s = samples - root
        length = np.linalg.norm(chord_s, axis=-1)
        fixed = (joints[idx] - root)[:, None]  # (n, 1, 3, 2): P_1..P_3
        cross_fixed = chord_s[None, :, None, 0] * fixed[..., 1] - chord_s[None, :, None, 1] * fixed[..., 0]
        p4_rel = p4 - root
        cross4 = chord_s[None, :, 0] * p4_rel[..., 1] - chord_s[None, :, 1] * p4_rel[..., 0]
        distance = np.minimum(cross_fixed.min(axis=-1), cross4) / length
        clearance = np.minimum.reduce(
            [distance, (theta5 - lo5) * l4, (hi5 - theta5) * l4, l4 + l5 - d, d - abs(l4 - l5)]
        )
        margin[idx] = clearance.min(axis=-1)
    return margin


Key = tuple[int, int, int]  # square (i, j, level)


def build_table(
    boom: PumpBoom,
    step_deg: float = STEP_DEG,
    min_margin: float = MIN_MARGIN,
    check_spacing: float = CHECK_SPACING,
    max_step: float = MAX_STEP,
    levels: int = LEVELS,
    coverage: Coverage | None = None,
    progress: Callable[[str], None] | None = None,
    min_theta3: float = MIN_THETA3,
    fold_width: float = FOLD_WIDTH,
) -> RegionTable:
    """The region table of ``boom``'s geometry and grid (module docstring); ``progress`` is
    called with a line per level."""
    grid = boom.grid
    area = coverage if coverage is not None else reachable_area(boom)
    triples = candidate_triples(boom, step_deg)
    triples = triples[triples[:, 1] >= min(min_theta3, boom.limits.upper[2])]
    shoulders = _shoulder(boom, triples)
    folded = np.flatnonzero(triples[:, 1] < FOLDED)
    fold = _fold_distance(boom, area, FOLDED)
    reach = boom.reach
    i_range = range(0, math.ceil((boom.root[0] + reach - grid.origin[0]) / grid.size) + 1)
    j_range = range(
        math.floor((boom.root[1] - reach - grid.origin[1]) / grid.size) - 1,
        math.ceil((boom.root[1] + reach - grid.origin[1]) / grid.size) + 1,
    )
    pending = [(i, j, 0) for i in i_range for j in j_range if _holds_envelope(area, grid, (i, j, 0))]
    chosen: dict[Key, tuple[int, float]] = {}
    buckets: dict[tuple[int, int], list[Key]] = {}

    def margin_of(key: Key) -> np.ndarray:
        side = float(grid.side(key[2]))
        corner = np.array(grid.corner(*key), dtype=float)
        margin = square_margin(boom, triples, corner, side, min(SCREEN_SPACING, side), shoulders)
        if fold(*(corner + 0.5 * side)) - 0.5 * math.sqrt(2.0) * side > fold_width:
            margin[folded] = -np.inf
        return margin

    valid = {key: int(np.sum(margin_of(key) >= 0.0)) for key in pending}
    if not any(valid.values()):
        raise RuntimeError("no square of the grid can be covered: check the geometry and limits")
    start = max(valid, key=lambda key: (valid[key], -key[0], -key[1]))
    centre = np.array(grid.corner(start[0] + 0.5, start[1] + 0.5))
    # One front from the start square outwards over every level: a square that fails is split at
    # once and its quarters wait in the same queue by distance, so the chosen squares grow as one
    # connected region (level by level, separate regions grew and met at seams no band crosses).
    queue = [(_distance(grid, key, centre), key) for key in pending]
    heapq.heapify(queue)
    searched, unserved = [0] * (levels + 1), [0] * (levels + 1)
    while queue:
        _, key = heapq.heappop(queue)
        level = key[2]
        searched[level] += 1
        margin = margin_of(key)
        tries = max(MAX_TRIES // 4**level, 10)
        if np.any(margin >= 0.0) and _choose(
            boom, grid, triples, margin, key, chosen, buckets, min_margin, check_spacing, max_step, tries
        ):
            continue
        unserved[level] += 1
        if level < levels:
            for a, b in ((0, 0), (1, 0), (0, 1), (1, 1)):
                child = (2 * key[0] + a, 2 * key[1] + b, level + 1)
                if _holds_envelope(area, grid, child):
                    heapq.heappush(queue, (_distance(grid, child, centre), child))
    if progress is not None:
        for level in range(levels + 1):
            progress(
                f"level {level} ({float(grid.side(level)):g} m): {searched[level]} squares searched, "
                f"{unserved[level]} not served"
            )
    if not chosen:
        raise RuntimeError("no square of the grid can be covered: check the geometry and limits")
    keys = _repair(boom, grid, sorted(chosen), chosen, triples, check_spacing, max_step, progress)
    for _ in range(FILLS):
        added = _fill(
            boom,
            grid,
            area,
            keys,
            chosen,
            triples,
            margin_of,
            centre,
            levels,
            (min_margin, check_spacing, max_step),
        )
        if progress is not None:
            progress(f"fill: {len(added)} squares of {float(grid.side(levels)):g} m added in the gaps")
        if not added:
            break
        keys = _repair(boom, grid, sorted(keys + added), chosen, triples, check_spacing, max_step, progress)
    draft = _table(grid, keys, chosen, triples)
    search = {
        "step_deg": step_deg,
        "min_margin": min_margin,
        "check_spacing": check_spacing,
        "max_step": max_step,
        "start": [int(start[0]), int(start[1])],
        "levels": levels,
        "min_theta3": min_theta3,
        "fold_width": fold_width,
    }
    failures, checked, largest, covered = check_table(boom, draft, check_spacing, area)
    envelope = area.envelope | covered
    stats = {
        "squares": len(draft),
        "covered_area": draft.covered_area,
        "reachable_area": float((area.reachable | covered).sum() * area.cell_area),
        "envelope_area": float(envelope.sum() * area.cell_area),
        "covered_share": float(covered.sum() / envelope.sum()),
        "raster_cell": float(area.r_edges[1] - area.r_edges[0]),
        "raster_samples": area.samples,
        "band_failures": failures,
        "checked_points": checked,
        "largest_step": largest,
    }
    return RegionTable(
        grid=grid,
        index=draft.index,
        triples=draft.triples,
        margin=draft.margin,
        built_for=boom.table_key(),
        search=search,
        coverage=stats,
    )


def _choose(
    boom: PumpBoom,
    grid: Grid,
    triples: np.ndarray,
    margin: np.ndarray,
    key: Key,
    chosen: dict[Key, tuple[int, float]],
    buckets: dict[tuple[int, int], list[Key]],
    min_margin: float,
    check_spacing: float,
    max_step: float,
    tries: int,
) -> bool:
    """Steps 3-4 of the module docstring for one square: True (and the square in ``chosen``) if a
    candidate passes the check with the squares chosen so far around it."""
    side = float(grid.side(key[2]))
    home = _home(key)
    near = [
        k for di in (-1, 0, 1) for dj in (-1, 0, 1) for k in buckets.get((home[0] + di, home[1] + dj), ())
    ]
    points = _lattice(grid, key, check_spacing)
    tips = np.stack([points[..., 0], np.zeros(points.shape[:-1]), points[..., 1]], axis=-1)
    best = float(margin.max())
    pool = np.flatnonzero(margin >= min(min_margin, 0.5 * best))
    # The band never blends two shape families (regions.family), so squares of two families must
    # not touch, not even at a corner (a line through it would jump): only the family of the
    # touching neighbours, and a square touching two is split.
    touching = {family(triples[chosen[k][0]]).item() for k in near if _touch(grid, key, k)}
    if len(touching) > 1:
        return False
    if touching:
        pool = pool[family(triples[pool]) == touching.pop()]
    if near:
        # The triples the neighbours blend in around the square: prefer a candidate close to them.
        around = _table(grid, near, chosen, triples).blend(points[..., 0], points[..., 1])[0].reshape(-1, 3)
        around = around[np.isfinite(around[:, 0])]
    if near and len(around):
        difference = triples[pool] - around.mean(axis=0)
        cost = np.sum(difference * difference, axis=-1)
    else:
        cost = -margin[pool]
    limit = max_step * check_spacing / 0.1
    corner = np.array(grid.corner(*key), dtype=float)
    for k in _alone(
        boom, triples, pool[np.lexsort((pool, -margin[pool], cost))], points, corner, side, limit, tries
    ):
        draft = _table(grid, [*near, key], {**chosen, key: (int(k), 0.0)}, triples)
        result = boom.region_ik(tips, table=draft)
        inside = draft.contains(points[..., 0], points[..., 1])
        if np.all(result.ok[inside]) and _largest_step(result.q) <= limit:
            dense = float(square_margin(boom, triples[k : k + 1], corner, side, check_spacing)[0])
            chosen[key] = (int(k), dense)
            buckets.setdefault(home, []).append(key)
            return True
    return False


def _alone(
    boom: PumpBoom,
    triples: np.ndarray,
    order: np.ndarray,
    points: np.ndarray,
    corner: np.ndarray,
    side: float,
    limit: float,
    count: int,
) -> list[int]:
    """The first ``count`` candidates of ``order`` that pass step 4 on the square's own lattice
    points with their own triple (no neighbours): a vectorised pre-check over many candidates."""
    edge = 1e-9
    keep_r = (points[:, 0, 0] >= corner[0] - edge) & (points[:, 0, 0] <= corner[0] + side + edge)
    keep_z = (points[0, :, 1] >= corner[1] - edge) & (points[0, :, 1] <= corner[1] + side + edge)
    inner = points[keep_r][:, keep_z]
    passing: list[int] = []
    for start in range(0, min(len(order), SCAN * count), 256):
        chunk = order[start : start + 256]
        q, reachable, within, envelope = boom.complete(
            triples[chunk][:, None, None], inner[..., 0], inner[..., 1]
        )
        ok = (reachable & within & envelope).all(axis=(1, 2)) & (_largest_step(q) <= limit)
        passing += chunk[ok].tolist()
        if len(passing) >= count:
            break
    return passing[:count]


def _repair(
    boom: PumpBoom,
    grid: Grid,
    keys: list[Key],
    chosen: dict[Key, tuple[int, float]],
    triples: np.ndarray,
    spacing: float,
    max_step: float,
    progress: Callable[[str], None] | None,
) -> list[Key]:
    """Step 5 of the module docstring: the squares that pass the final check. Each pass solves a
    lattice half the check spacing apart over the whole table (it holds the check and coverage
    lattices) and every square's edges and corners at that spacing (small squares' edges are off
    the lattices), and where a point fails or a step of ``spacing`` from a lattice point along r
    and z exceeds ``max_step`` drops the square nearest to the point among the smallest under its
    window (the small squares' blend makes such points), until no point fails."""
    fine = 0.5 * spacing
    limit = max_step * spacing / 0.1
    half = 0.5 * grid.band
    for _ in range(REPAIRS):
        table = _table(grid, keys, chosen, triples)
        lattice = _lattice_over(table, fine)
        q, ok = _plane_ik(boom, lattice, table)
        # Steps of ``spacing`` (two fine points) from every fine point: the check lattice shifted.
        along_r = np.nan_to_num(np.abs(q[2:] - q[:-2]))[:, :-2]
        along_z = np.nan_to_num(np.abs(q[:, 2:] - q[:, :-2]))[:-2, :]
        steep = np.zeros(lattice.shape[:-1], dtype=bool)
        steep[:-2, :-2] = np.hypot(along_r, along_z).max(axis=-1) > limit
        steep[2:, :-2] |= steep[:-2, :-2]
        steep[:-2, 2:] |= steep[:-2, :-2]
        failed = table.contains(lattice[..., 0], lattice[..., 1]) & ~ok
        # Every square's edges, and steps of ``spacing`` from them along r and z (near the rims the
        # last two sections' angles change fastest at the edge, between the lattice points).
        edges = table_samples(table, fine)
        moves = np.array([[0.0, 0.0], [spacing, 0.0], [-spacing, 0.0], [0.0, spacing], [0.0, -spacing]])
        around, solved = _plane_ik(boom, edges[None] + moves[:, None], table)
        step = np.nan_to_num(np.abs(around[1:] - around[:1])).max(axis=-1).max(axis=0)
        bad = np.concatenate([lattice[steep | failed], edges[~solved[0] | (step > limit)]])
        if not len(bad):
            break
        low, high = table.extent[None, :, :2], table.extent[None, :, 2:]
        under = ((low < bad[:, None] + half) & (high > bad[:, None] - half)).all(axis=-1)
        level = np.where(under, table.index[None, :, 2], -1)
        gap = np.linalg.norm(np.clip(bad[:, None], low, high) - bad[:, None], axis=-1)
        smallest = under & (level == level.max(axis=1, keepdims=True))
        drop = set(np.argmin(np.where(smallest, gap, np.inf), axis=1).tolist())
        if progress is not None:
            progress(f"final check: {len(bad)} points fail, {len(drop)} squares dropped")
        keys = [key for k, key in enumerate(keys) if k not in drop]
    return keys


def _fill(
    boom: PumpBoom,
    grid: Grid,
    area: Coverage,
    keys: list[Key],
    chosen: dict[Key, tuple[int, float]],
    triples: np.ndarray,
    margin_of: Callable[[Key], np.ndarray],
    centre: np.ndarray,
    level: int,
    rules: tuple[float, float, float],
) -> list[Key]:
    """Step 6 of the module docstring: the squares of ``level`` (the smallest) added in the gaps of
    the table of ``keys``. Every square of that level holding a positive-envelope lattice point of
    ``area`` that the table does not cover is searched again (outward from ``centre``, as the
    front), with FILL_TRIES candidates and the squares around it now on every side; ``rules`` are
    (min_margin, check_spacing, max_step) of :func:`_choose`. The gaps are those the front left
    (its neighbours then were others) and those the final check opened."""
    table = _table(grid, keys, chosen, triples)
    covered = _plane_ik(boom, area.centres, table)[1]
    side = float(grid.side(level))
    cells = np.floor((area.centres[area.envelope & ~covered] - np.asarray(grid.origin)) / side).astype(int)
    cells = np.unique(cells, axis=0)
    # A cell of the smallest squares is wholly inside one square or in none.
    uncovered = table.owner(*grid.corner(cells[:, 0] + 0.5, cells[:, 1] + 0.5, level)) < 0
    gaps = [(i, j, level) for i, j in cells[uncovered].tolist()]
    gaps.sort(key=lambda key: (_distance(grid, key, centre), key))
    buckets: dict[tuple[int, int], list[Key]] = {}
    for key in keys:
        buckets.setdefault(_home(key), []).append(key)
    added = []
    for key in gaps:
        chosen.pop(key, None)
        margin = margin_of(key)
        if np.any(margin >= 0.0) and _choose(
            boom, grid, triples, margin, key, chosen, buckets, *rules, FILL_TRIES
        ):
            added.append(key)
    return added


def _fold_distance(boom: PumpBoom, area: Coverage, lowest: float) -> Callable[[float, float], float]:
    """Distance (m) from a plane point to the nearest positive-envelope lattice point of ``area``
    that no shape with theta3 >= ``lowest`` reaches (where section 2 must fold back)."""
    lower = boom.limits.lower.copy()
    lower[2] = lowest
    unfolded = PumpBoom(boom.root, boom.lengths, replace(boom.limits, lower=lower), boom.grid)
    cell = float(area.r_edges[1] - area.r_edges[0])
    folded = area.envelope & ~reachable_area(unfolded, area.samples, cell).envelope
    if not folded.any():
        return lambda r, z: math.inf
    distance = ndimage.distance_transform_edt(~folded) * cell
    r0, z0 = area.r_edges[0] + 0.5 * cell, area.z_edges[0] + 0.5 * cell

    def at(r: float, z: float) -> float:
        a = min(max(round((float(r) - r0) / cell), 0), distance.shape[0] - 1)
        b = min(max(round((float(z) - z0) / cell), 0), distance.shape[1] - 1)
        return float(distance[a, b])

    return at


def _home(key: Key) -> tuple[int, int]:
    """The level-0 square (i, j) holding square ``key``: its bucket of the squares chosen."""
    return key[0] >> key[2], key[1] >> key[2]


def _touch(grid: Grid, a: Key, b: Key) -> bool:
    """True if the closed squares ``a`` and ``b`` share a point (an edge or a corner)."""
    ra, za = (float(c) for c in grid.corner(*a))
    rb, zb = (float(c) for c in grid.corner(*b))
    sa, sb = float(grid.side(a[2])), float(grid.side(b[2]))
    return ra <= rb + sb and rb <= ra + sa and za <= zb + sb and zb <= za + sa


def _distance(grid: Grid, key: Key, centre: np.ndarray) -> float:
    """Distance (m) of a square's centre from ``centre`` (the visiting order)."""
    r, z = grid.corner(key[0] + 0.5, key[1] + 0.5, key[2])
    return math.hypot(float(r) - centre[0], float(z) - centre[1])


def _table(
    grid: Grid, keys: Sequence[Key], chosen: dict[Key, tuple[int, float]], triples: np.ndarray
) -> RegionTable:
    return RegionTable(
        grid=grid,
        index=np.array(keys, dtype=int).reshape(-1, 3),
        triples=triples[[chosen[k][0] for k in keys]],
        margin=np.array([chosen[k][1] for k in keys]),
        built_for={},
        search={},
        coverage={},
    )


def _holds_envelope(area: Coverage, grid: Grid, key: Key) -> bool:
    """True if a positive-envelope lattice point of ``area`` lies in the closed square ``key``."""
    side = float(grid.side(key[2]))
    r0, z0 = (float(c) for c in grid.corner(*key))
    cell = area.r_edges[1] - area.r_edges[0]
    a0 = max(0, math.floor((r0 - area.r_edges[0]) / cell - 0.5))
    b0 = max(0, math.floor((z0 - area.z_edges[0]) / cell - 0.5))
    a1 = math.ceil((r0 + side - area.r_edges[0]) / cell + 0.5)
    b1 = math.ceil((z0 + side - area.z_edges[0]) / cell + 0.5)
    return bool(area.envelope[a0:a1, b0:b1].any())


def _largest_step(q: np.ndarray) -> np.ndarray:
    """Largest joint change (rad) over one lattice step in any direction: per joint and lattice
    point the norm of its changes along r and z (a step (c, s) changes it by at most that), from a
    lattice of solutions (..., n_r, n_z, 6) (NaN outside the table: those differences do not
    count); shape (...)."""
    along_r = np.nan_to_num(np.abs(np.diff(q, axis=-3))[..., :, :-1, :])
    along_z = np.nan_to_num(np.abs(np.diff(q, axis=-2))[..., :-1, :, :])
    return np.hypot(along_r, along_z).max(axis=(-3, -2, -1), initial=0.0)


def _lattice(grid: Grid, key: Key, spacing: float) -> np.ndarray:
    """Points (n_r, n_z, 2) of the check lattice (grid origin + spacing * integers) in square ``key``
    widened by half a band and one lattice step on every side: every point whose triple the square's
    choice can change, and the steps from them to the points it does not change."""
    side, half = float(grid.side(key[2])), 0.5 * grid.band + spacing
    r0, z0 = (float(c) for c in grid.corner(*key))
    axes = []
    for low, origin in ((r0, grid.origin[0]), (z0, grid.origin[1])):
        first = math.ceil((low - half - origin) / spacing - 1e-9)
        last = math.floor((low + side + half - origin) / spacing + 1e-9)
        axes.append(origin + spacing * np.arange(first, last + 1))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def table_samples(table: RegionTable, spacing: float) -> np.ndarray:
    """(M, 2) plane points covering the table's squares at most ``spacing`` apart (edges included)."""
    points = []
    for level in np.unique(table.index[:, 2]):
        rows = table.index[table.index[:, 2] == level]
        side = float(table.grid.side(level))
        offsets = np.linspace(0.0, side, max(2, math.ceil(side / spacing - 1e-9) + 1))
        local = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2)
        corners = np.stack(table.grid.corner(rows[:, 0], rows[:, 1], level), axis=-1)
        points.append((corners[:, None] + local[None]).reshape(-1, 2))
    return np.concatenate(points) if points else np.empty((0, 2))


def check_table(
    boom: PumpBoom, table: RegionTable, spacing: float, area: Coverage | None = None
) -> tuple[int, int, float, np.ndarray]:
    """The region IK over the table's area: (failures, points checked, largest joint change per
    lattice step in any direction (rad), and with ``area`` its lattice points covered and solved).
    The check lattice is the grid origin + ``spacing`` * integers."""
    lattice = _lattice_over(table, spacing)
    q, ok = _plane_ik(boom, lattice, table)
    inside = table.contains(lattice[..., 0], lattice[..., 1])
    failures = int(np.sum(inside & ~ok))
    covered = np.zeros((0, 0), dtype=bool)
    if area is not None:
        centres = area.centres
        covered = _plane_ik(boom, centres, table)[1]
        failures += int(np.sum(table.contains(centres[..., 0], centres[..., 1]) & ~covered))
    return failures, int(inside.sum()), float(_largest_step(q)), covered


def _plane_ik(boom: PumpBoom, plane: np.ndarray, table: RegionTable) -> tuple[np.ndarray, np.ndarray]:
    """The region IK of boom-plane points (..., 2) (r, z) at theta1 = 0 with ``table``: q (..., 6)
    (NaN where it fails) and ok (...,), in blocks (the final check's lattices hold millions of
    points: in one piece their temporaries took 3.8 GB)."""

    def solve(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tips = np.stack([points[:, 0], np.zeros(len(points)), points[:, 1]], axis=-1)
        result = boom.region_ik(tips, table=table)
        return result.q, result.ok

    q, ok = in_blocks(solve, plane.reshape(-1, 2))
    return q.reshape(plane.shape[:-1] + (6,)), ok.reshape(plane.shape[:-1])


def _lattice_over(table: RegionTable, spacing: float) -> np.ndarray:
    """The check lattice (n_r, n_z, 2) over the bounding box of the table's squares."""
    extent = table.extent
    origin = table.grid.origin
    axes = []
    for k in (0, 1):
        first = math.floor((extent[:, k].min() - origin[k]) / spacing)
        last = math.ceil((extent[:, k + 2].max() - origin[k]) / spacing)
        axes.append(origin[k] + spacing * np.arange(first, last + 1))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def reachable_area(boom: PumpBoom, samples: int = SAMPLES, cell: float = RASTER) -> Coverage:
    """Lattice points (every ``cell``) of the pour plane in front of the slew axis that a joint state
    inside the limits reaches, and those it reaches in positive-envelope shape. Each point counts
    only with a certificate, a joint state with its tip exactly there: ``samples`` random states
    (fixed seed) lend their (theta2, theta3, theta4) to the lattice point of their tip's cell, then
    every certified point lends its triple to its 8 neighbours until no point is added (the last
    two sections solved in closed form, both elbow branches). A lower bound of the true area."""
    rng = np.random.default_rng(20220913)
    extent = boom.reach + float(np.abs(boom.root).max()) + cell
    r_edges = np.arange(0.0, extent + cell, cell)
    z_edges = np.arange(boom.root[1] - boom.reach - cell, boom.root[1] + boom.reach + 2 * cell, cell)
    shape = (len(r_edges) - 1, len(z_edges) - 1)
    seeds = {kind: np.full(shape + (3,), np.nan) for kind in ("reachable", "envelope")}
    lower, upper = boom.limits.lower.copy(), boom.limits.upper.copy()
    lower[0] = upper[0] = 0.0
    for start in range(0, samples, 200_000):
        q = lower + (upper - lower) * rng.random((min(200_000, samples - start), 6))
        tip = boom.plane_points(q)[:, -1]
        front = tip[:, 0] >= 0.0
        i = np.clip(np.searchsorted(r_edges, tip[:, 0], side="right") - 1, 0, shape[0] - 1)
        j = np.clip(np.searchsorted(z_edges, tip[:, 1], side="right") - 1, 0, shape[1] - 1)
        seeds["reachable"][i[front], j[front]] = q[front, 1:4]
        good = front & boom.positive_envelope(q)
        seeds["envelope"][i[good], j[good]] = q[good, 1:4]
    centres = 0.5 * np.stack(
        np.meshgrid(r_edges[:-1] + r_edges[1:], z_edges[:-1] + z_edges[1:], indexing="ij"), axis=-1
    )
    found = {}
    for kind, triple in seeds.items():
        envelope = kind == "envelope"
        certified = np.zeros(shape, dtype=bool)
        todo = np.isfinite(triple[..., 0])
        while todo.any():
            a, b = np.nonzero(todo)
            ok = _certifies(boom, centres[a, b], triple[a, b], envelope)
            certified[a[ok], b[ok]] = True
            new = np.zeros(shape, dtype=bool)
            new[a[ok], b[ok]] = True
            todo = np.zeros(shape, dtype=bool)
            lend = np.full(shape + (3,), np.nan)
            for da in (-1, 0, 1):
                for db in (-1, 0, 1):
                    source = np.zeros(shape, dtype=bool)
                    source[max(da, 0) : shape[0] + min(da, 0), max(db, 0) : shape[1] + min(db, 0)] = new[
                        max(-da, 0) : shape[0] + min(-da, 0), max(-db, 0) : shape[1] + min(-db, 0)
                    ]
                    target = source & ~certified & ~todo
                    ta, tb = np.nonzero(target)
                    lend[ta, tb] = triple[ta - da, tb - db]
                    todo |= target
            triple = np.where(todo[..., None], lend, triple)
        found[kind] = certified
    return Coverage(
        r_edges=r_edges,
        z_edges=z_edges,
        reachable=found["reachable"],
        envelope=found["envelope"],
        samples=samples,
    )


def _certifies(boom: PumpBoom, plane: np.ndarray, triples: np.ndarray, envelope: bool) -> np.ndarray:
    """(N,) True where a triple (N, 3) with either elbow branch of sections 4-5 puts the tip at the
    plane point (N, 2) inside the limits (and in positive-envelope shape if ``envelope``)."""
    q = np.concatenate([np.zeros((len(plane), 1)), triples, np.full((len(plane), 2), np.pi)], axis=-1)
    shoulder = boom.plane_points(q)[:, 3]
    phi3 = boom.section_angles(q)[:, 2]
    arm = two_link_ik(
        plane[:, 0] - shoulder[:, 0], plane[:, 1] - shoulder[:, 1], boom.lengths[3], boom.lengths[4], tol=1e-9
    )
    ok = np.zeros(len(plane), dtype=bool)
    for branch in (0, 1):
        q[:, 4] = wrap_angle(arm.theta1[:, branch] - phi3) + np.pi
        q[:, 5] = arm.theta2[:, branch] + np.pi
        good = arm.reachable & boom.limits.within(q, LIMIT_TOL)
        if envelope:
            good &= boom.positive_envelope(q)
        ok |= good
    return ok


def table_header(table: RegionTable, source: str) -> list[str]:
    """The comment lines at the top of a table file: what it is, how to rebuild it, its numbers."""
    c, grid, search = table.coverage, table.grid, table.search
    spacing = search["check_spacing"]
    levels, counts = np.unique(table.index[:, 2], return_counts=True)
    sizes = ", ".join(f"{n} of {float(grid.side(k)):g} m" for k, n in zip(levels.tolist(), counts.tolist()))
    header = [
        "Region table of the pump boom (paper 001, section 2.2). GENERATED: do not edit;",
        f"regenerate with: pump_boom_regions --config <machine file> (built from {source}).",
        f"Grid: squares of {grid.size:g} m with corners at r = {grid.origin[0]:g} + {grid.size:g} i,"
        f" z = {grid.origin[1]:g} + {grid.size:g} j (m), split into four down to {search['levels']} levels;"
        f" transition bands {grid.band:g} m.",
        f"Squares: {c['squares']} ({sizes}).",
        f"Coverage: {c['covered_area']:.1f} m^2; of the {c['envelope_area']:.1f} m^2 reachable in"
        f" positive-envelope shape (lattice points every {c['raster_cell']:g} m)"
        f" {100 * c['covered_share']:.2f} % covered; {c['reachable_area']:.1f} m^2 reachable in front of the"
        " slew axis.",
        f"Check: {c['checked_points']} points every {spacing:g} m, {c['band_failures']} failures;"
        f" largest joint change {math.degrees(c['largest_step']):.2f} deg per {spacing:g} m step.",
        "The squares, their extents and triples in degrees: pump_boom_regions --list"
        " [--output <table file>].",
    ]
    return header


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="pump_boom_regions",
        description="Build the pump boom's region table (paper 001, section 2.2) from a machine file.",
    )
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        help=f"machine parameters file (default: the shipped {CONFIG_FILE})",
    )
    parser.add_argument(
        "--output",
        type=Path,
        default=None,
        help="table file to write (default: regions.table_file in the source tree's config/)",
    )
    parser.add_argument("--step-deg", type=float, default=STEP_DEG, help="search grid of the triples (deg)")
    parser.add_argument("--min-margin", type=float, default=MIN_MARGIN, help="wanted clearance (m)")
    parser.add_argument("--check-spacing", type=float, default=CHECK_SPACING, help="check grid (m)")
    parser.add_argument(
        "--max-step-deg",
        type=float,
        default=math.degrees(MAX_STEP),
        help="largest joint change per 100 mm in any direction (deg)",
    )
    parser.add_argument("--levels", type=int, default=LEVELS, help="splittings below the 5 m squares")
    parser.add_argument(
        "--min-theta3-deg",
        type=float,
        default=math.degrees(MIN_THETA3),
        help="smallest theta3 searched (deg)",
    )
    parser.add_argument(
        "--fold-width",
        type=float,
        default=FOLD_WIDTH,
        help="folded shapes (theta3 < 15 deg) only this near the points needing them (m)",
    )
    parser.add_argument(
        "--list",
        action="store_true",
        help="print the squares of the table file (--output) and exit, building nothing",
    )
    args = parser.parse_args(argv)
    config = args.config if args.config is not None else config_path(CONFIG_FILE)
    try:
        section = load_parameters(config).get(SECTION, {})
        boom = PumpBoom.from_parameters(section)
        output = args.output
        if output is None:
            output = CONFIG_DIR / section["regions"]["table_file"]
        if args.list:
            print("\n".join(RegionTable.load(output, boom.table_key()).listing()))
            return 0
    except ConfigError as error:  # the machine file or the table: one line naming the key
        print(f"pump_boom_regions: {error}", file=sys.stderr)
        return 2
    area = reachable_area(boom)
    table = build_table(
        boom,
        args.step_deg,
        args.min_margin,
        args.check_spacing,
        math.radians(args.max_step_deg),
        args.levels,
        coverage=area,
        progress=print,
        min_theta3=math.radians(args.min_theta3_deg),
        fold_width=args.fold_width,
    )
    header = table_header(table, config.name)
    table.dump(output, header)
    for line in header[2:]:
        print(line)
    print(f"wrote {output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
