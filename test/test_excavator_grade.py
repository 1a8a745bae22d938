"""Grade indication and the URDF joints' rates (excavator_kinematics.nodes.display_outputs)
against hand geometry and finite differences (the forward node publishing them:
test_excavator_grade_ros.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.urdf_joints import joint_positions
from excavator_kinematics.nodes.display_outputs import DesignPlane, urdf_joint_states
from manipulator_kinematics.param_files import ConfigError

EXC = Excavator.default()
LIM = EXC.limits
RNG = np.random.default_rng(13)


def plane(**grade) -> DesignPlane:
    return DesignPlane.from_settings({"point": [0.0, 0.0, 0.0], **grade})


def test_level_plane_height_is_z_difference():
    p = plane(point=[3.0, -1.0, -0.5])
    tips = RNG.uniform(-5, 5, (100, 3))
    np.testing.assert_allclose(p.height(tips), tips[:, 2] + 0.5, atol=1e-15)
    np.testing.assert_allclose(p.local(tips), tips - [3.0, -1.0, -0.5], atol=1e-15)


def test_slope_by_hand():
    # 100 % slope along x through the origin: the plane z = x, 45 deg. A tip at (2, 0, 0) is 2 m below
    # the surface point above it, so sqrt(2) m below the plane, perpendicular.
    p = plane(slope=100.0)
    assert p.height([2.0, 0.0, 0.0]) == pytest.approx(-math.sqrt(2.0), abs=1e-15)
    assert p.height([0.0, 7.0, 1.0]) == pytest.approx(1.0 / math.sqrt(2.0), abs=1e-15)
    # On the plane: height 0, and its x in the surface frame is the distance up the slope.
    np.testing.assert_allclose(p.local([1.0, 0.0, 1.0]), [math.sqrt(2.0), 0.0, 0.0], atol=1e-15)
    # Cross-slope -2 % along y: the point (0, 10, -0.2) lies on it; straight above it by 1 m is
    # cos(atan(0.02)) m above the plane.
    q = plane(cross_slope=-2.0)
    assert q.height([0.0, 10.0, -0.2]) == pytest.approx(0.0, abs=1e-15)
    assert q.height([0.0, 10.0, 0.8]) == pytest.approx(math.cos(math.atan(0.02)), abs=1e-15)


def test_slopes_and_normal_agree_and_frame_is_orthonormal():
    s, c = 3.5, -1.25
    by_slope, by_normal = plane(slope=s, cross_slope=c), plane(normal=[-s, -c, 100.0])
    tips = RNG.uniform(-10, 10, (50, 3))
    np.testing.assert_allclose(by_slope.height(tips), by_normal.height(tips), atol=1e-14)
    r = by_slope.rotation
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-14)
    # x is the base x projected onto the plane: in the plane of base x and the normal, forward.
    assert r[0] @ np.cross(r[2], [1.0, 0.0, 0.0]) == pytest.approx(0.0, abs=1e-15) and r[0, 0] > 0
    # A point of the surface z = s x + c y (percent) has height 0 whatever x, y.
    xy = RNG.uniform(-20, 20, (50, 2))
    on = np.column_stack([xy, xy @ [s / 100, c / 100]])
    np.testing.assert_allclose(by_slope.height(on), 0.0, atol=1e-13)


@pytest.mark.parametrize(
    "grade, key",
    [
        ({"normal": [0.0, 0.0, 1.0], "slope": 1.0}, "grade.normal"),
        ({"normal": [1.0, 0.0, 0.0]}, "grade.normal"),
        ({"normal": [0.0, 0.0, -1.0]}, "grade.normal"),
        ({"normal": [0.0, 0.0, 0.0]}, "grade.normal"),
    ],
)
def test_inconsistent_planes_name_the_key(grade, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        plane(**grade)


def test_urdf_joint_rates_match_finite_differences():
    """Each passive joint depends on one cylinder (the module's claim): its rate equals the central
    difference of joint_positions along the whole state rate."""
    D = RNG.uniform(LIM.d_min + 0.05, LIM.d_max - 0.05, (20, 4))
    D_dot = RNG.uniform(-1, 1, (20, 4)) * LIM.max_rates
    positions, rates = urdf_joint_states(EXC, D, D_dot)
    np.testing.assert_array_equal(positions, joint_positions(EXC, D))
    h = 1e-6
    diff = joint_positions(EXC, D + h * D_dot) - joint_positions(EXC, D - h * D_dot)
    diff = (diff + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(rates, diff / (2 * h), atol=1e-7)
    # The open chain's against the model's exact joint rates.
    exact = EXC.state(D, D_dot).theta_dot
    np.testing.assert_allclose(rates[:, :4], exact, atol=1e-8)
    # At the stroke ends (one-sided difference), still the model's rates.
    ends = np.column_stack([D[:2, 0], np.stack([LIM.d_min[1:], LIM.d_max[1:]])])
    _, end_rates = urdf_joint_states(EXC, ends, D_dot[:2])
    np.testing.assert_allclose(end_rates[:, :4], EXC.state(ends, D_dot[:2]).theta_dot, atol=1e-5)
