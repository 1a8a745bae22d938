"""Avoidance zones: clearances against brute force, the speed scale against a simulated stop, files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.tri import Triangulation

from manipulator_kinematics.param_files import ConfigError
from manipulator_kinematics.zones import Monitor, Zone, load_zones, scale_for, stop_time

RNG = np.random.default_rng(34)


def zone(kind: str, margin: float = 0.0, frame: str = "base", **values) -> Zone:
    return Zone(kind, kind, frame, margin, values)


def test_box_clearance_is_the_distance_to_the_nearest_box_point() -> None:
    box = zone("box", 0.2, min=[1.0, -1.0, 0.0], max=[3.0, 2.0, 1.5])
    points = RNG.uniform([-2, -4, -2], [6, 5, 4], (400, 3))
    c, g = box.clearance(points)
    # Brute force: the box's six faces sampled every 1 cm.
    lo, hi = np.array([1.0, -1.0, 0.0]), np.array([3.0, 2.0, 1.5])
    faces = []
    for axis in range(3):
        u, w = [a for a in range(3) if a != axis]
        U, W = np.meshgrid(np.arange(lo[u], hi[u] + 1e-9, 0.01), np.arange(lo[w], hi[w] + 1e-9, 0.01))
        for level in (lo[axis], hi[axis]):
            face = np.empty((U.size, 3))
            face[:, axis], face[:, u], face[:, w] = level, U.ravel(), W.ravel()
            faces.append(face)
    on_surface = np.vstack(faces)
    for p, ci, gi in zip(points[:60], c[:60], g[:60], strict=True):
        d = np.min(np.linalg.norm(on_surface - p, axis=1))
        inside = np.all((p > [1, -1, 0]) & (p < [3, 2, 1.5]))
        assert ci == pytest.approx((-d if inside else d) - 0.2, abs=0.01)
        # g points the way clearance grows, at unit rate.
        step = box.clearance(p + 1e-4 * gi)[0] - ci
        assert step == pytest.approx(1e-4, rel=1e-3)


@pytest.mark.parametrize("start, end", [(0.5, 1.7), (2.8, -2.6), (-1.0, 4.0)])
def test_sector_clearance_is_the_arc_to_the_nearest_edge(start: float, end: float) -> None:
    sector = zone("sector", 0.1, **{"from": start, "to": end})
    points = np.column_stack([RNG.uniform(-8, 8, (500, 2)), RNG.uniform(-1, 3, 500)])
    c, g = sector.clearance(points)
    r = np.hypot(points[:, 0], points[:, 1])
    bearing = np.arctan2(points[:, 1], points[:, 0])
    fine = np.linspace(0, np.mod(end - start, 2 * np.pi), 20001) + start  # the sector's bearings
    gap = np.abs(np.angle(np.exp(1j * (bearing[:, None] - fine[None, :]))))
    inside = gap.min(axis=1) < 1e-3
    to_edge = np.minimum(
        np.abs(np.angle(np.exp(1j * (bearing - start)))), np.abs(np.angle(np.exp(1j * (bearing - end))))
    )
    expected = np.where(inside, -to_edge, gap.min(axis=1)) * r - 0.1
    np.testing.assert_allclose(c, expected, atol=2e-3 * r.max())
    step = sector.clearance(points + 1e-5 * g)[0] - c
    np.testing.assert_allclose(step[r > 0.5], 1e-5, rtol=2e-2)


def test_planes_and_walls() -> None:
    p = np.array([[1.0, 2.0, 3.0], [4.0, -1.0, 7.0]])
    assert zone("ceiling", 0.5, height=6.0).clearance(p)[0].tolist() == pytest.approx([2.5, -1.5])
    assert zone("floor", 0.5, height=2.0).clearance(p)[0].tolist() == pytest.approx([0.5, 4.5])
    wall = zone("wall", 0.25, point=[3.0, 0.0], normal=[2.0, 0.0])  # forbidden: x > 3
    c, g = wall.clearance(p)
    assert c.tolist() == pytest.approx([1.75, -1.25]) and g[0].tolist() == [-1.0, 0.0, 0.0]


def test_scale_along_a_curved_path_is_where_it_first_meets_the_zone() -> None:
    """scale_for with the path's curvature w and a command in flight, against a brute-force
    search: the largest s whose path c - u sigma - w sigma^2 / 2, run to sigma = s dt + s^2 T / 2
    from the room the command in flight leaves, stays >= 0 all the way."""
    rng = np.random.default_rng(8)
    c = rng.uniform(0.0, 0.05, 200)
    u, w, u_f = rng.normal(0.0, 0.3, 200), rng.normal(0.0, 2.0, 200), rng.normal(0.0, 0.3, 200)
    T, dt, delay = 0.3, 0.05, 0.02
    s = scale_for(c, u, T, dt, w, u_f, delay)
    room = c - np.maximum(u_f, 0.0) * delay
    grid = np.linspace(0.0, 1.0, 2001)
    for i in range(200):
        sigma = np.linspace(0.0, 1.0, 400)[:, None] * (grid * dt + grid**2 * T / 2)
        clear = np.all(room[i] - u[i] * sigma - w[i] * sigma**2 / 2 >= -1e-12, axis=0)
        if room[i] <= 0.0:  # no room: only a pair moving out goes on
            assert s[i] == (1.0 if u[i] <= 0.0 else 0.0)
            continue
        best = grid[np.argmin(clear)] if not clear.all() else 1.0
        assert s[i] == pytest.approx(best, abs=1e-3), (c[i], u[i], w[i], u_f[i])


def test_scale_moving_away_or_along_is_never_limited() -> None:
    s = scale_for(np.array([0.01, -0.5, 0.0, 2.0]), np.array([-1.0, -0.1, 0.0, 0.0]), 0.5, 0.01)
    assert s.tolist() == [1.0, 1.0, 1.0, 1.0]
    assert scale_for(np.array([-0.01, 0.0]), np.array([0.3, 0.3]), 0.5, 0.01).tolist() == [0.0, 0.0]


@pytest.mark.parametrize("speed, decel, period", [(0.4, 0.5, 0.01), (1.2, 0.3, 0.02), (0.1, 2.0, 0.01)])
def test_a_point_driven_at_a_ceiling_stops_before_it_and_close_to_it(
    speed: float, decel: float, period: float
) -> None:
    """Closed loop, as the velocity IK runs it: each period the full command (speed up, one
    actuator at its rate) is scaled; the actuator follows within its deceleration limit."""
    ceiling = Monitor([zone("ceiling", 0.3, height=5.0)], ["tip"])
    z, v, lowest_clear = 2.0, 0.0, math.inf
    for _ in range(int(30 / period)):
        T = stop_time([speed], [decel])  # one actuator at `speed` m/s drives the point 1:1
        check = ceiling.check(np.array([[0.0, 0.0, z]]), np.array([[0.0, 0.0, speed]]), T, period)
        target = check.scale * speed
        v = max(target, v - decel * period) if target < v else target  # accelerating is free here
        z += v * period
        lowest_clear = min(lowest_clear, 5.0 - 0.3 - z)
    assert lowest_clear >= -1e-9  # never past the boundary plus margin
    assert 5.0 - 0.3 - z < 0.02 and v < 1e-3  # and it got there: stopped at it, not short of it


def test_site_zones_follow_the_site_pose_and_without_a_pose_stop_approaches() -> None:
    mon = Monitor([zone("floor", 0.0, frame="site", height=100.0)], ["tip", "heel"])
    p = np.array([[1.0, 0.0, 0.01], [0.0, 0.0, 0.2]])
    v = np.array([[0.0, 0.0, -0.2], [0.0, 0.0, 0.0]])
    R = np.eye(3)
    check = mon.check(p, v, 0.2, 0.01, site=(R, np.array([0.0, 0.0, 100.0])))
    assert check.clearance["floor"] == (pytest.approx(0.01), "tip")
    # 0.002 s + 0.02 s^2 <= 0.01: s = 0.6589
    assert check.zone == "floor" and check.point == "tip" and check.scale == pytest.approx(0.65887, abs=1e-4)
    blind = mon.check(p, v, 0.2, 0.01)
    assert blind.scale == 0.0 and blind.clearance["floor"][0] == -math.inf


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "zones.yaml"
    path.write_text(text)
    return path


def test_a_zone_file_loads(tmp_path: Path) -> None:
    zones = load_zones(
        write(
            tmp_path,
            """
