"""Site-frame avoidance zones: the machine's site pose (and its tilt) places them, checked against
the equivalent base-frame zones and closed forms (no ROS)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.core.path_zones import plan_clear
from excavator_kinematics.grade.design_surface import SitePose
from excavator_kinematics.machine import MACHINE
from excavator_kinematics.sensing.imu import base_up
from manipulator_kinematics.zone_guard import ZoneGuard, first_entry
from manipulator_kinematics.zones import Monitor, Zone

RNG = np.random.default_rng(3434)
EXC = MACHINE.model()
POINTS = MonitoredPoints(EXC)
#: base_link in the site frame: 512 m east, 7 km north, 92.5 m up, heading 0.7 rad (level).
POSITION, YAW = np.array([512.0, 7031.0, 92.5]), 0.7
LEVEL = SitePose.from_rpy(POSITION, [0.0, 0.0, YAW])


def zone(name: str, kind: str, frame: str, margin: float, **values: object) -> Zone:
    return Zone(name, kind, frame, margin, values)


def site_and_base_zones() -> tuple[list[Zone], list[Zone]]:
    """A ceiling, a floor and a wall in the site frame, and the same zones in base_link of LEVEL
    (written out by hand: heights less the base's elevation; the wall's point and normal turned
    back by the heading)."""
    point, normal = np.array([520.0, 7030.0]), np.array([math.cos(0.3), math.sin(0.3)])
    c, s = math.cos(YAW), math.sin(YAW)
    back = np.array([[c, s], [-s, c]])  # Rz(-yaw) in the plane
    site = [
        zone("line", "ceiling", "site", 0.5, height=99.0),
        zone("floor", "floor", "site", 0.2, height=90.0),
        zone("trench", "wall", "site", 0.3, point=point.tolist(), normal=normal.tolist()),
    ]
    base = [
        zone("line", "ceiling", "base", 0.5, height=99.0 - POSITION[2]),
        zone("floor", "floor", "base", 0.2, height=90.0 - POSITION[2]),
        zone(
            "trench",
            "wall",
            "base",
            0.3,
            point=(back @ (point - POSITION[:2])).tolist(),
            normal=(back @ normal).tolist(),
        ),
    ]
    return site, base


@pytest.mark.parametrize("compiled", [False, True])
def test_site_zones_with_a_known_pose_give_the_base_equivalents_clearances(compiled: bool) -> None:
    site, base = site_and_base_zones()
    names = [f"p{i}" for i in range(40)]
    p = RNG.uniform([-8, -8, -3], [12, 8, 10], (40, 3))
    v = RNG.normal(0.0, 0.5, (40, 3))
    in_site = Monitor(site, names).check(p, v, 0.3, 0.05, (LEVEL.rotation, LEVEL.translation), compiled)
    in_base = Monitor(base, names).check(p, v, 0.3, 0.05, None, compiled)
    for name in ("line", "floor", "trench"):
        assert in_site.clearance[name][0] == pytest.approx(in_base.clearance[name][0], abs=1e-9)
        assert in_site.clearance[name][1] == in_base.clearance[name][1]
    assert in_site.scale == pytest.approx(in_base.scale, abs=1e-9)
    assert (in_site.zone, in_site.point) == (in_base.zone, in_base.point)


def test_a_path_enters_a_site_ceiling_where_it_enters_the_base_equivalent() -> None:
    site, base = site_and_base_zones()
    D = EXC.limits.d_min + np.linspace(0.1, 0.9, 30)[:, None] * (EXC.limits.d_max - EXC.limits.d_min)
    positions = POINTS.positions(D)
    hit = first_entry(base[:1], POINTS.names, positions)
    assert hit is not None  # the sweep does reach the ceiling
    assert first_entry(site[:1], POINTS.names, positions, (LEVEL.rotation, LEVEL.translation)) == hit
    with pytest.raises(ValueError, match="site frame"):
        first_entry(site[:1], POINTS.names, positions)


def test_plan_path_under_a_site_ceiling_ends_where_under_the_base_ceiling() -> None:
    site, base = site_and_base_zones()
    tip = EXC.pose(EXC.limits.reference)[:3]
    waypoints = [tip, tip + [0.5, 0.0, 0.0], tip + [0.5, 0.0, 5.0]]
    in_base = plan_clear(EXC, POINTS, base[:1], waypoints, 0.05, 0.5, 0.5)
    in_site = plan_clear(
        EXC, POINTS, site[:1], waypoints, 0.05, 0.5, 0.5, site=(LEVEL.rotation, LEVEL.translation)
    )
    assert in_base.truncated and in_site.message == in_base.message
    np.testing.assert_allclose(in_site.points, in_base.points)


def test_levelled_with_the_poses_own_tilt_is_the_pose() -> None:
    for rpy in RNG.uniform([-0.3, -0.3, -math.pi], [0.3, 0.3, math.pi], (20, 3)):
        pose = SitePose.from_rpy(POSITION, rpy)
        own_up = pose.rotation.T @ [0.0, 0.0, 1.0]
        levelled = pose.levelled(own_up)
        np.testing.assert_allclose(levelled.rotation, pose.rotation, atol=1e-12)
        np.testing.assert_allclose(levelled.translation, POSITION)


def test_a_tilt_raises_the_front_under_a_site_ceiling_as_a_pitch_does() -> None:
    # The machine pitched nose-up by beta (IMU), on a level surveyed stand: a point x ahead of the
    # swing axis at height z is at z cos(beta) + x sin(beta) above base_link's origin, so its
    # clearance under a ceiling H (site) is H - elevation - that - margin.
    beta, x, z, H, margin = math.radians(8.0), 6.0, 2.0, 99.0, 0.5
    up = [math.sin(beta), 0.0, math.cos(beta)]  # world up in a base tilted nose-up: leans forward
    pose = LEVEL.levelled(up)
    ceiling = [zone("line", "ceiling", "site", margin, height=H)]
    monitor = Monitor(ceiling, ["front", "axis"])
    p = np.array([[x, 0.0, z], [0.0, 0.0, z]])
    tilted = monitor.check(p, np.zeros_like(p), 0.0, 0.05, (pose.rotation, pose.translation))
    level = monitor.check(p, np.zeros_like(p), 0.0, 0.05, (LEVEL.rotation, LEVEL.translation))
    expected = H - POSITION[2] - (z * math.cos(beta) + x * math.sin(beta)) - margin
    assert tilted.clearance["line"] == (pytest.approx(expected, abs=1e-9), "front")
    assert level.clearance["line"] == (pytest.approx(H - POSITION[2] - z - margin, abs=1e-9), "front")
    # The heading is the site pose's: a tilt does not turn the machine about the vertical.
    forward = pose.rotation @ [1.0, 0.0, 0.0]
    assert math.atan2(forward[1], forward[0]) == pytest.approx(YAW, abs=1e-12)
    assert forward[2] == pytest.approx(math.sin(beta), abs=1e-12)


def test_the_cab_tilt_gives_the_same_site_pose_at_any_swing_angle() -> None:
    # The IMU is on the upper structure: the same ground tilt reads differently as it swings,
    # base_up turns it back (u_base = Rz(theta1) u_upper).
    up_base = Rotation.from_euler("xy", [0.05, -0.12]).inv().apply([0.0, 0.0, 1.0])
    reference = LEVEL.levelled(up_base)
    for theta1 in np.linspace(-math.pi, math.pi, 9):
        up_cab = Rotation.from_euler("z", -theta1).apply(up_base)
        np.testing.assert_allclose(
            LEVEL.levelled(base_up(up_cab, theta1)).rotation, reference.rotation, atol=1e-12
        )


def test_a_guard_without_a_site_pose_stops_and_says_the_clearance_is_unknown() -> None:
    site, _ = site_and_base_zones()
    guard = ZoneGuard(site[:1], ["p"], [1.0], 0.05)
    up, p = np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]])
    blind = guard.check(p, up, np.array([0.5]))
    assert blind.scale == 0.0 and blind.check.clearance["line"] == (-math.inf, "")
    posed = guard.check(p, up, np.array([0.5]), site=(LEVEL.rotation, LEVEL.translation))
    # 5 m below the line's margin (99 - 0.5 - 93.5): a 0.5 m/s climb is not slowed.
    assert posed.scale == 1.0
    assert posed.check.clearance["line"] == (pytest.approx(5.0, abs=1e-9), "p")
