"""Pump-truck boom (paper 001): FK against the D-H chain, Jacobian against finite differences,
region IK round trips over the whole table, bands, envelope, the paper's example, pours."""

from __future__ import annotations

import base64
import math
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import yaml

from manipulator_kinematics.compiled import enabled as compiled_enabled
from manipulator_kinematics.model import IKStatus, RequestError, pose_matrix
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.time_scaling import ACCELERATION, TIP_SPEED
from pump_boom_kinematics import build_regions, kinematics, regions
from pump_boom_kinematics.kinematics import Failure, PumpBoom, RegionIK, RegionTableError, compiled_kernel
from pump_boom_kinematics.pour import ACCELERATION as TIP_ACCELERATION
from pump_boom_kinematics.pour import (
    MAX_DURATION,
    MAX_POINTS,
    MAX_WAYPOINTS,
    TYPICAL_POURS,
    plan_path,
    pour_line,
)
from pump_boom_kinematics.regions import RegionTable

#: The largest joint change per 100 mm of tip motion in any direction (issue #19 item 3); the builder
#: holds 7.5 deg on its 0.1 m lattice (the norm of the changes along r and z).
MAX_STEP = math.radians(8.0)


@pytest.fixture(scope="module")
def boom() -> PumpBoom:
    return PumpBoom.default()


@pytest.fixture(scope="module")
def random_q(boom: PumpBoom) -> np.ndarray:
    rng = np.random.default_rng(7)
    return boom.limits.lower + (boom.limits.upper - boom.limits.lower) * rng.random((2000, 6))


def _plane(boom: PumpBoom, spacing: float) -> np.ndarray:
    """Pour points (M, 3) at y = 0 every ``spacing`` over the table's squares, without the upper and
    right edges of the covered area (a half-open square each), moved 1 um toward their square's
    centre (points on edges are tested on their own, below)."""
    plane = build_regions.table_samples(boom.table, spacing)
    plane = plane[boom.table.contains(plane[:, 0] + 1e-7, plane[:, 1] + 1e-7)]
    i, j, level = boom.table.square(plane[:, 0], plane[:, 1]).T
    centre = np.stack(boom.grid.corner(i + 0.5, j + 0.5, level), axis=-1)
    plane = plane + 1e-6 * np.sign(centre - plane)
    return np.stack([plane[:, 0], np.zeros(len(plane)), plane[:, 1]], axis=-1)


def test_plane_geometry_equals_dh_chain(boom: PumpBoom, random_q: np.ndarray) -> None:
    frames = boom.frames(random_q)
    assert frames.shape == (2000, 7, 4, 4)
    np.testing.assert_allclose(frames[:, 1:, :3, 3], boom.points(random_q), atol=1e-12)
    np.testing.assert_allclose(boom.fkine(random_q)[:, :3, 3], boom.tip(random_q), atol=1e-12)


def test_straight_boom_and_paper_convention(boom: PumpBoom) -> None:
    # theta2 = 90 deg, every section straight on (180 deg): a vertical boom 41.5 m above the pin.
    up = np.array([0.3, math.pi / 2, math.pi, math.pi, math.pi, math.pi])
    np.testing.assert_allclose(
        boom.tip(up), [0.25 * math.cos(0.3), 0.25 * math.sin(0.3), 3.6 + 41.5], atol=1e-12
    )
    # Section 2 folded back onto section 1 (theta3 = 0): its end returns to the root pin's line.
    folded = np.array([0.0, 0.0, 0.0, math.pi, math.pi, math.pi])
    np.testing.assert_allclose(boom.points(folded)[2], [0.25 + 9.6 - 8.4, 0.0, 3.6], atol=1e-12)


def test_tip_jacobian_against_finite_differences_and_chain(boom: PumpBoom, random_q: np.ndarray) -> None:
    q = random_q[:200]
    jacobian = boom.tip_jacobian(q)
    h = 1e-6
    numeric = np.stack([(boom.tip(q + h * e) - boom.tip(q - h * e)) / (2 * h) for e in np.eye(6)], axis=-1)
    np.testing.assert_allclose(jacobian, numeric, atol=1e-7)
    np.testing.assert_allclose(boom.jacob0(q)[:, :3], jacobian, atol=1e-11)


def test_round_trip_on_the_whole_table(boom: PumpBoom) -> None:
    points = _plane(boom, 0.1)
    assert len(points) > 100_000
    heading = np.linspace(-math.pi, math.pi, len(points), endpoint=False)
    points = np.stack([points[:, 0] * np.cos(heading), points[:, 0] * np.sin(heading), points[:, 2]], axis=-1)
    result = boom.region_ik(points)
    assert result.ok.all(), result.reason(int(np.argmin(result.ok)))
    assert np.abs(boom.tip(result.q) - points).max() < 1e-9
    assert boom.limits.within(result.q).all()
    assert (boom.envelope_margin(result.q) >= 0.0).all()  # positive envelope at every pour point


def test_random_points_of_the_table(boom: PumpBoom) -> None:
    rng = np.random.default_rng(3)
    squares = boom.table.index[rng.integers(0, len(boom.table), 100_000)]
    side = boom.grid.side(squares[:, 2])[:, None]
    plane = np.stack(boom.table.grid.corner(*squares.T), axis=-1) + side * rng.random((100_000, 2))
    points = np.stack([plane[:, 0], np.zeros(len(plane)), plane[:, 1]], axis=-1)
    result = boom.region_ik(points)
    assert result.ok.all()
    assert np.abs(boom.tip(result.q) - points).max() < 1e-9


def test_triples_constant_inside_squares_and_blended_only_in_bands(boom: PumpBoom) -> None:
    points = _plane(boom, 0.1)
    result = boom.region_ik(points)
    square = boom.table.square(points[:, 0], points[:, 2])
    r0, z0 = boom.grid.corner(*square.T)
    side = boom.grid.side(square[:, 2])
    r, z = points[:, 0], points[:, 2]
    edge = np.minimum.reduce([r - r0, r0 + side - r, z - z0, z0 + side - z])
    core = edge > boom.grid.band / 2 + 1e-9
    own = boom.table.own_triple(points[:, 0], points[:, 2])
    np.testing.assert_array_equal(result.q[core, 1:4], own[core])
    assert not result.blended[core].any()
    assert core.sum() > 50_000 and result.blended[~core].mean() > 0.5  # band points mostly between squares


