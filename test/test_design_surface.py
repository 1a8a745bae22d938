"""Design TIN (excavator_kinematics.grade.design_surface): LandXML 1.2 loading, heights against hand
geometry and the design plane, the point location against brute force, the cutting edge."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.tri import Triangulation

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.grade.design_surface import SitePose, Tin, cutting_edge, read_landxml, write_landxml
from excavator_kinematics.nodes.display_outputs import DesignPlane
from manipulator_kinematics.param_files import ConfigError

DITCH = Path(__file__).parent / "data" / "landxml" / "ditch.xml"
E0, N0 = 500100.0, 5400200.0
RNG = np.random.default_rng(21)


def ditch_by_hand(e: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The V-ditch of ditch.xml: banks at 100 - 0.01 n, 1.5 m deeper at the axis, 1:2 slopes."""
    return 100.0 - 0.01 * n - np.maximum(0.0, 1.5 - 0.5 * np.abs(e))


def two_triangles(plane: DesignPlane, half: float = 50.0) -> Tin:
    """The plane as a TIN: a square of +-half around its point, split along a diagonal."""
    corners = plane.point[:2] + half * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    n = plane.normal
    z = plane.point[2] - ((corners - plane.point[:2]) @ n[:2]) / n[2]
    return Tin(np.column_stack([corners, z]), np.array([[0, 1, 2], [0, 2, 3]]))


@pytest.mark.parametrize(
    "grade", [{}, {"slope": -2.0, "cross_slope": 1.5}, {"slope": 100.0}, {"normal": [0.3, -0.2, 1.0]}]
)
def test_two_triangle_tin_equals_the_design_plane(grade):
    """The plane's perpendicular height h times 1/n_z is the vertical height (same plane, same
    points); for a level plane the two are the same number."""
    plane = DesignPlane.from_settings({"point": [6.0, -1.0, -1.5], **grade})
    tin = two_triangles(plane)
    points = np.column_stack([RNG.uniform(-40, 40, (500, 2)) + plane.point[:2], RNG.uniform(-8, 4, 500)])
    got = tin.heights(points)
    assert got.inside.all()
    np.testing.assert_allclose(got.height, plane.height(points) / plane.normal[2], rtol=0, atol=1e-12)
    if not grade:
        np.testing.assert_allclose(got.height, plane.height(points), rtol=0, atol=1e-12)


def test_landxml_ditch_loads_in_site_order_and_matches_hand_geometry():
    tin = read_landxml(DITCH, "Ditch design")
    assert tin.name == "Ditch design"
    assert tin.vertices.shape == (15, 3) and tin.faces.shape == (15, 3)  # 16 faces, one invisible
    # "northing easting elevation" in the file -> x = easting, y = northing here.
    np.testing.assert_array_equal(tin.vertices[0], [500092.0, 5400200.0, 100.0])
    np.testing.assert_array_equal(tin.vertices[2], [500100.0, 5400200.0, 98.5])
    # Hand points: the axis, both slopes, a bank, a corner of the ditch.
    e = np.array([0.0, 1.0, -1.0, -2.5, 5.0, 3.0, 0.0])
    n = np.array([0.0, 5.0, 12.0, 20.0, 7.0, 29.0, 3.0])
    z = np.array([98.5, 99.2, 100.0, 98.0, 100.0, 99.72, 99.0])
    got = tin.heights(np.column_stack([E0 + e, N0 + n, z]))
    assert got.inside.all()
    np.testing.assert_allclose(got.height, z - ditch_by_hand(e, n), rtol=0, atol=1e-9)
    # By hand, two of them: 1 m off the axis at n = 5 the surface is 100 - 0.05 - 1.0 = 98.95.
    assert got.height[1] == pytest.approx(99.2 - 98.95, abs=1e-9)
    assert got.height[0] == pytest.approx(0.0, abs=1e-9)


def test_points_outside_and_in_the_hole_have_a_status_not_a_number():
    tin = read_landxml(DITCH, "Ditch design")
    points = np.array(
        [
            [E0 + 1.0, N0 + 28.0, 99.0],  # the invisible face (i="1"): a hole
            [E0 + 8.5, N0 + 5.0, 99.0],  # beyond the east bank
            [E0, N0 - 0.1, 99.0],  # before the start
            [E0, N0 + 10.0, 99.0],
        ]
    )  # on the axis: inside
    got = tin.heights(points)
    np.testing.assert_array_equal(got.inside, [False, False, False, True])
    np.testing.assert_array_equal(got.triangle[:3], [-1, -1, -1])
    assert np.isnan(got.height[:3]).all() and np.isfinite(got.height[3])


