"""Build the pump boom's region table (paper 001, section 2.2) from its geometry: ``pump_boom_regions``.

For every 5 m square of the pour plane the builder searches (theta2, theta3, theta4) on a grid of
``step_deg`` over the joint limits, vectorised over all triples at once:

1. exact tests over the whole square, cheap: the farthest corner within L4 + L5 of section 3's
   end S, the square no closer than |L4 - L5| to S, and P_1..P_3 left of the chord root -> p for
   every corner (the chord's left side is a half plane through the root pin, so the corners
   decide for the whole square);
2. on the square sampled every 1 m: theta5 of the elbow-over 2R inside its limits and P_4 left
   of the chord; the triple's *margin* is the smallest clearance over the samples, in metres
   (a joint's distance from the chord, theta5's distance from a limit times L4, the distance from
   the 2R annulus' rims);
3. choice, deterministic: squares are visited from the one with the most valid triples outwards
   (by distance, ties by (i, j)); the first takes its largest-margin triple, every later one the
   triple closest (sum of squared angle differences) to its already chosen 4-neighbours among
   those whose margin is at least min(``min_margin``, half the square's best), so neighbouring
   triples are alike and transition bands move the joints little;
4. a choice is kept only if the region IK then solves every point of the check lattice
   (``check_spacing``) in the square widened by half a band on each side (every point whose
   triple it changes, the blends with the neighbours included) and no joint changes by more than
   ``max_step`` (10 deg) per 100 mm between lattice neighbours along r or z; else the next candidate, up to
   ``MAX_TRIES``; a square with no such triple is left out of the table (the paper: the automatic
   pour workspace is slightly smaller than the reachable one);
5. the finished table is checked the same way over its whole area (``band_failures``, 0 expected).

Coverage: the reachable area of the pour plane in front of the slew axis (r >= 0) and its
positive-envelope part are estimated from 2 * 10^6 joint states drawn uniformly inside the limits
(fixed seed), rasterised on 0.25 m cells.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manipulator_kinematics.params import CONFIG_DIR, config_path, load_parameters
from pump_boom_kinematics.kinematics import CONFIG_FILE, SECTION, PumpBoom
from pump_boom_kinematics.regions import Grid, RegionTable

STEP_DEG = 2.5
MIN_MARGIN = 0.3  # m
CHECK_SPACING = 0.1  # m
SCREEN_SPACING = 1.0  # m
RASTER = 0.25  # m, cell of the reachable-area estimate
SAMPLES = 2_000_000
CHUNK = 20_000
MAX_TRIES = 400  # candidates tried per square before it is left out of the table
MAX_STEP = math.radians(10.0)  # rad per 100 mm of tip motion along r or z, on the check lattice


@dataclass(frozen=True)
class Coverage:
    """Reachable-area raster of the pour plane (r >= 0): ``reachable`` and ``envelope`` (ni, nj)."""

    r_edges: np.ndarray
    z_edges: np.ndarray
    reachable: np.ndarray
    envelope: np.ndarray

    @property
    def cell_area(self) -> float:
        return float((self.r_edges[1] - self.r_edges[0]) * (self.z_edges[1] - self.z_edges[0]))


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
    boom: PumpBoom, triples: np.ndarray, corner: np.ndarray, size: float, spacing: float
) -> np.ndarray:
    """(N,) margin (m) of each triple over the square with lower-left ``corner`` (module docstring,
    steps 1-2); -inf where a test fails, so margin >= 0 means valid on the samples."""
    l4, l5 = boom.lengths[3], boom.lengths[4]
    root = boom.root
    joints, phi3 = _shoulder(boom, triples)
    shoulder = joints[:, 2]
    corners = corner + size * np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    far = np.linalg.norm(corners[None] - shoulder[:, None], axis=-1).max(axis=-1)
    near = np.linalg.norm(np.clip(shoulder, corner, corner + size) - shoulder, axis=-1)
    chord = corners - root  # (4, 2)
    rel = joints - root  # (N, 3, 2)
    cross = chord[None, :, None, 0] * rel[:, None, :, 1] - chord[None, :, None, 1] * rel[:, None, :, 0]
    cheap = (far <= l4 + l5) & (near >= abs(l4 - l5)) & (cross >= 0.0).all(axis=(1, 2))
    margin = np.full(len(triples), -np.inf)
    survivors = np.flatnonzero(cheap)
    n = round(size / spacing) + 1
    offsets = np.linspace(0.0, size, n)
    samples = (corner + np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1)).reshape(-1, 2)
    lo5, hi5 = boom.limits.lower[4], boom.limits.upper[4]
    for start in range(0, len(survivors), CHUNK):
        idx = survivors[start : start + CHUNK]
        s = shoulder[idx][:, None]  # (n, 1, 2)
        d_vec = samples[None] - s
        d = np.linalg.norm(d_vec, axis=-1)
        cos_beta = np.clip((l4 * l4 + d * d - l5 * l5) / (2.0 * l4 * np.maximum(d, 1e-12)), -1.0, 1.0)
        phi4 = np.arctan2(d_vec[..., 1], d_vec[..., 0]) + np.arccos(cos_beta)
        theta5 = (phi4 - phi3[idx][:, None] + np.pi) % (2.0 * np.pi)
        p4 = s + l4 * np.stack([np.cos(phi4), np.sin(phi4)], axis=-1)
        chord_s = samples - root
        length = np.linalg.norm(chord_s, axis=-1)
        fixed = rel[idx][:, None]  # (n, 1, 3, 2): P_1..P_3
        cross_fixed = chord_s[None, :, None, 0] * fixed[..., 1] - chord_s[None, :, None, 1] * fixed[..., 0]
        p4_rel = p4 - root
        cross4 = chord_s[None, :, 0] * p4_rel[..., 1] - chord_s[None, :, 1] * p4_rel[..., 0]
        distance = np.minimum(cross_fixed.min(axis=-1), cross4) / length
        clearance = np.minimum.reduce(
            [distance, (theta5 - lo5) * l4, (hi5 - theta5) * l4, l4 + l5 - d, d - abs(l4 - l5)]
        )
        margin[idx] = clearance.min(axis=-1)
    return margin


def build_table(
    boom: PumpBoom,
    step_deg: float = STEP_DEG,
    min_margin: float = MIN_MARGIN,
    check_spacing: float = CHECK_SPACING,
    max_step: float = MAX_STEP,
    coverage: Coverage | None = None,
) -> RegionTable:
    """The region table of ``boom``'s geometry and grid (module docstring)."""
    grid = boom.grid
    triples = candidate_triples(boom, step_deg)
    s = grid.size
    reach = boom.reach
    i_range = range(0, math.ceil((boom.root[0] + reach - grid.origin[0]) / s) + 1)
    j_range = range(
        math.floor((boom.root[1] - reach - grid.origin[1]) / s) - 1,
        math.ceil((boom.root[1] + reach - grid.origin[1]) / s) + 1,
    )
    margins: dict[tuple[int, int], np.ndarray] = {}
    for i in i_range:
        for j in j_range:
            corner = np.array(grid.corner(i, j), dtype=float)
            if corner[0] < boom.root[0] - 1e-12:
                continue
            corners = corner + s * np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
            if np.linalg.norm(corners - boom.root, axis=-1).max() > reach:
                continue
            margin = square_margin(boom, triples, corner, s, SCREEN_SPACING)
            if np.any(margin >= 0.0):
                margins[(i, j)] = margin
    if not margins:
        raise RuntimeError("no square of the grid can be covered: check the geometry and limits")
    start = max(margins, key=lambda key: (int(np.sum(margins[key] >= 0.0)), -key[0], -key[1]))
    order = sorted(margins, key=lambda key: (math.dist(key, start), key))
    chosen: dict[tuple[int, int], tuple[int, float]] = {}
    for key in order:
        margin = margins[key]
        best = float(margin.max())
        pool = np.flatnonzero(margin >= min(min_margin, 0.5 * best))
        neighbours = [
            chosen[n][0]
            for n in ((key[0] - 1, key[1]), (key[0] + 1, key[1]), (key[0], key[1] - 1), (key[0], key[1] + 1))
            if n in chosen
        ]
        if neighbours:
            difference = triples[pool][:, None] - triples[neighbours][None]
            cost = np.sum(difference * difference, axis=(1, 2))
        else:
            cost = -margin[pool]
        corner = np.array(grid.corner(*key), dtype=float)
        points = _lattice(grid, key, check_spacing)
        tips = np.stack([points[..., 0], np.zeros(points.shape[:-1]), points[..., 1]], axis=-1)
        limit = max_step * check_spacing / 0.1
        for k in pool[np.lexsort((pool, -margin[pool], cost))][:MAX_TRIES]:
            draft = _table(grid, {**chosen, key: (int(k), 0.0)}, triples)
            result = boom.region_ik(tips, table=draft)
            inside = draft.contains(points[..., 0], points[..., 1])
            if np.all(result.ok[inside]) and _largest_step(result.q) <= limit:
                dense = float(square_margin(boom, triples[k : k + 1], corner, s, check_spacing)[0])
                chosen[key] = (int(k), dense)
                break
    draft = _table(grid, chosen, triples)
    search = {
        "step_deg": step_deg,
        "min_margin": min_margin,
        "check_spacing": check_spacing,
        "max_step": max_step,
        "start": [int(start[0]), int(start[1])],
    }
    failures, checked = check_table(boom, draft, check_spacing)
    area = coverage if coverage is not None else reachable_area(boom)
    stats = {
        "squares": len(draft),
        "covered_area": len(draft) * s * s,
        "reachable_area": float(area.reachable.sum() * area.cell_area),
        "envelope_area": float(area.envelope.sum() * area.cell_area),
        "band_failures": failures,
        "checked_points": checked,
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


def _table(grid: Grid, chosen: dict[tuple[int, int], tuple[int, float]], triples: np.ndarray) -> RegionTable:
    keys = sorted(chosen)
    return RegionTable(
        grid=grid,
        index=np.array(keys, dtype=int).reshape(-1, 2),
        triples=triples[[chosen[k][0] for k in keys]],
        margin=np.array([chosen[k][1] for k in keys]),
        built_for={},
        search={},
        coverage={},
    )


def _largest_step(q: np.ndarray) -> float:
    """Largest joint change (rad) between neighbouring points of a lattice of solutions (n, n, 6)
    (NaN outside the table: those pairs do not count)."""
    steps = [np.abs(np.diff(q, axis=0)), np.abs(np.diff(q, axis=1))]
    return max((float(np.nanmax(d)) if np.any(np.isfinite(d)) else 0.0) for d in steps)


def _lattice(grid: Grid, key: tuple[int, int], spacing: float) -> np.ndarray:
    """Points of the check lattice (grid corner + spacing * integers) in square ``key`` widened by
    half a band on every side: every point whose triple the square's choice can change."""
    s, half = grid.size, 0.5 * grid.band
    n0, n1 = math.floor(-half / spacing), math.ceil((s + half) / spacing)
    offsets = np.arange(n0, n1 + 1) * spacing
    local = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1)
    return np.array(grid.corner(*key), dtype=float) + local