def test_window_blend_is_the_papers_partition_of_unity_on_equal_squares(boom: PumpBoom) -> None:
    """On squares of one size the window mean equals the bands' partition of unity a_k(u) b_l(v)
    (renormalised over the squares present), written out here independently; split into quarters
    the same squares give the same triples."""
    rng = np.random.default_rng(29)
    grid = boom.grid
    keys = np.array([(i, j) for i in range(8) for j in range(-3, 5) if rng.random() < 0.7])
    triples = rng.uniform(0.3, 3.0, (len(keys), 3))  # one shape family (unfolded: 0.3 rad > 15 deg)
    assert not regions.family(triples).any()
    level0 = RegionTable(
        grid,
        np.concatenate([keys, np.zeros((len(keys), 1), int)], axis=1),
        triples,
        np.zeros(len(keys)),
        {},
        {},
        {},
    )
    quarters = np.array([(2 * i + a, 2 * j + b, 1) for i, j in keys for a in (0, 1) for b in (0, 1)])
    level1 = RegionTable(grid, quarters, np.repeat(triples, 4, axis=0), np.zeros(len(quarters)), {}, {}, {})
    plane = np.stack([rng.uniform(0.0, 42.0, 50_000), rng.uniform(-16.0, 26.0, 50_000)], axis=-1)
    h = grid.band / (2 * grid.size)

    def ramp(x: np.ndarray) -> np.ndarray:
        return np.clip((x + h) / (2 * h), 0.0, 1.0)

    u = (plane[:, 0] - grid.origin[0]) / grid.size
    v = (plane[:, 1] - grid.origin[1]) / grid.size
    weight = (ramp(u[:, None] - keys[None, :, 0]) - ramp(u[:, None] - keys[None, :, 0] - 1)) * (
        ramp(v[:, None] - keys[None, :, 1]) - ramp(v[:, None] - keys[None, :, 1] - 1)
    )
    own = (np.floor(u)[:, None] == keys[None, :, 0]) & (np.floor(v)[:, None] == keys[None, :, 1])
    own = own.any(axis=1)
    with np.errstate(invalid="ignore"):  # points outside every square: no weight
        expected = weight @ triples / weight.sum(axis=1, keepdims=True)
    for table in (level0, level1):
        triple, inside = table.blend(plane[:, 0], plane[:, 1])
        np.testing.assert_array_equal(inside, own)
        np.testing.assert_allclose(triple[own], expected[own], rtol=0.0, atol=1e-10)
    assert (level0.blend(plane[:, 0], plane[:, 1])[0][own] != triples[level0.owner(*plane[own].T)]).any()


@pytest.mark.parametrize("axis", [0, 1])
def test_continuity_across_bands(boom: PumpBoom, axis: int) -> None:
    # Lines along r (axis 0) or z (axis 1) through the table every 0.1 m, 100 mm apart.
    step = np.zeros(2)
    step[axis] = 0.1
    start = _plane(boom, 0.1)
    after = start + np.array([step[0], 0.0, step[1]])
    a, b = boom.region_ik(start), boom.region_ik(after)
    both = a.ok & b.ok
    assert both.sum() > 100_000
    jump = np.abs(b.q[both] - a.q[both]).max()
    # The builder checks its lattice; these points are 1 um off it: 1 % slack.
    assert jump <= MAX_STEP * 1.01, math.degrees(jump)
    assert jump > math.radians(2.0)  # the bands do move the joints: the bound is not vacuous


def test_any_direction_step(boom: PumpBoom) -> None:
    rng = np.random.default_rng(11)
    start = _plane(boom, 0.25)
    angle = rng.uniform(0, 2 * math.pi, len(start))
    after = start + 0.1 * np.stack([np.cos(angle), np.zeros(len(angle)), np.sin(angle)], axis=-1)
    a, b = boom.region_ik(start), boom.region_ik(after)
    both = a.ok & b.ok
    assert np.abs(b.q[both] - a.q[both]).max() <= MAX_STEP


def test_random_lines_inside_the_covered_area(boom: PumpBoom) -> None:
    """Issue #19 item 3: straight lines in the boom plane inside the covered area, 100 mm steps,
    through the squares and the bands between them: every point solved exactly, inside the
    limits, in positive envelope, and no joint moves more than 8 deg per step."""
    rng = np.random.default_rng(19)
    plane = boom.table.random_lines(6000, rng)  # lines of 4 m, points 100 mm apart
    assert len(plane) > 2000
    points = np.stack([plane[..., 0], np.zeros(plane.shape[:-1]), plane[..., 1]], axis=-1)
    result = boom.region_ik(points)
    assert result.ok.all(), result.reason(tuple(np.argwhere(~result.ok)[0]))
    assert np.abs(boom.tip(result.q) - points).max() < 1e-9
    assert boom.limits.within(result.q).all() and (boom.envelope_margin(result.q) >= 0.0).all()
    jump = np.abs(np.diff(result.q, axis=1)).max()
    assert math.radians(5.0) < jump <= MAX_STEP, math.degrees(jump)


def test_points_on_edges_and_corners_belong_to_every_square_containing_them(boom: PumpBoom) -> None:
    table = boom.table
    side = boom.grid.side(table.index[:, 2])
    r0, z0 = boom.grid.corner(*table.index.T)
    fractions = np.array(
        [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.0], [0.5, 1.0], [0.0, 0.5], [1.0, 0.5]]
    )
    plane = np.stack([r0, z0], axis=-1)[:, None] + side[:, None, None] * fractions[None]
    assert table.contains(plane[..., 0], plane[..., 1]).all()
    points = np.stack([plane[..., 0], np.zeros(plane.shape[:-1]), plane[..., 1]], axis=-1).reshape(-1, 3)
    result = boom.region_ik(points)
    assert result.ok.all(), result.reason(int(np.argmin(result.ok)))
    assert np.abs(boom.tip(result.q) - points).max() < 1e-9
    # The round height: z = 30 m is the top edge of the 5 m square (3, 5).
    assert boom.region_ik([18.0, 0.0, 30.0]).ok and boom.region_ik([18.0, 0.0, 29.999]).ok


def test_a_refusal_names_the_nearest_covered_point(boom: PumpBoom) -> None:
    rng = np.random.default_rng(23)
    table = boom.table
    plane = np.stack([rng.uniform(0.0, 45.0, 4000), rng.uniform(-40.0, 47.0, 4000)], axis=-1)
    plane = plane[~table.contains(plane[:, 0], plane[:, 1])][:60]
    samples = build_regions.table_samples(table, 0.05)
    for r, z in plane.tolist():
        result = boom.region_ik([r, 0.0, z])
        assert not result.ok and "the nearest covered point is" in result.reason()
        near = table.nearest(r, z)
        assert boom.region_ik([near[0], 0.0, near[1]]).ok
        # No covered sample is nearer (the samples are at most 0.05 m apart on the squares).
        assert math.dist(near, (r, z)) <= np.hypot(*(samples - [r, z]).T).min() + 1e-12


