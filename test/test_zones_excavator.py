"""The excavator's avoidance zones without ROS: its monitored points, and the velocity IK's loop
(twist split, rate command, zone scale; test/zone_scenario.py) run in one process for minutes of
simulated time against a ceiling, a wall, a floor and a TIN: no point crosses, and the machine
still gets to every zone."""

from __future__ import annotations

import numpy as np
import pytest
from zone_loop import CURVE_TOLERANCE, IDLE, LOADED, Timing, drive
from zone_scenario import CEILING, FLOOR, PERIOD, STOP_TIME, ZONES, Targets, clearances

from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.core.rate_command import rate_command
from excavator_kinematics.core.twist import split_twist
from excavator_kinematics.grade.design_surface import read_landxml
from excavator_kinematics.machine import MACHINE
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.zone_guard import STOPPED, ZoneGuard

EXC = MACHINE.model()
POINTS = MonitoredPoints(EXC)


def test_monitored_points_are_the_pins_corners_outline_and_tail() -> None:
    names = POINTS.names
    pins = EXC.pins(EXC.limits.reference)
    assert names[: len(pins)] == list(pins) and "bucket_tip" in names
    assert len(names) == len(set(names)) == len(pins) + 2 + 2 * 3 + 2
    rng = np.random.default_rng(1)
    D = EXC.limits.d_min + rng.uniform(0.1, 0.9, (50, 4)) * (EXC.limits.d_max - EXC.limits.d_min)
    p = POINTS.positions(D)
    at = {name: p[:, i] for i, name in enumerate(names)}
    # Corners and the outline's two sides are a bucket width apart, across the boom plane.
    np.testing.assert_allclose(np.linalg.norm(at["left_corner"] - at["right_corner"], axis=-1), 1.0)
    across = np.stack((-np.sin(D[:, 0]), np.cos(D[:, 0]), np.zeros(50)), axis=-1)
    np.testing.assert_allclose(at["bucket_outline_1_left"] - at["bucket_outline_1_right"], across, atol=1e-12)
    # An outline point keeps its distance from the bucket pin and from the tip (a rigid bucket).
    middle = 0.5 * (at["bucket_outline_1_left"] + at["bucket_outline_1_right"])
    x, y = 0.70, 0.62  # config/excavator_cet200.yaml, bucket.outline
    np.testing.assert_allclose(np.linalg.norm(middle - at["bucket_pin"], axis=-1), np.hypot(x, y))
    to_tip = np.linalg.norm(middle - at["bucket_tip"], axis=-1)
    np.testing.assert_allclose(to_tip, np.hypot(1.309039383 - x, y))
    # The tail: the tail swing radius behind the swing axis, at its heights.
    tail = np.stack((at["tail_0"], at["tail_1"]), axis=1)
    np.testing.assert_allclose(np.hypot(tail[..., 0], tail[..., 1]), 2.75)
    np.testing.assert_allclose(tail[..., 2], [[1.05, 2.25]] * 50)
    np.testing.assert_allclose(tail[:, 0, 0], -2.75 * np.cos(D[:, 0]))


def test_point_velocities_are_the_positions_derivative() -> None:
    rng = np.random.default_rng(2)
    for _ in range(20):
        D = EXC.limits.d_min + rng.uniform(0.1, 0.9, 4) * (EXC.limits.d_max - EXC.limits.d_min)
        D_dot = rng.uniform(-1, 1, 4) * EXC.limits.max_rates
        _, v = POINTS(D, D_dot)
        h = 1e-4  # central differences, second order: an independent estimate
        central = (POINTS.positions(D + h * D_dot) - POINTS.positions(D - h * D_dot)) / (2 * h)
        np.testing.assert_allclose(v, central, atol=2e-5)
        # The tip's velocity in closed form (eq. 8).
        np.testing.assert_allclose(v[POINTS.names.index("bucket_tip")], EXC.jc0(D)[:3] @ D_dot, atol=2e-5)