def test_surface_chosen_by_name_and_refused_by_reason(tmp_path):
    ground = read_landxml(DITCH, "Existing ground")
    assert ground.heights([[E0, N0, 101.0]]).height[0] == pytest.approx(0.8, abs=1e-12)
    with pytest.raises(ConfigError, match=r"2 surfaces \['Existing ground', 'Ditch design'\]"):
        read_landxml(DITCH)
    with pytest.raises(ConfigError, match="no Surface named 'Ditch'"):
        read_landxml(DITCH, "Ditch")
    text = DITCH.read_text()
    cases = {
        "grid": (text.replace('"TIN" area2DSurf="480', '"GRID" area2DSurf="480'), "surfType"),
        "units": (text.replace('linearUnit="meter"', 'linearUnit="cubit"'), "linearUnit 'cubit'"),
        "point": (text.replace(">5400215.000 500097.000 99.850<", ">5400215.000 500097.000<"), "id='7'"),
        "face": (text.replace("<F>9 15 14</F>", "<F>9 15 99</F>"), "unknown: \\['99'\\]"),
        "xml": (text[:500], "cannot read"),
        "duplicate": (
            text.replace(">5400215.000 500097.000 99.850<", ">5400200.000 500097.000 99.850<"),
            "share x, y",
        ),
    }
    for name, (content, message) in cases.items():
        path = tmp_path / f"{name}.xml"
        path.write_text(content)
        with pytest.raises(ConfigError, match=message):
            read_landxml(path, "Ditch design")
    feet = tmp_path / "feet.xml"
    feet.write_text(text.replace('linearUnit="meter"', 'linearUnit="USSurveyFoot"'))
    np.testing.assert_allclose(
        read_landxml(feet, "Ditch design").vertices,
        read_landxml(DITCH, "Ditch design").vertices * 1200 / 3937,
        rtol=1e-15,
    )


def test_written_file_reads_back(tmp_path):
    tin = read_landxml(DITCH, "Ditch design")
    write_landxml(tmp_path / "out.xml", tin)
    again = read_landxml(tmp_path / "out.xml")
    np.testing.assert_allclose(again.vertices, tin.vertices, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(again.faces, tin.faces)


def test_point_location_equals_brute_force_on_a_random_tin():
    """A Delaunay TIN of 2000 scattered points at UTM-sized coordinates: the trapezoid map finds
    the triangle every-triangle barycentric signs find (away from shared edges), and the height
    is the barycentric interpolation of the corners' elevations."""
    xy = RNG.uniform(0, 200, (2000, 2)) + [431_000.0, 5_861_000.0]
    z = 50 + 3 * np.sin(xy[:, 0] / 17) + RNG.normal(0, 0.2, len(xy))
    tin = Tin(np.column_stack([xy, z]), Triangulation(xy[:, 0] - 431_000, xy[:, 1]).triangles)
    q = RNG.uniform(-10, 210, (600, 2)) + [431_000.0, 5_861_000.0]
    found, brute = tin.locate(q), tin.locate_all_triangles(q)
    assert (found == -1).any() and (found >= 0).mean() > 0.8
    np.testing.assert_array_equal(found, brute)
    inside = found >= 0
    corners = tin.vertices[tin.faces[found[inside]]]  # (k, 3, 3)
    # Barycentric weights solved independently (np.linalg.solve of [x; y; 1] w = [qx, qy, 1]).
    A = np.concatenate([np.moveaxis(corners[:, :, :2], 1, 2), np.ones((len(corners), 1, 3))], axis=1)
    b = np.column_stack([q[inside] - [431_000.0, 5_861_000.0], np.ones(inside.sum())])
    w = np.linalg.solve(A - [[[431_000.0], [5_861_000.0], [0.0]]], b[..., None])[..., 0]
    surface = np.einsum("ki,ki->k", w, corners[:, :, 2])
    got = tin.heights(np.column_stack([q, np.full(len(q), 60.0)]))
    np.testing.assert_allclose(got.height[inside], 60.0 - surface, rtol=0, atol=1e-9)


def test_cutting_edge_ends_and_site_pose():
    exc = Excavator.default()
    assert exc.bucket_width == 1.0
    D = exc.limits.reference + [0.7, 0.1, -0.2, 0.1]
    tip = exc.pose(D)[:3]
    edge = cutting_edge(tip, D[0], exc.bucket_width)
    np.testing.assert_array_equal(edge[0], tip)
    np.testing.assert_allclose(np.linalg.norm(edge[1] - edge[2]), 1.0, rtol=1e-15)
    # Across the boom plane: perpendicular to the tip's radial direction, level, left = +y side.
    across = edge[1] - edge[2]
    assert across @ [math.cos(0.7), math.sin(0.7), 0.0] == pytest.approx(0.0, abs=1e-15)
    assert across[2] == 0.0 and np.cross([math.cos(0.7), math.sin(0.7), 0.0], across)[2] > 0
    # Batches: (N, 3) tips and (N,) swings.
    batch = cutting_edge(np.tile(tip, (4, 1)), np.full(4, D[0]), 1.0)
    np.testing.assert_array_equal(batch, np.broadcast_to(edge, (4, 3, 3)))
    # Site pose: yaw 90 deg turns base x into site y; a quaternion gives the same pose.
    rpy = [0.02, -0.05, 1.2]
    by_rpy = SitePose.from_rpy([E0, N0, 100.0], rpy)
    half = [0.5 * a for a in rpy]
    cr, sr, cp, sp, cy, sy = (f(h) for h in half for f in (math.cos, math.sin))
    q = [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]
    by_q = SitePose.from_quaternion([E0, N0, 100.0], q)
    np.testing.assert_allclose(by_q.apply(edge), by_rpy.apply(edge), rtol=0, atol=1e-9)
    turned = SitePose.from_rpy([1.0, 2.0, 3.0], [0.0, 0.0, math.pi / 2]).apply([1.0, 0.0, 0.0])
    np.testing.assert_allclose(turned, [1.0, 3.0, 3.0], atol=1e-15)