@pytest.mark.slow
def test_single_point_path_equals_the_vectorised_ik(boom: PumpBoom, monkeypatch: pytest.MonkeyPatch) -> None:
    """region_ik_point (the compiled kernel, and before it is loaded region_ik on a batch of one)
    against region_ik over the table, its bands and around it: the same joints to 1e-12, the same
    failure and band flag for every point (the kernel's raw joints too where the failure needs them)."""
    rng = np.random.default_rng(17)
    inside = _plane(boom, 0.25)
    around = inside + np.stack(
        [
            rng.normal(scale=4.0, size=len(inside)),
            np.zeros(len(inside)),
            rng.normal(scale=4.0, size=len(inside)),
        ],
        axis=-1,
    )
    plane = np.concatenate([inside, around])
    heading = rng.uniform(-math.pi, math.pi, len(plane))
    points = np.stack([plane[:, 0] * np.cos(heading), plane[:, 0] * np.sin(heading), plane[:, 2]], axis=-1)
    points[:50] = [[np.nan, 0.0, 1.0], [60.0, 0.0, 3.6], [0.1, 0.0, 10.0], [0.0, 0.0, 10.0], *points[4:50]]
    slew = rng.uniform(-6.0, 6.0, len(points))
    seed = np.zeros((len(points), 6))
    seed[:, 0] = slew
    expected = boom.region_ik(points, seed=seed)
    assert len(points) >= 10_000
    kernel = compiled_kernel(boom, wait=True) if compiled_enabled() else None
    q = np.full((len(points), 6), np.nan)
    failure = np.empty(len(points), dtype=int)
    for k, (point, s) in enumerate(zip(points.tolist(), slew.tolist(), strict=True)):
        solution, failure[k] = boom.region_ik_point(*point, s)
        if solution is not None:
            q[k] = solution
    np.testing.assert_array_equal(failure, expected.failure)
    assert set(failure.tolist()) >= {
        Failure.NONE,
        Failure.NOT_FINITE,
        Failure.BEYOND_REACH,
        Failure.BEHIND_ROOT,
        Failure.NOT_IN_TABLE,
    }
    assert expected.blended.sum() > 5000  # the bands are well sampled
    np.testing.assert_allclose(q, expected.q, atol=1e-12)  # NaN where both fail
    unseeded, _ = boom.region_ik_point(-20.0, 5.0, 17.5)
    assert unseeded == pytest.approx(tuple(boom.region_ik([-20.0, 5.0, 17.5]).q), abs=1e-12)
    # Without the kernel (not loaded yet, or MK_COMPILED=0): region_ik on a batch of one.
    monkeypatch.setattr(kinematics, "compiled_kernel", lambda boom, wait=False: None)
    for k in range(0, len(points), 20):
        solution, code = boom.region_ik_point(*points[k].tolist(), slew[k])
        assert code == expected.failure[k]
        assert (solution is None) == (code != Failure.NONE)
        if solution is not None:
            np.testing.assert_allclose(solution, expected.q[k], atol=1e-12)
    monkeypatch.undo()
    if kernel is None:
        return
    _kernel_equals_numpy(kernel, boom, points, slew, expected)
    # A table of jittered triples fails in the steps the shipped table never fails in.
    table = boom.table
    jittered = RegionTable(
        grid=table.grid,
        index=table.index,
        triples=table.triples + rng.normal(scale=0.2, size=table.triples.shape),
        margin=table.margin,
        built_for=table.built_for,
        search=table.search,
        coverage=table.coverage,
    )
    other = PumpBoom(boom.root, boom.lengths, boom.limits, boom.grid, table=jittered)
    inside_points = points[: len(inside)]
    failures = _kernel_equals_numpy(
        kernel,
        other,
        inside_points,
        slew[: len(inside)],
        other.region_ik(inside_points, seed=seed[: len(inside)]),
    )
    for code in (Failure.NONE, Failure.TWO_LINK, Failure.JOINT_LIMITS, Failure.ENVELOPE):
        assert np.sum(failures == code) > 100, (code, np.bincount(failures))


def _kernel_equals_numpy(
    kernel: ModuleType, boom: PumpBoom, points: np.ndarray, slew: np.ndarray, expected: RegionIK
) -> np.ndarray:
    """The kernel against region_ik (seeded): the same failures and band flags, joints to 1e-12
    where solved and, before the failure mask, where the steps that fill every joint ran."""
    raw, blended = np.full((len(points), 6), np.nan), np.zeros(len(points), dtype=bool)
    failures = np.empty(len(points), dtype=int)
    for k, (point, s) in enumerate(zip(points.tolist(), slew.tolist(), strict=True)):
        failures[k], blended[k] = kernel.region_ik(*boom._kernel_args, *point, s, True, raw[k])
    np.testing.assert_array_equal(failures, expected.failure)
    reached = failures >= Failure.TWO_LINK
    np.testing.assert_allclose(raw[reached], expected.raw[reached], atol=1e-12)
    in_table = failures >= Failure.NOT_IN_TABLE
    np.testing.assert_array_equal(blended[in_table], expected.blended[in_table])
    return failures


def test_paper_example_area(boom: PumpBoom) -> None:
    q = boom.example_sweep(401)
    tips = boom.plane_points(q)[..., -1, :].reshape(-1, 2)
    envelope = boom.positive_envelope(q).reshape(-1)

    def area(p: np.ndarray) -> float:
        return len({tuple(c) for c in np.floor(p / 0.1).astype(int).tolist()}) * 0.01

    assert 140.0 < area(tips) < 165.0
    assert 0.87 < area(tips[envelope]) / area(tips) < 0.91  # the reference note's "about 89 %"
    # The 2R of the IK recovers the example's theta5, theta6 from its tips with the example's triple.
    corner = np.floor(tips.min(axis=0) / 5.0).astype(int) - 1
    extent = np.ceil(tips.max(axis=0) / 5.0).astype(int) + 1
    squares = np.stack(
        np.meshgrid(np.arange(corner[0], extent[0]), np.arange(corner[1], extent[1]), indexing="ij"), axis=-1
    ).reshape(-1, 2)
    grid = type(boom.grid)((0.0, 0.0), 5.0, 1.0)
    table = RegionTable(
        grid=grid,
        index=np.concatenate([squares, np.zeros((len(squares), 1), dtype=int)], axis=1),
        triples=np.tile(q[0, 0, 1:4], (len(squares), 1)),
        margin=np.zeros(len(squares)),
        built_for={},
        search={},
        coverage={},
    )
    flat = q.reshape(-1, 6)[envelope]
    result = boom.region_ik(boom.tip(flat), table=table)
    assert result.ok.all()
    np.testing.assert_allclose(result.q, flat, atol=1e-9)