def test_point_accelerations_are_the_second_derivative_along_the_command() -> None:
    """MonitoredPoints.motion's accelerations against second differences of the positions at
    another step; the tip's also against the derivative of its closed-form velocity (eq. 8); at
    a stroke end commanded inward, the one-sided difference."""
    rng = np.random.default_rng(5)
    h = 4e-3
    for _ in range(20):
        D = EXC.limits.d_min + rng.uniform(0.1, 0.9, 4) * (EXC.limits.d_max - EXC.limits.d_min)
        D_dot = rng.uniform(-1, 1, 4) * EXC.limits.max_rates
        a = POINTS.motion(D, D_dot)[2]
        at = POINTS.positions(np.stack((D - h * D_dot, D, D + h * D_dot)))
        np.testing.assert_allclose(a, (at[0] - 2 * at[1] + at[2]) / h**2, atol=1e-4)
        tip = (EXC.jc0(D + h * D_dot)[:3] - EXC.jc0(D - h * D_dot)[:3]) @ D_dot / (2 * h)
        np.testing.assert_allclose(a[POINTS.names.index("bucket_tip")], tip, atol=1e-4)
    # At the ends, commanded inward: one-sided, within its first-order error.
    for end, inward in ((EXC.limits.d_max, -1.0), (EXC.limits.d_min, 1.0)):
        D = np.where(np.arange(4) == 0, 0.3, end)
        D_dot = inward * EXC.limits.max_rates * [0.0, 1.0, 1.0, 1.0]
        a = POINTS.motion(D, D_dot)[2]
        at = POINTS.positions(np.stack((D, D + h * D_dot, D + 2 * h * D_dot)))
        np.testing.assert_allclose(a, (at[0] - 2 * at[1] + at[2]) / h**2, atol=0.1)


#: The velocity IK's bucket_angle_gives_way: at a stroke end the tip keeps its direction and the
#: bucket angle gives way, so the random walk is not held at every stroke end it runs into.
GIVES_WAY = True


def guard() -> ZoneGuard:
    return ZoneGuard.from_file(ZONES, POINTS.names, EXC.limits.max_rates / STOP_TIME, PERIOD, read_landxml)