zones:
  power_line: {kind: ceiling, height: 7.5, margin: 1.0}
  trench: {kind: wall, point: [4.0, 0.0], normal: [1.0, 0.0], margin: 0.3}
  truck: {kind: box, frame: site, min: [10.0, 2.0, 0.0], max: [18.0, 5.0, 4.0]}
  tail_side: {kind: sector, from: 2.5, to: -2.5}
""",
        )
    )
    assert [(z.name, z.kind, z.frame) for z in zones] == [
        ("power_line", "ceiling", "base"),
        ("trench", "wall", "base"),
        ("truck", "box", "site"),
        ("tail_side", "sector", "base"),
    ]


@pytest.mark.parametrize(
    "text, key",
    [
        ("zones:\n  a: {kind: roof, height: 3}\n", "zones.a.kind"),
        ("zones:\n  a: {kind: ceiling, hieght: 3}\n", "zones.a.hieght"),
        ("zones:\n  a: {kind: ceiling}\n", "zones.a.height"),
        ("zones:\n  a: {kind: ceiling, height: .nan}\n", "zones.a.height"),
        ("zones:\n  a: {kind: box, min: [0, 0, 0], max: [1, -1, 1]}\n", "zones.a.max"),
        ("zones:\n  a: {kind: wall, point: [0, 0], normal: [0, 0]}\n", "zones.a.normal"),
        ("zones:\n  a: {kind: sector, frame: site, from: 0, to: 1}\n", "zones.a.frame"),
        ("zones:\n  a: {kind: surface, file: x.xml, side: below}\n", "zones.a"),
        ("zones: []\n", "zones"),
        ("zone:\n  a: {kind: ceiling, height: 3}\n", "zones"),
    ],
)
def test_a_malformed_zone_file_is_refused_naming_the_key(tmp_path: Path, text: str, key: str) -> None:
    with pytest.raises(ConfigError) as error:
        load_zones(write(tmp_path, text))
    assert str(error.value).split(":")[0] == key


@pytest.mark.parametrize(
    "name", ["excavator_cet200.yaml", "wheel_loader_wl20.yaml", "knuckle_crane_kc100.yaml"]
)
def test_monitored_points_move_as_their_positions_differentiate(name: str) -> None:
    from manipulator_kinematics.hydraulic import HydraulicModel
    from manipulator_kinematics.param_files import config_path

    model = HydraulicModel.from_file(config_path(name))
    D = model.lower + RNG.uniform(0.2, 0.8, (5, model.m)) * (model.upper - model.lower)
    D_dot = RNG.uniform(-1, 1, (5, model.m)) * np.asarray(model.max_speed)
    names, p, v = model.monitored(D, D_dot)
    pins = model.pins(D)
    # the pins, the cutting edge's corners, and where the file gives them (the CET200) the tool's
    # outline and the swing tail
    d = model.description
    assert len(names) == len(pins) + 2 + 2 * len(d.outline) + len(d.tail) and set(pins) <= set(names)
    np.testing.assert_allclose(p[:, 0], pins[names[0]], atol=1e-12)
    left, right = model.corners(D)
    np.testing.assert_allclose(p[:, names.index("left_corner")], left, atol=1e-12)
    np.testing.assert_allclose(p[:, names.index("right_corner")], right, atol=1e-12)
    h = 1e-6  # central differences of the positions along the motion
    ahead, behind = model.monitored(D + h * D_dot, D_dot)[1], model.monitored(D - h * D_dot, D_dot)[1]
    np.testing.assert_allclose(v, (ahead - behind) / (2 * h), atol=1e-6)


def drive(
    model,
    monitor: Monitor,
    D: np.ndarray,
    twist,
    seconds: float,
    period: float = 0.05,
    decel_time: float = 0.3,
):
    """Closed loop as the velocity IK runs it: the target twist's rates (eq. 9) capped at the
    actuators' speeds in their own direction, scaled by the zones; the actuators slow at most at
    max_speed / decel_time. Returns the smallest clearance per step and the states."""
    a = np.asarray(model.max_speed) / decel_time
    rate = np.zeros(model.m)
    clearances, states = [], []
    for k in range(int(seconds / period)):
        target = model.cylinder_rates(D, twist(k * period)).D_dot
        target = target / max(1.0, float(np.max(np.abs(target) / model.max_speed)))
        _, p, v = model.monitored(D, target)
        check = monitor.check(p, v, stop_time(target, a), period)
        wanted = check.scale * target
        rate = np.clip(wanted, rate - a * period, rate + a * period)
        D_next = D + rate * period
        if np.any(D_next < model.lower) or np.any(D_next > model.upper):  # a stroke end: stop there
            rate[:] = 0.0
            D_next = D
        D = D_next
        clearances.append(min(c for c, _ in check.clearance.values()))
        states.append(D.copy())
    _, p, _ = model.monitored(D, np.zeros(model.m))
    final = min(z.clearance(p)[0].min() for z in monitor.zones)
    return np.array(clearances), np.array(states), final


@pytest.mark.parametrize(
    "name", ["excavator_cet200.yaml", "wheel_loader_wl20.yaml", "knuckle_crane_kc100.yaml"]
)
@pytest.mark.slow
def test_random_commands_never_cross_a_ceiling_and_still_reach_it(name: str) -> None:
    from manipulator_kinematics.hydraulic import HydraulicModel
    from manipulator_kinematics.param_files import config_path

    model = HydraulicModel.from_file(config_path(name))
    D0 = np.asarray(model.reference, float)
    names, p, _ = model.monitored(D0, np.zeros(model.m))
    height = float(p[:, 2].max()) + 1.0  # 1 m above the highest point at the reference state
    monitor = Monitor([zone("ceiling", 0.2, height=height)], names)
    rng = np.random.default_rng(7)
    nq = len(model.task_names)
    for trial in range(3):
        direction = rng.normal(size=nq)
        direction[2] = abs(direction[2]) + 1.0  # upward on the whole
        clear, states, final = drive(model, monitor, D0.copy(), lambda t, d=direction: 0.6 * d, 6.0)
        assert clear.min() >= -1e-6, f"trial {trial}: a point crossed the ceiling plus margin"
    # Straight up at full speed: the machine rises until a point stops at the ceiling, near it.
    up = np.zeros(nq)
    up[2] = 1.0
    clear, states, final = drive(model, monitor, D0.copy(), lambda t: up, 15.0)
    assert clear.min() >= -1e-6
    moved = np.ptp(states, axis=0).max()
    assert moved > 0.05
    assert final < 0.05 or np.any(np.isclose(states[-1], model.upper) | np.isclose(states[-1], model.lower))


def test_the_compiled_check_is_the_numpy_check() -> None:
    """zone_kernel against the numpy path: random planes, boxes, sectors and a sloped TIN (points
    inside and outside, off the TIN, on a box's symmetry planes and on the swing axis too)."""
    from excavator_kinematics.grade.design_surface import Tin
    from manipulator_kinematics.zones import KERNEL

    assert KERNEL.get(wait=True) is not None
    xy = RNG.uniform(-4.0, 4.0, (60, 2))
    ground = Tin(np.column_stack([xy, 0.3 * xy[:, 0] - 0.2 * xy[:, 1]]), Triangulation(*xy.T).triangles)
    tin = Zone("t", "surface", "base", 0.2, {"side": "below"}, ground)
    rng = np.random.default_rng(5)
    for trial in range(20):
        zones = [
            zone("ceiling", 0.3, height=rng.uniform(2, 8)),
            zone("floor", 0.1, height=rng.uniform(-3, 0)),
            Zone(
                "w",
                "wall",
                "base",
                0.2,
                {"point": rng.uniform(-5, 5, 2).tolist(), "normal": rng.normal(size=2).tolist()},
            ),
            Zone("b1", "box", "base", 0.2, {"min": [-1.0, -1.0, -1.0], "max": [1.0, 2.0, 3.0]}),
            Zone(
                "b2",
                "box",
                "base",
                0.0,
                {"min": rng.uniform(-4, 0, 3).tolist(), "max": rng.uniform(0.5, 4, 3).tolist()},
            ),
            Zone("s1", "sector", "base", 0.1, {"from": rng.uniform(-3, 3), "to": rng.uniform(-3, 3)}),
            Zone("s2", "sector", "base", 0.3, {"from": 2.5, "to": -2.5}),
        ][: 3 + trial % 5] + ([tin] if trial % 2 else [])
        p = rng.uniform(-5, 5, (40, 3))
        p[:3] = [[0.0, 0.0, 1.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.0]]  # swing axis, box symmetry
        v = rng.normal(size=(40, 3))
        names = [f"p{i}" for i in range(40)]
        T, dt = rng.uniform(0, 0.5), rng.uniform(0.005, 0.1)
        # Half the trials with the paths' curvature and a command in flight.
        curved = {}
        if trial % 4 >= 2:
            flight = rng.normal(0.0, 0.5, (40, len(zones)))
            curved = {"accelerations": rng.normal(size=(40, 3)), "in_flight": flight, "delay": 0.03}
        compiled = Monitor(zones, names).check(p, v, T, dt, **curved)
        numpy_path = Monitor(zones, names).check(p, v, T, dt, compiled=False, **curved)
        assert compiled.scale == pytest.approx(numpy_path.scale, abs=1e-12)
        np.testing.assert_allclose(compiled.approach, numpy_path.approach, atol=1e-12)
        assert (compiled.zone, compiled.point) == (numpy_path.zone, numpy_path.point)
        for name, (c, point) in numpy_path.clearance.items():
            assert (
                compiled.clearance[name][0] == pytest.approx(c, abs=1e-12)
                and compiled.clearance[name][1] == point
            )
