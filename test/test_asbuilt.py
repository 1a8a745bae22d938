"""As-built surface core against a brute-force reference (every segment rasterised at a fine step)."""

from __future__ import annotations

import numpy as np
import pytest

from manipulator_kinematics.asbuilt import AsBuilt, densify, lowest_elevation


def brute_force(
    left: np.ndarray,
    right: np.ndarray,
    x0: float,
    y0: float,
    cell: float,
    shape: tuple[int, int],
    step: float = 2e-4,
) -> np.ndarray:
    """Every sample's edge as points ``step`` apart (ends included), the lowest per cell."""
    n = int(np.ceil(np.max(np.linalg.norm(right - left, axis=1)) / step)) + 1
    s = np.linspace(0.0, 1.0, n)[None, :, None]
    pts = (left[:, None, :] + s * (right - left)[:, None, :]).reshape(-1, 3)
    i = np.floor((pts[:, 0] - x0) / cell).astype(int)
    j = np.floor((pts[:, 1] - y0) / cell).astype(int)
    z = np.full(shape, np.inf)
    inside = (i >= 0) & (i < shape[1]) & (j >= 0) & (j < shape[0])
    np.minimum.at(z, (j[inside], i[inside]), pts[inside, 2])
    return np.where(np.isfinite(z), z, np.nan)


def sweep(n: int, seconds: float, origin=(512_300.0, 4_123_400.0)) -> tuple[np.ndarray, np.ndarray]:
    """A 1.2 m edge dragged along a curved, sloped, swinging path (site frame, UTM-sized)."""
    t = np.linspace(0.0, seconds, n)
    heading = 0.4 + 0.6 * np.sin(0.3 * t)
    mid = np.column_stack(
        [
            origin[0] + 0.5 * t + 0.7 * np.sin(0.5 * t),
            origin[1] + 1.1 * np.cos(0.4 * t),
            102.0 - 0.08 * t + 0.3 * np.sin(0.9 * t),
        ]
    )
    across = 0.6 * np.column_stack([-np.sin(heading), np.cos(heading), 0.1 * np.sin(t)])
    return mid + across, mid - across


@pytest.mark.parametrize("cell", [*(pytest.param(c, marks=pytest.mark.slow) for c in (0.1, 0.25)), 0.5])
def test_lowest_elevation_matches_the_brute_force_reference(cell: float) -> None:
    left, right = sweep(301, 3.0)  # 100 Hz: the corners move < 1 cm a sample
    grid = lowest_elevation(left, right, cell)
    assert np.all(grid.hits[np.isfinite(grid.z)] > 0)
    # At 100 Hz no corner moves 1 cm (the default step): the grid used the samples' own edges.
    assert len(densify(left, right, 0.01)[0]) == len(left)
    # Step 20 um along each edge: a segment that crosses a cell's corner over less than that is
    # the reference's blind spot, so a few cells may read lower here than there, never higher.
    ref = brute_force(left, right, grid.x0, grid.y0, cell, grid.z.shape, step=2e-5)
    reached = np.isfinite(ref)
    assert np.all(np.isfinite(grid.z[reached]))
    assert np.all(grid.z[reached] <= ref[reached] + 1e-9)  # exact: no point seen lies below it
    assert np.mean(ref[reached] - grid.z[reached] < 1e-3) >= 0.99  # (the first edge of this run
    # passes exactly through a grid corner: one cell of 199 at 0.1 m)
    extra = np.isfinite(grid.z) & ~reached  # cells only grazed: as rare
    assert extra.sum() <= 0.005 * reached.sum() + 1
    assert reached.sum() > 15


def test_a_fast_sweep_is_densified_and_leaves_no_holes() -> None:
    left, right = sweep(21, 10.0)  # 2 Hz: corners move up to 0.5 m a sample
    cell = 0.1
    coarse = lowest_elevation(left, right, cell, max_step=1e9)  # no densification
    dense = lowest_elevation(left, right, cell)
    # Reference: the same run interpolated 200 times finer in time, then rasterised.
    fl, fr = densify(left, right, 0.002)
    ref = brute_force(fl, fr, dense.x0, dense.y0, cell, dense.z.shape, step=1e-3)
    reached = np.isfinite(ref)
    assert np.isfinite(coarse.z).sum() < 0.75 * reached.sum()  # holes without densification
    assert np.isfinite(dense.z[reached]).mean() > 0.995  # at most a grazed corner cell missed
    both = reached & np.isfinite(dense.z)
    # 1 cm steps (default): the swept sheet between two used edges is lower by at most about a
    # step times its slope (up to 2 here, where the edge plunges while it sweeps).
    assert np.max(dense.z[both] - ref[both]) < 0.02
    assert np.min(dense.z[both] - ref[both]) > -2e-3


def test_densify_keeps_the_samples_and_bounds_the_step() -> None:
    left, right = sweep(11, 10.0)
    dl, dr = densify(left, right, 0.05)
    step = np.maximum(
        np.linalg.norm(np.diff(dl, axis=0), axis=1), np.linalg.norm(np.diff(dr, axis=0), axis=1)
    )
    assert step.max() <= 0.05 + 1e-12
    for p in left:  # every sample is among the edges used
        assert np.min(np.linalg.norm(dl - p, axis=1)) < 1e-9
    np.testing.assert_allclose(dl[-1], left[-1])


def test_a_level_edge_gives_its_height_and_grids_merge_to_the_lower() -> None:
    left = np.array([[0.05, 0.05, 1.0], [0.05, 0.35, 1.0]])
    right = np.array([[0.95, 0.05, 1.0], [0.95, 0.35, 1.0]])
    a = lowest_elevation(left, right, 0.1)
    assert a.x0 == 0.0 and a.y0 == 0.0 and a.z.shape == (4, 10)
    np.testing.assert_allclose(a.z, 1.0)
    b = lowest_elevation(left + (0.5, 0.2, -0.3), right + (0.5, 0.2, -0.3), 0.1)
    m = AsBuilt.merge([a, b])
    assert m.z.shape == (6, 15)
    assert m.z[0, 0] == pytest.approx(1.0) and m.z[3, 6] == pytest.approx(0.7) and np.isnan(m.z[5, 0])
    assert m.points().shape == (np.isfinite(m.z).sum(), 3)


def test_gaps_in_the_record_and_bad_cells_are_handled() -> None:
    left, right = sweep(50, 1.0)
    left[10] = np.nan
    assert np.isfinite(lowest_elevation(left, right, 0.2).z).any()
    with pytest.raises(ValueError, match="cell size"):
        lowest_elevation(left, right, 0.0)
    empty = lowest_elevation(np.full((3, 3), np.nan), np.full((3, 3), np.nan), 0.2)
    assert empty.z.size == 0


def test_the_landxml_surface_reads_back_with_the_design_reader(tmp_path) -> None:
    from excavator_kinematics.grade.design_surface import read_landxml

    left, right = sweep(301, 3.0)
    grid = lowest_elevation(left, right, 0.25)
    grid.write_landxml(tmp_path / "asbuilt.xml")
    tin = read_landxml(tmp_path / "asbuilt.xml")
    vertices, faces = grid.triangles()
    assert len(tin.faces) == len(faces) > 0
    # At every reached centre that a face uses, the surface passes through the cell's value.
    used = np.unique(faces)
    heights = tin.heights(vertices[used])
    assert np.all(heights.inside)
    np.testing.assert_allclose(heights.height, 0.0, atol=2e-6)  # 6 decimals in the file
    grid.write_csv(tmp_path / "asbuilt.csv")
    table = np.loadtxt(tmp_path / "asbuilt.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table, grid.points(), atol=1e-4)