def run(
    seconds: float, seed: int, timing: Timing = IDLE, opening: tuple = (), curved: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """The velocity IK's steps (twist split, rate command) and excavator_sim's ideal actuators
    (its default) in test/zone_loop.py's loop; states and zone factors."""
    plant = Plant(EXC.limits, EXC.limits.reference)
    targets = Targets(seed, EXC.pose(EXC.limits.reference)[:3], opening)

    def command(D: np.ndarray, t: float) -> tuple[np.ndarray, ...]:
        tip = EXC.pose(D)[:3]
        linear, angular = targets(t, tip)
        split = split_twist(D[0], tip, linear, angular)
        rates = rate_command(EXC.jc0(D), D, split.q_dot, EXC.limits, 50.0, 0.1, GIVES_WAY)
        return rates.d_dot, *POINTS.motion(D, rates.d_dot)

    return drive(plant, command, guard(), seconds, timing, seed, curved)


def test_straight_up_stops_at_the_ceiling() -> None:
    """The loop's short form for the fast tier: 5 s of the tip commanded straight up."""
    states, scales = run(5.0, seed=1, opening=((5.0, np.array([0.0, 0.0, 0.6])),))
    ceiling = clearances(POINTS.positions(states))["power_line"]
    assert 0.0 <= ceiling.min() < 0.01 and scales[-1] == 0.0


@pytest.mark.slow
def test_minutes_of_random_targets_never_cross_a_zone_and_reach_every_one() -> None:
    states, scales = run(120.0, seed=34, timing=LOADED)
    clear = clearances(POINTS.positions(states))
    print("smallest clearances " + ", ".join(f"{z} {c.min() * 1e3:.4f} mm" for z, c in clear.items()))
    for zone, c in clear.items():
        assert c.min() >= -CURVE_TOLERANCE, f"{zone}: crossed by {-c.min():.4f} m"
        assert c.min() < 0.03, f"{zone}: never came within 3 cm ({c.min():.3f} m)"
    # Stopped at times, not always; and it still moves: the tip covers most of the heights allowed.
    assert 0.02 < np.mean(scales == 0.0) < 0.5 and np.mean(scales == 1.0) > 0.5
    tip = POINTS.positions(states)[:, POINTS.names.index("bucket_tip")]
    assert np.ptp(tip[:, 2]) > 0.5 * (CEILING - FLOOR) and np.ptp(tip[:, 0]) > 2.0


def test_a_machine_inside_a_zone_may_only_move_out() -> None:
    zones = guard()
    D = EXC.limits.reference.copy()
    up = np.array([0.0, 0.0, 0.5, 0.0])
    x = rate_command(EXC.jc0(D), D, up, EXC.limits, 50.0, 0.1).d_dot
    p, v = POINTS(D, x)
    lifted = p + [0.0, 0.0, CEILING - p[:, 2].max() + 0.1]  # the highest point 10 cm into the margin
    verdict = zones.check(lifted, v, x)
    assert verdict.scale == 0.0 and verdict.state == STOPPED
    assert "inside zone power_line" in verdict.message and "only motion out" in verdict.message
    assert zones.check(lifted, -v, -x).scale == 1.0  # down and out: not slowed


@pytest.mark.parametrize(
    "text, key",
    [
        ("zones:\n  a: {kind: ceiling, height: .nan}\n", "zones_file: {path}: zones.a.height"),
        ("zones:\n  a: {kind: floor, frame: site, height: 1}\n", "zones_file: {path}: zones.a.frame"),
        ("zones:\n  a: {kind: surface, file: none.xml, side: below}\n", "zones_file: {path}: zones.a.file"),
    ],
)
def test_a_bad_zone_file_is_refused_in_one_line_naming_the_key(tmp_path, text: str, key: str) -> None:
    path = tmp_path / "zones.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        ZoneGuard.from_file(path, POINTS.names, EXC.limits.max_rates, PERIOD, read_landxml)
    message = str(error.value)
    assert message.startswith(key.format(path=path) + ":") and "\n" not in message


def test_plan_path_ends_before_a_zone_with_the_reason() -> None:
    from excavator_kinematics.core.path_zones import plan_clear

    zones = guard().zones
    tip = EXC.pose(EXC.limits.reference)[:3]
    waypoints = [tip, tip + [0.5, 0.0, 0.0], tip + [0.5, 0.0, 5.0]]  # then straight up, through the ceiling
    plan = plan_clear(EXC, POINTS, zones, waypoints, 0.05, 0.5, 0.5)
    assert plan.truncated and plan.last_waypoint == 1 and plan.timing is not None
    assert "enters zone power_line" in plan.message and "the path ends before it" in plan.message
    # Every sample is clear of every zone; the last one within a step (at the tip) of the ceiling.
    clear = clearances(POINTS.positions(plan.timing.q))
    assert min(c.min() for c in clear.values()) >= 0.0
    assert clear["power_line"][-1] < 0.06
    np.testing.assert_allclose(plan.timing.qd[-1], 0.0, atol=1e-9)  # at rest at its end
    # A path clear of every zone is left as it is; one that starts inside a zone is refused.
    low = plan_clear(EXC, POINTS, zones, waypoints[:2], 0.05, 0.5, 0.5)
    assert not low.truncated and low.last_waypoint == 1
    inside = plan_clear(EXC, POINTS, zones, [tip + [0.0, 0.0, -2.5], tip], 0.05, 0.5, 0.5)
    assert inside.timing is None and inside.message.startswith("the path starts inside a zone")


@pytest.mark.parametrize(
    "section, key, value, named",
    [
        ("tool", "outline", [0.1, 0.6, 0.7], "hydraulic_machine.tool.outline: expected [x, z] pairs"),
        ("tool", "outline", [0.1, float("nan")], "hydraulic_machine.tool.outline[1]"),
        (
            "swing",
            "tail_heights",
            None,
            "hydraulic_machine.swing.tail_heights: tail_radius and tail_heights go together",
        ),
        ("swing", "tail_radius", -1.0, "hydraulic_machine.swing.tail_radius"),
    ],
)
def test_the_optional_monitored_points_of_the_machine_file_are_checked(section, key, value, named) -> None:
    """tool.outline and swing.tail_radius/tail_heights: refused naming the key; left out, the
    machine has only its pins and tool corners."""
    sections = load_parameters(config_path("excavator_cet200.yaml"))
    description = sections["hydraulic_machine"]
    if value is None:
        del description[section][key]
    else:
        description[section][key] = value
    with pytest.raises(ConfigError) as error:
        MACHINE.model_of(sections)
    assert str(error.value).startswith(named), str(error.value)
    for optional in ("outline",):
        description["tool"].pop(optional, None)
    for optional in ("tail_radius", "tail_heights"):
        description["swing"].pop(optional, None)
    bare = MonitoredPoints(MACHINE.model_of(sections))
    assert bare.names == POINTS.names[: len(POINTS.names) - 8]