@pytest.mark.skipif(not compiled_enabled(), reason="MK_COMPILED=0: the kernel is off")
# Every 10th pour point of a 4 m sampling of the table (873) in the fast tier; all 8,730 slow.
@pytest.mark.parametrize("every", [10, pytest.param(1, marks=pytest.mark.slow)])
def test_one_target_through_the_kernel_equals_a_batch_of_one(boom: PumpBoom, every: int) -> None:
    """solve_ik of one target (the kernel once loaded) against the same target as a batch (numpy):
    joints to 1e-12, statuses, selections and reasons equal, solved and failing targets."""
    compiled_kernel(boom, wait=True)
    rng = np.random.default_rng(29)
    # Points off the table cost a nearest-covered-point search each (the reason's text).
    off_table = rng.uniform([-5.0, -45.0], [60.0, 50.0], (100 // every, 2))
    plane = np.concatenate([_plane(boom, 4.0)[::every, [0, 2]], off_table])
    heading = rng.uniform(-math.pi, math.pi, len(plane))
    points = np.stack([plane[:, 0] * np.cos(heading), plane[:, 0] * np.sin(heading), plane[:, -1]], axis=-1)
    points[0] = [np.nan, 0.0, 1.0]
    seeds = np.zeros((len(points), 6))
    seeds[:, 0] = rng.uniform(-6.0, 6.0, len(points))
    statuses = set()
    for point, seed in zip(points, seeds, strict=True):
        one = boom.solve_ik(pose_matrix(point), use_orientation=False, seed=seed)
        batch = boom.solve_ik(pose_matrix(point)[None], use_orientation=False, seed=seed[None])
        np.testing.assert_allclose(one.q, batch.q[0], atol=1e-12)
        np.testing.assert_array_equal(one.status, batch.status[0])
        assert one.selected == batch.selected[0] and one.note() == batch.note(0)
        statuses.add(int(one.status[0]))
    assert statuses >= {IKStatus.SUCCESS, IKStatus.UNREACHABLE, IKStatus.INVALID}


def test_behind_the_slew_axis(boom: PumpBoom, random_q: np.ndarray) -> None:
    behind = np.array([-20.0, 5.0, 17.5])
    result = boom.region_ik(behind)
    assert result.ok and math.isclose(result.q[0], math.atan2(5.0, -20.0))
    np.testing.assert_allclose(boom.tip(result.q), behind, atol=1e-9)
    # With a seed the slew turn nearest to it is taken (no swing round by 2 pi).
    turned = boom.region_ik(behind, seed=np.array([-3.0, 1, 2, 2, 2, 2]))
    assert math.isclose(turned.q[0], math.atan2(5.0, -20.0) - 2 * math.pi)
    np.testing.assert_allclose(boom.tip(turned.q), behind, atol=1e-9)
    # Joint states with the tip behind the slew axis: the IK answers with theta1 + pi, tip in front.
    tips = boom.tip(random_q)
    plane_r = boom.plane_points(random_q)[:, -1, 0]
    solved = boom.region_ik(tips[plane_r < 0])
    assert (plane_r < 0).mean() > 0.1 and solved.ok.any()
    turn = np.abs((solved.q[solved.ok, 0] - random_q[plane_r < 0][solved.ok, 0]) % (2 * math.pi) - math.pi)
    assert turn.max() < 1e-9


def test_failures_with_reasons(boom: PumpBoom) -> None:
    points = np.array(
        [[40.7, 0.0, 12.0], [60.0, 0.0, 3.6], [0.1, 0.0, 10.0], [np.nan, 0.0, 1.0], [0.0, 0.0, 10.0]]
    )
    result = boom.region_ik(points)
    assert list(result.failure) == [
        Failure.NOT_IN_TABLE,
        Failure.BEYOND_REACH,
        Failure.BEHIND_ROOT,
        Failure.NOT_FINITE,
        Failure.BEHIND_ROOT,
    ]
    assert np.isnan(result.q).all()
    assert "outside the region table" in result.reason(0) and "square (8, 2)" in result.reason(0)
    assert "beyond the boom's reach" in result.reason(1)
    assert "behind the boom root pin" in result.reason(2)


def test_solve_ik_protocol(boom: PumpBoom) -> None:
    targets = np.stack([pose_matrix(p) for p in ([20.0, 5.0, 17.5], [40.7, 0.0, 12.0])])
    solutions = boom.solve_ik(targets, use_orientation=False, mode="region")
    assert solutions.q.shape == (2, 1, 6) and list(solutions.selected) == [0, -1]
    assert solutions.outcome[1] == IKStatus.UNREACHABLE
    assert "outside the region table" in solutions.note(1)
    np.testing.assert_allclose(boom.tip(solutions.solution[0]), [20.0, 5.0, 17.5], atol=1e-9)
    single = boom.solve_ik(targets[0], use_orientation=False)  # the kernel: the band's sums in its order
    np.testing.assert_allclose(single.solution, solutions.solution[0], rtol=0.0, atol=1e-12)
    with pytest.raises(RequestError, match="position only"):
        boom.solve_ik(targets[0])
    with pytest.raises(RequestError, match="unknown IK mode"):
        boom.solve_ik(targets[0], use_orientation=False, mode="phi")
    with pytest.raises(RequestError, match="unknown branch"):
        boom.solve_ik(targets[0], use_orientation=False, branch="elbow_a")


@pytest.mark.parametrize("name", list(TYPICAL_POURS))
def test_typical_pours(boom: PumpBoom, name: str) -> None:
    _, start, end = TYPICAL_POURS[name]
    plan = pour_line(boom, start, end)
    assert plan.ok and not plan.truncated and plan.last_waypoint == 1
    length = float(np.linalg.norm(np.subtract(end, start)))
    assert len(plan.points) == math.ceil(length / 0.1 - 1e-9) + 1  # eqs. 5-6
    np.testing.assert_allclose(boom.tip(plan.q), plan.points, atol=1e-9)
    assert_timed(boom, plan, np.subtract(end, start) / length, boom.tip_speed)
    # Slower than the constant tip speed only by the start, the stop and the joint limits.
    assert plan.t[-1] >= length / boom.tip_speed + boom.tip_speed / TIP_ACCELERATION
    assert np.mean(plan.active == TIP_SPEED) > 0.85
    assert np.abs(np.diff(plan.q, axis=0)).max() <= MAX_STEP
    assert plan.blended.any() and (~plan.blended).any()
    own = boom.table.own_triple(np.hypot(plan.points[:, 0], plan.points[:, 1]), plan.points[:, 2])
    np.testing.assert_array_equal(plan.q[~plan.blended, 1:4], own[~plan.blended])
    slew = np.ptp(plan.q[:, 0])
    if name == "horizontal_line":
        assert slew < 1e-12 and np.ptp(plan.points[:, 2]) < 1e-12
    else:
        assert slew > 1.0 and np.all(np.diff(plan.q[:, 0]) > 0)


def assert_timed(boom: PumpBoom, plan, direction: np.ndarray, tip_speed: float) -> None:
    """The plan's timing: at rest at both ends, no joint above its speed limit (relative 1e-12), the
    tip no faster than asked and exactly as asked where the tip speed is what limits it, |sdd| within
    the bound; the tip velocity J(q) qd is the speed along the line (the boom's own Jacobian)."""
    assert plan.t[0] == 0.0 and np.all(np.diff(plan.t) > 0.0)
    np.testing.assert_array_equal(plan.qd[[0, -1]], 0.0)
    assert np.all(np.abs(plan.qd) <= boom.joint_speed * (1.0 + 1e-12))
    assert np.all(plan.speed <= tip_speed)
    np.testing.assert_array_equal(plan.speed[plan.active == TIP_SPEED], tip_speed)
    assert np.all(np.abs(plan.timing.sdd) <= TIP_ACCELERATION * (1.0 + 1e-9))
    # The region IK's q(s) has kinks at the band edges, where the central difference of 100 mm
    # samples is off by up to ~8 % of the speed (2.8 % at 25 mm): bounded there, tight on average.
    tip_velocity = np.einsum("nij,nj->ni", boom.tip_jacobian(plan.q), plan.qd)
    error = np.linalg.norm(tip_velocity - plan.speed[:, None] * direction, axis=1) / tip_speed
    assert error.max() < 0.1 and np.sqrt(np.mean(error**2)) < 0.015, (error.max(), np.sqrt(np.mean(error**2)))
    assert plan.qdd.shape == plan.q.shape and np.all(np.isfinite(plan.qdd))


def test_joint_speed_limits_slow_the_pour_where_they_bind(boom: PumpBoom) -> None:
    _, start, end = TYPICAL_POURS["slanted_line"]
    direction = np.subtract(end, start) / np.linalg.norm(np.subtract(end, start))
    section = load_parameters(config_path("pump_boom.yaml"))["pump_boom"]
    section["joint_max_speed"] = [0.005, 0.06, 0.08, 0.08, 0.1, 0.1]  # a slow slew
    slow = PumpBoom.from_parameters(section)
    fast, limited = pour_line(boom, start, end), pour_line(slow, start, end)
    assert_timed(slow, limited, direction, slow.tip_speed)
    np.testing.assert_array_equal(limited.q, fast.q)  # the same path, timed differently
    assert limited.t[-1] > 1.5 * fast.t[-1]
    at_limit = limited.active == 0
    assert at_limit.mean() > 0.5 and "slew_joint" in limited.message
    # At the limit at the sample or on a chord next to it (the slew is smooth: within 0.5 %).
    assert np.all(np.abs(limited.qd[at_limit, 0]) >= 0.005 * (1.0 - 5e-3))
    assert np.all(limited.speed[at_limit] < slow.tip_speed)
    assert set(np.unique(limited.active).tolist()) <= {TIP_SPEED, ACCELERATION, 0, 5}


def test_pour_end_outside_is_replaced_by_farthest_reachable_point(boom: PumpBoom) -> None:
    plan = pour_line(boom, (20.0, 0.0, 17.5), (45.0, 0.0, 17.5))
    assert plan.ok and plan.truncated and plan.last_waypoint == 0
    assert "farthest reachable point" in plan.message
    assert boom.region_ik(plan.end).ok
    assert not boom.region_ik(plan.end + [2e-6, 0.0, 0.0]).ok
    np.testing.assert_allclose(plan.points[-1], plan.end)
    assert np.linalg.norm(np.diff(plan.points, axis=0), axis=1).max() <= 0.1 + 1e-12
    nothing = plan_path(boom, [[60.0, 0.0, 3.6], [20.0, 0.0, 17.5]])
    assert not nothing.ok and nothing.last_waypoint == -1 and len(nothing.q) == 0


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"step": 1e-10}, r"step 1e-10 m is outside \[0.001, 10\] m"),
        ({"step": math.nan}, "step nan m is outside"),
        (
            {"step": 0.002, "waypoints": [[20.0, 5.0, 17.5], [70.0, 5.0, 17.5]]},
            rf"would have 2.5e\+04 points at step 0.002 m; at most {MAX_POINTS}",
        ),
        ({"waypoints": [[20.0, 5.0, 17.5], [1e300, 5.0, 17.5]]}, f"at most {MAX_POINTS}"),
        (
            {"waypoints": [[20.0, 5.0, 17.5], [1.7e308, 5.0, 17.5], [-1.7e308, 5.0, 17.5]]},
            f"at most {MAX_POINTS}",
        ),
        ({"waypoints": [[20.0, 5.0, 17.5]] * (MAX_WAYPOINTS + 1)}, f"1 <= K <= {MAX_WAYPOINTS}"),
        ({"waypoints": [[20.0, 5.0, math.inf]]}, "finite"),
        ({"tip_speed": 1e-300}, "tip_speed 1e-300 m/s is outside"),
        ({"tip_speed": 5e-324}, "tip_speed 4.94066e-324 m/s is outside"),  # denormal
        ({"tip_speed": 1e300}, r"tip_speed 1e\+300 m/s is outside"),
        ({"tip_speed": math.inf}, "tip_speed inf m/s is outside"),
        ({"tip_speed": math.nan}, "tip_speed nan m/s is outside"),
        ({"tip_speed": -0.2}, "tip_speed -0.2 m/s is outside"),
        ({"acceleration": 0.0}, r"acceleration 0 m/s\^2 is outside"),
        ({"acceleration": math.inf}, r"acceleration inf m/s\^2 is outside"),
        (
            {"tip_speed": 0.001, "waypoints": [[20.0, 5.0, 17.5], [24.0, 5.0, 17.5]] * 20},
            rf"at least 1.56e\+05 s at 0.001 m/s; at most {MAX_DURATION:g} s",
        ),
    ],
)
def test_a_plan_out_of_bounds_is_refused_before_any_work(boom: PumpBoom, change: dict, match: str) -> None:
    request = {"waypoints": [[20.0, 5.0, 17.5], [24.0, 5.0, 17.5]]} | change
    with pytest.raises(ValueError, match=match):
        plan_path(boom, **request)