def table_samples(table: RegionTable, spacing: float) -> np.ndarray:
    """(M, 2) plane points covering the table's squares every ``spacing`` (edges included)."""
    s = table.grid.size
    n = round(s / spacing) + 1
    offsets = np.linspace(0.0, s, n)
    local = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2)
    corners = np.stack(table.grid.corner(table.index[:, 0], table.index[:, 1]), axis=-1)
    points = (corners[:, None] + local[None]).reshape(-1, 2)
    # Edge points shared by two squares belong to the upper one (floor); keep those in the table.
    return points[table.contains(points[:, 0], points[:, 1])]


def check_table(boom: PumpBoom, table: RegionTable, spacing: float) -> tuple[int, int]:
    """(failures, points checked): the region IK over the table's area sampled every ``spacing``."""
    plane = table_samples(table, spacing)
    points = np.stack([plane[:, 0], np.zeros(len(plane)), plane[:, 1]], axis=-1)
    return int(np.sum(~boom.region_ik(points, table=table).ok)), len(points)


def reachable_area(boom: PumpBoom, samples: int = SAMPLES, cell: float = RASTER) -> Coverage:
    """Reachable and positive-envelope cells of the pour plane in front of the slew axis."""
    rng = np.random.default_rng(20220913)
    extent = boom.reach + float(np.abs(boom.root).max()) + cell
    r_edges = np.arange(0.0, extent + cell, cell)
    z_edges = np.arange(boom.root[1] - boom.reach - cell, boom.root[1] + boom.reach + 2 * cell, cell)
    reachable = np.zeros((len(r_edges) - 1, len(z_edges) - 1), dtype=bool)
    envelope = np.zeros_like(reachable)
    lower, upper = boom.limits.lower.copy(), boom.limits.upper.copy()
    lower[0] = upper[0] = 0.0
    for start in range(0, samples, 200_000):
        q = lower + (upper - lower) * rng.random((min(200_000, samples - start), 6))
        tip = boom.plane_points(q)[:, -1]
        front = tip[:, 0] >= 0.0
        i = np.clip(np.searchsorted(r_edges, tip[:, 0], side="right") - 1, 0, reachable.shape[0] - 1)
        j = np.clip(np.searchsorted(z_edges, tip[:, 1], side="right") - 1, 0, reachable.shape[1] - 1)
        reachable[i[front], j[front]] = True
        good = front & boom.positive_envelope(q)
        envelope[i[good], j[good]] = True
    return Coverage(r_edges=r_edges, z_edges=z_edges, reachable=reachable, envelope=envelope)


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
    parser.add_argument(
        "--plots",
        type=Path,
        default=None,
        help="directory for the Fig. 5 / Fig. 6 style PNGs (none if not given)",
    )
    parser.add_argument("--step-deg", type=float, default=STEP_DEG, help="search grid of the triples (deg)")
    parser.add_argument("--min-margin", type=float, default=MIN_MARGIN, help="wanted clearance (m)")
    parser.add_argument("--check-spacing", type=float, default=CHECK_SPACING, help="check grid (m)")
    parser.add_argument(
        "--max-step-deg",
        type=float,
        default=math.degrees(MAX_STEP),
        help="largest joint change per 100 mm along r or z (deg)",
    )
    args = parser.parse_args(argv)
    config = args.config if args.config is not None else config_path(CONFIG_FILE)
    section = load_parameters(config).get(SECTION, {})
    boom = PumpBoom.from_parameters(section)
    output = args.output
    if output is None:
        output = CONFIG_DIR / section["regions"]["table_file"]
    area = reachable_area(boom)
    table = build_table(
        boom,
        args.step_deg,
        args.min_margin,
        args.check_spacing,
        math.radians(args.max_step_deg),
        coverage=area,
    )
    c, grid = table.coverage, table.grid
    header = [
        "Region table of the pump boom (paper 001, section 2.2). GENERATED: do not edit;",
        f"regenerate with: pump_boom_regions --config <machine file> (built from {config.name}).",
        f"Grid: squares of {grid.size:g} m with corners at r = {grid.origin[0]:g} + {grid.size:g} i,"
        f" z = {grid.origin[1]:g} + {grid.size:g} j (m); transition bands {grid.band:g} m.",
        f"Coverage: {c['squares']} squares = {c['covered_area']:.0f} m^2 of"
        f" {c['reachable_area']:.0f} m^2 reachable in front of the slew axis"
        f" ({100 * c['covered_area'] / c['reachable_area']:.1f} %) and"
        f" {c['envelope_area']:.0f} m^2 reachable in positive-envelope shape"
        f" ({100 * c['covered_area'] / c['envelope_area']:.1f} %).",
        f"Check: {c['checked_points']} points every {args.check_spacing:g} m, {c['band_failures']} failures.",
    ]
    table.dump(output, header)
    for line in header[2:]:
        print(line)
    print(f"wrote {output}")
    if args.plots is not None:
        from pump_boom_kinematics import plots

        args.plots.mkdir(parents=True, exist_ok=True)
        for path in (plots.plot_regions(boom, args.plots, area), plots.plot_example_area(boom, args.plots)):
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