def test_table_file_matches_the_machine(boom: PumpBoom) -> None:
    assert boom.table_problem() is None
    coverage = boom.table.coverage
    assert coverage["squares"] == len(boom.table) >= 42 and coverage["band_failures"] == 0
    assert coverage["covered_area"] == pytest.approx(boom.table.covered_area)
    assert coverage["covered_area"] < coverage["envelope_area"]
    # The builder's final check, run again, gives the recorded numbers.
    spacing = boom.table.search["check_spacing"]
    failures, checked, largest, _ = build_regions.check_table(boom, boom.table, spacing)
    assert failures == coverage["band_failures"] == 0 and checked == coverage["checked_points"]
    assert largest == pytest.approx(coverage["largest_step"], rel=1e-9)
    section = load_parameters(config_path("pump_boom.yaml"))["pump_boom"]
    section["lenghts"] = section.pop("lengths")
    with pytest.raises(ConfigError, match=r"pump_boom\.lenghts.*did you mean 'lengths'"):
        PumpBoom.from_parameters(section)


def test_lookup_arrays_are_the_squares_drawn_one_by_one(boom: PumpBoom) -> None:
    """The cell owners (filled level by level at load) against each square drawn on the cells on
    its own from its corner in metres; a new table of the same squares first used from four
    threads at once (a node's executor) gives the same blends and nearest points."""
    table = boom.table
    constants, owner, _ = table.lookup
    cell, lower = constants[2], constants[3:5]
    drawn = np.full(owner.shape, -1)
    for k, (i, j, level) in enumerate(table.index.tolist()):
        corner = np.array(boom.grid.corner(i, j, level), dtype=float)
        a, b = np.rint((corner - boom.grid.origin) / cell - lower).astype(int)
        n = round(float(boom.grid.side(level)) / cell)
        assert (drawn[a : a + n, b : b + n] == -1).all()
        drawn[a : a + n, b : b + n] = k
    np.testing.assert_array_equal(owner, drawn)
    assert (owner >= 0).sum() * cell**2 == pytest.approx(table.covered_area, rel=1e-12)
    fresh = RegionTable(table.grid, table.index, table.triples, table.margin, {}, {}, {})
    rng = np.random.default_rng(31)
    r, z = rng.uniform(0.0, 45.0, 2000), rng.uniform(-30.0, 45.0, 2000)
    blend = table.blend(r, z)[0]
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda _: (fresh.blend(r, z)[0], fresh.nearest(50.0, 50.0)), range(8)))
    for blended, near in results:
        np.testing.assert_array_equal(blended, blend)
        assert near == table.nearest(50.0, 50.0)


def test_band_mean_is_the_area_weighted_mean_of_the_squares_under_the_window(boom: PumpBoom) -> None:
    """In the bands of the shipped table (squares of six sizes, gaps, shape families) the blend
    against the mean of the triples of the squares of the point's family weighted by the area each
    shares with the window, in metres from the squares' corners (no cells); a window over squares
    of one triple gives that triple exactly."""
    table = boom.table
    rng = np.random.default_rng(37)
    rows = rng.integers(0, len(table), 4000)
    side = boom.grid.side(table.index[rows, 2])[:, None]
    corner = np.stack(boom.grid.corner(*table.index[rows].T), axis=-1)
    plane = corner + side * rng.random((len(rows), 2))
    triple, inside = table.blend(plane[:, 0], plane[:, 1])
    assert inside.all()
    low = np.stack(boom.grid.corner(*table.index.T), axis=-1)
    high = low + boom.grid.side(table.index[:, 2])[:, None]
    half = 0.5 * boom.grid.band
    sides = np.minimum(plane[:, None] + half, high) - np.maximum(plane[:, None] - half, low)
    overlap = np.prod(np.clip(sides, 0.0, None), axis=-1)  # (points, squares) m^2
    families = regions.family(table.triples)
    overlap *= families[None] == families[table.owner(plane[:, 0], plane[:, 1])][:, None]
    expected = overlap @ table.triples / overlap.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(triple, expected, rtol=0.0, atol=1e-12)
    own = table.own_triple(plane[:, 0], plane[:, 1])
    blended = np.any(triple != own, axis=-1)
    one_triple = ((overlap == 0.0) | (table.triples[None] == own[:, None]).all(axis=-1)).all(axis=1)
    assert blended.sum() > 2000 and one_triple.sum() > 200
    np.testing.assert_array_equal(blended, ~one_triple)
    # One point (0-d) in a band: its blend, and the table's triples untouched.
    before = table.triples.copy()
    k = int(np.argmax(blended))
    np.testing.assert_array_equal(table.blend(*plane[k])[0], triple[k])
    np.testing.assert_array_equal(table.triples, before)


def test_the_band_never_blends_two_shape_families(boom: PumpBoom) -> None:
    """A folded square between two unfolded ones: these keep their own triples at the folded one's
    edges (it drops out like a missing square), and it keeps its own; an unfolded square blends
    with a small unfolded one across a gap narrower than the band; the compiled kernel the same. In the
    shipped table every blend keeps the family of its square, and no squares of two families touch
    (the builder leaves a gap between them: a line through a shared point would jump)."""
    unfolded, folded = np.radians([60.0, 150.0, 120.0]), np.radians([80.0, 5.0, 120.0])
    # (48, 30, 4): r 15.25-15.5625, z 9.375-9.6875, under the folded (3, 2) across a 0.3125 m gap.
    index = np.array([[2, 2, 0], [3, 2, 0], [4, 2, 0], [48, 30, 4]])
    other = np.radians([62.0, 152.0, 118.0])
    triples = np.stack([unfolded, folded, unfolded, other])
    table = RegionTable(boom.grid, index, triples, np.zeros(4), {}, {}, {})
    assert regions.family(table.triples).tolist() == [0, 1, 0, 0]
    r = boom.grid.origin[0] + 5.0 * np.array([3.0 - 0.2 / 5, 3.0 + 0.2 / 5, 4.0 - 0.2 / 5, 4.0 + 0.2 / 5])
    z = np.full(4, 12.5)
    np.testing.assert_array_equal(table.blend(r, z)[0], np.stack([unfolded, folded, folded, unfolded]))
    # The window of a point of (2, 2) by its corner next to the folded square reaches (48, 30, 4),
    # of its own family: a blend (the folded square under the window drops out).
    corner = np.array([15.25 - 0.1, 10.0 + 0.1])
    blend = table.blend(*corner)[0]
    assert np.all(blend != unfolded) and regions.family(blend) == 0
    shipped = boom.table
    rng = np.random.default_rng(43)
    rows = rng.integers(0, len(shipped), 20_000)
    side = boom.grid.side(shipped.index[rows, 2])[:, None]
    plane = np.stack(boom.grid.corner(*shipped.index[rows].T), axis=-1) + side * rng.random((len(rows), 2))
    triple, inside = shipped.blend(plane[:, 0], plane[:, 1])
    families = regions.family(shipped.triples)
    assert inside.all() and len(set(families.tolist())) > 1
    np.testing.assert_array_equal(regions.family(triple), families[rows])
    low = np.stack(boom.grid.corner(*shipped.index.T), axis=-1)
    high = low + boom.grid.side(shipped.index[:, 2])[:, None]
    touch = ((low[:, None] <= high[None]) & (low[None] <= high[:, None])).all(axis=-1)
    assert not (touch & (families[:, None] != families[None])).any()
    if compiled_enabled():
        kernel = compiled_kernel(boom, wait=True)
        mixed = PumpBoom(boom.root, boom.lengths, boom.limits, boom.grid, table=table)
        points = np.stack([[*r, corner[0]], np.zeros(5), [*z, corner[1]]], axis=-1)
        raw = np.full((5, 6), np.nan)
        for k, point in enumerate(points.tolist()):
            kernel.region_ik(*mixed._kernel_args, *point, 0.0, False, raw[k])
        expected = np.stack([*table.blend(r, z)[0], blend])
        np.testing.assert_allclose(raw[:, 1:4], expected, rtol=0.0, atol=1e-12)


def test_overlapping_squares_are_refused_naming_both(boom: PumpBoom) -> None:
    # (7, 9) of level 1 is a quarter of (3, 4) of level 0.
    index = np.array([[3, 4, 0], [10, 10, 2], [7, 9, 1]])
    with pytest.raises(ValueError, match=r"square \(7, 9, 1\) overlaps square \(3, 4, 0\)"):
        RegionTable(boom.grid, index, np.zeros((3, 3)), np.zeros(3), {}, {}, {})
    RegionTable(boom.grid, index[:2], np.zeros((2, 3)), np.zeros(2), {}, {}, {})


def test_a_truncated_pour_ends_before_a_gap_its_resampled_points_catch(boom: PumpBoom) -> None:
    # A 3-D line from a table point: the first 100 mm samples step over the corner of a gap that the
    # line spaced anew up to the farthest reachable point catches (a line with this property in the
    # shipped table, found by a seeded search over random lines; another table needs another line).
    start = (2.5750003911571793, -1.0649440449825676, 7.387173223887741)
    plan = pour_line(boom, start, (3.6127339969596, -7.8584148664640265, 15.557747108352295))
    assert plan.truncated and len(plan.points) > 10 and np.isfinite(plan.q).all()
    np.testing.assert_allclose(boom.tip(plan.q), plan.points, atol=1e-9)
    assert boom.region_ik(plan.points).ok.all()


def _squares_block(document: str) -> str:
    """The ``squares`` block (base64) of a table file's text."""
    return yaml.safe_load(document)["/**"]["ros__parameters"]["pump_boom_regions"]["squares"]


def _shipped_squares() -> tuple[str, np.ndarray]:
    """The shipped table file's text before its squares, and its squares (a copy)."""
    text = Path(config_path("pump_boom_regions.yaml")).read_text(encoding="utf-8")
    squares = regions.decode_squares(_squares_block(text), "squares")
    return text[: text.index("      squares: |")], squares.copy()


def _table_file(tmp_path: Path, head: str, stream: bytes) -> Path:
    """A table file of the shipped file's text before its squares, ``head``, and the squares block
    ``stream`` in base64."""
    path = tmp_path / "table.yaml"
    path.write_text(head + f"      squares: {base64.b64encode(stream).decode()}\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("column", 100_001, r"squares, square 2: need .* column and row within \+-100000"),
        ("level", 13, r"squares, square 2: need .* level in \[0, 12\]"),
        ("triple", [np.nan, 1.0, 1.0], r"squares, square 2: need finite numbers"),
        ("margin", np.inf, r"squares, square 2: need finite numbers"),
        (None, None, r"squares: expected base64 of the zlib-deflated squares of 37 bytes"),
    ],
)
def test_a_bad_square_of_the_table_file_is_refused_with_its_key(
    tmp_path, field: str | None, value: object, match: str
) -> None:
    head, squares = _shipped_squares()
    if field is None:
        data = squares.tobytes()[:-1]  # a byte short
    else:
        squares[1][field] = value
        data = squares.tobytes()
    with pytest.raises(ConfigError, match=r"pump_boom_regions\." + match):
        RegionTable.load(_table_file(tmp_path, head, zlib.compress(data)))


@pytest.mark.parametrize(
    ("stream", "match"),
    [
        (lambda data: data, "expected base64 of the zlib-deflated squares .* rebuild it"),  # not deflated
        (lambda data: zlib.compress(data)[:-10], "expected base64 of the zlib-deflated squares"),  # cut short
        (lambda data: zlib.compress(bytes(37_000_037), 9), "more than 1000000 squares"),  # 36 KB -> 37 MB
    ],
    ids=["not deflated", "cut short", "inflates too far"],
)
def test_a_squares_block_that_is_no_whole_zlib_stream_is_refused(tmp_path, stream, match: str) -> None:
    head, squares = _shipped_squares()
    with pytest.raises(ConfigError, match=r"pump_boom_regions\.squares: " + match):
        RegionTable.load(_table_file(tmp_path, head, stream(squares.tobytes())))


def _far_column(squares: np.ndarray) -> np.ndarray:
    """The squares with the last one moved to column 100 000 of its level (about 15 km away)."""
    squares = squares.copy()
    squares[-1]["column"] = 100_000
    return squares


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (
            lambda squares: squares[[0, 0, *range(2, len(squares))]],  # square 1 twice
            r"square \(0, -85, 4\) overlaps square \(0, -85, 4\)",
        ),
        (
            lambda squares: np.concatenate([squares, squares[-1:]]),  # the last one twice
            r"square \(264, 19, 5\) overlaps square \(264, 19, 5\)",
        ),
        (_far_column, r"the squares span \d+ x \d+ cells of 0.15625 m, more than 16777216"),
    ],
    ids=["first twice", "last twice", "a square 15 km away"],
)
def test_squares_the_lookup_cannot_hold_are_refused_with_the_key(tmp_path, change, match: str) -> None:
    head, squares = _shipped_squares()
    with pytest.raises(ConfigError, match=r"pump_boom_regions\.squares: region table: " + match):
        RegionTable.load(_table_file(tmp_path, head, zlib.compress(change(squares).tobytes())))


def test_the_table_file_is_what_dump_writes_and_an_older_one_is_refused(boom: PumpBoom, tmp_path) -> None:
    # The shipped file is what dump writes of the table read from it: its text before the squares
    # the same, and its squares the same bytes once inflated (another zlib, e.g. zlib-ng, may
    # deflate them to other bytes; with this machine's zlib they are the same).
    shipped = Path(config_path("pump_boom_regions.yaml"))
    path = tmp_path / "table.yaml"
    boom.table.dump(path, build_regions.table_header(boom.table, "pump_boom.yaml"))
    written, text = path.read_text(encoding="utf-8"), shipped.read_text(encoding="utf-8")
    cut = text.index("      squares: |")
    assert written[:cut] == text[:cut] and written[cut:].splitlines()[0] == text[cut:].splitlines()[0]
    inflated = [zlib.decompress(base64.b64decode(_squares_block(document))) for document in (written, text)]
    assert inflated[0] == inflated[1]
    # A table from before the rows were base64 (a line of 7 numbers per square): refused, key named.
    old = "".join(" " * 8 + line + "\n" for line in ["0 -85 4 0.0 1.22173 3.0979 0.17", "1 2 0 1 1 1 0.1"])
    path.write_text(text[:cut] + "      squares: |\n" + old, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"pump_boom_regions\.squares: expected base64 .* rebuild it"):
        RegionTable.load(path)


def test_the_listing_shows_each_square_with_its_extent_and_degrees(boom: PumpBoom, capsys) -> None:
    assert build_regions.main(["--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    table = boom.table
    assert len(lines) == len(table) + 1 and lines[0].startswith("square (i, j, level)")
    k = len(table) // 2
    numbers = [float(word) for word in lines[k + 1].translate(str.maketrans("(),", "   ")).split()]
    i, j, level = table.index[k]
    side = float(boom.grid.side(level))
    r0, z0 = (float(c) for c in boom.grid.corner(i, j, level))
    assert numbers[:3] == [i, j, level]
    np.testing.assert_allclose(numbers[3:7], [r0, r0 + side, z0, z0 + side], atol=5e-4)
    np.testing.assert_allclose(numbers[7:10], np.degrees(table.triples[k]), atol=0.05)
    assert numbers[10] == pytest.approx(table.margin[k], abs=5e-4)


def test_a_changed_geometry_runs_fk_but_no_region_ik_until_its_table_is_built(
    boom: PumpBoom, random_q: np.ndarray, tmp_path
) -> None:
    section = load_parameters(config_path("pump_boom.yaml"))["pump_boom"]
    section["lengths"] = [9.7, 8.4, 8.2, 8.6, 6.7]
    changed = PumpBoom.from_parameters(section)
    # FK and the Jacobian need no table: section 1 is 0.1 m longer, so every joint from P_1 on moves
    # by 0.1 m along section 1.
    phi1 = random_q[:, 1]
    shift = 0.1 * np.stack(
        [np.cos(phi1) * np.cos(random_q[:, 0]), np.cos(phi1) * np.sin(random_q[:, 0]), np.sin(phi1)], axis=-1
    )
    np.testing.assert_allclose(changed.tip(random_q) - boom.tip(random_q), shift, atol=1e-12)
    np.testing.assert_allclose(changed.jacob0(random_q)[:, :3], changed.tip_jacobian(random_q), atol=1e-11)
    # Region IK, solve_ik and pours refuse with the reason and the fix.
    problem = changed.table_problem()
    assert "built_for.lengths" in problem and "pump_boom_regions --config" in problem, problem
    with pytest.raises(RegionTableError, match=r"built_for\.lengths.*pump_boom_regions"):
        changed.region_ik([20.0, 0.0, 17.5])
    with pytest.raises(RegionTableError, match="pump_boom_regions"):
        changed.solve_ik(pose_matrix([20.0, 0.0, 17.5]), use_orientation=False)
    with pytest.raises(RegionTableError, match="pump_boom_regions"):
        pour_line(changed, (20.0, 0.0, 17.5), (25.0, 0.0, 17.5))
    section["regions"]["table_file"] = str(tmp_path / "missing.yaml")
    assert "missing.yaml does not exist" in PumpBoom.from_parameters(section).table_problem()


def test_section_2_folds_back_only_where_no_other_shape_reaches(boom: PumpBoom) -> None:
    # By the truck above the root pin the table folds section 2 back; brute force over a 2.5 deg
    # grid of every other shape (theta3 >= 15 deg, both elbows of sections 4-5) finds none that
    # reaches the point inside the limits in positive envelope. Far from the truck it stays unfolded.
    folded = boom.region_ik([2.5, 0.0, 10.0])
    assert folded.ok and math.degrees(folded.q[2]) < 15.0
    grid = np.radians(2.5)
    axes = [np.arange(boom.limits.lower[k], boom.limits.upper[k] + 1e-9, grid) for k in (1, 2, 3)]
    triples = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    triples = triples[triples[:, 1] >= np.radians(15.0)]
    q = np.concatenate([np.zeros((len(triples), 1)), triples, np.full((len(triples), 2), np.pi)], axis=-1)
    shoulder, phi3 = boom.plane_points(q)[:, 3], boom.section_angles(q)[:, 2]
    reached = np.zeros(len(q), dtype=bool)
    for elbow in (1.0, -1.0):
        d = np.hypot(2.5 - shoulder[:, 0], 10.0 - shoulder[:, 1])
        l4, l5 = boom.lengths[3], boom.lengths[4]
        cos5 = np.clip((d * d - l4 * l4 - l5 * l5) / (2.0 * l4 * l5), -1.0, 1.0)
        bend = elbow * np.arccos(cos5)
        phi4 = np.arctan2(10.0 - shoulder[:, 1], 2.5 - shoulder[:, 0]) - np.arctan2(
            l5 * np.sin(bend), l4 + l5 * np.cos(bend)
        )
        q[:, 4] = np.mod(phi4 - phi3 + np.pi, 2.0 * np.pi)
        q[:, 5] = bend + np.pi
        tip_error = np.abs(boom.plane_points(q)[:, 5] - [2.5, 10.0]).max(axis=-1)
        reached |= (tip_error < 1e-9) & boom.limits.within(q, 1e-9) & boom.positive_envelope(q)
    assert not reached.any()
    assert math.degrees(boom.region_ik([20.0, 0.0, 17.5]).q[2]) >= 90.0


@pytest.mark.slow
def test_builder_is_deterministic_and_its_table_serves_a_changed_machine(tmp_path) -> None:
    section = load_parameters(config_path("pump_boom.yaml"))["pump_boom"]
    section["lengths"] = [9.7, 8.4, 8.2, 8.6, 6.7]
    section["regions"]["table_file"] = str(tmp_path / "t0.yaml")
    boom = PumpBoom.from_parameters(section)
    area = build_regions.reachable_area(boom, samples=20_000, cell=1.0)
    # The check lattice 0.25 m apart (the shipped table's 0.1 m): each final check runs on a sixth
    # of the points, and the build (its gaps filled and checked again) takes 12 s instead of 90 s;
    # the test's 0.5 m points lie on that lattice (to 1 um), so the check vouches for every one.
    tables = [
        build_regions.build_table(boom, step_deg=15.0, levels=1, coverage=area, check_spacing=0.25)
        for _ in range(2)
    ]
    for k, table in enumerate(tables):
        table.dump(tmp_path / f"t{k}.yaml")
    assert (tmp_path / "t0.yaml").read_bytes() == (tmp_path / "t1.yaml").read_bytes()
    assert boom.table_problem() is None
    assert len(boom.table) > 5 and boom.table.coverage["band_failures"] == 0
    np.testing.assert_array_equal(boom.table.triples, tables[0].triples)
    points = _plane(boom, 0.5)
    result = boom.region_ik(points)
    assert result.ok.all() and np.abs(boom.tip(result.q) - points).max() < 1e-9
