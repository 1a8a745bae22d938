"""The hydraulic family's avoidance zones without ROS: the optional monitored points of a machine
file (tool outline, swing tail), and hydraulic_velocity_ik's loop (task rates, rate command, zone
scale: the pieces of manipulator_kinematics.hydraulic.control it runs) in one process for the wheel
loader and the knuckle crane against a ceiling, a wall, a floor and a TIN
(test/family_zone_scenario.py): no point crosses, and the machine still gets to the zones."""

from __future__ import annotations

import numpy as np
import pytest
from family_zone_scenario import SCENARIOS, Scenario
from zone_loop import CURVE_TOLERANCE, IDLE, LOADED, Timing, drive
from zone_scenario import PERIOD, STOP_TIME

from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.hydraulic.control import Plant, rate_command, task_rates, toward_line
from manipulator_kinematics.hydraulic.description import parse
from manipulator_kinematics.landxml import read_landxml
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.registry import machine
from manipulator_kinematics.zone_guard import STOPPED, ZoneGuard


def model(scenario: Scenario) -> HydraulicModel:
    return HydraulicModel.from_file(config_path(scenario.config))


def section(name: str = "knuckle_crane_kc100.yaml") -> dict:
    return load_parameters(config_path(name))["hydraulic_machine"]


def test_the_optional_points_are_the_tool_outline_and_the_tail() -> None:
    raw = section()
    raw["tool"].update(width=0.6, outline=[0.3, 0.2, -0.2, 0.4])
    raw["swing"].update(tail_radius=1.4, tail_heights=[0.3, 1.1])
    h = HydraulicModel(parse(raw))
    bare = HydraulicModel(parse(section()))
    rng = np.random.default_rng(3)
    D = h.lower + rng.uniform(0.1, 0.9, (20, h.m)) * (h.upper - h.lower)
    D_dot = rng.uniform(-1, 1, (20, h.m)) * h.max_speed
    names, p, v = h.monitored(D, D_dot)
    plain = bare.monitored(D, D_dot)[0]
    assert names == [
        *plain,
        "tool_outline_0_left",
        "tool_outline_1_left",
        "tool_outline_0_right",
        "tool_outline_1_right",
        "tail_0",
        "tail_1",
    ]
    at = {name: p[:, i] for i, name in enumerate(names)}
    across = np.stack((-np.sin(D[:, 0]), np.cos(D[:, 0]), np.zeros(20)), axis=-1)
    np.testing.assert_allclose(
        at["tool_outline_1_left"] - at["tool_outline_1_right"], 0.6 * across, atol=1e-12
    )
    # An outline point is rigid with the tool body: its distances from the body's two pins.
    middle = 0.5 * (at["tool_outline_1_left"] + at["tool_outline_1_right"])
    pins = h.description.bodies[h.description.tool_body]
    for pin, xz in pins.items():
        np.testing.assert_allclose(np.linalg.norm(middle - at[pin], axis=-1), np.hypot(*(xz - [-0.2, 0.4])))
    tail = np.stack((at["tail_0"], at["tail_1"]), axis=1)
    np.testing.assert_allclose(np.hypot(tail[..., 0], tail[..., 1]), 1.4)
    np.testing.assert_allclose(tail[..., 2], [[0.3, 1.1]] * 20)
    np.testing.assert_allclose(tail[:, 0, 0], -1.4 * np.cos(D[:, 0]))
    h_ = 1e-6  # the velocities: central differences of the positions along the motion
    ahead, behind = h.monitored(D + h_ * D_dot, D_dot)[1], h.monitored(D - h_ * D_dot, D_dot)[1]
    np.testing.assert_allclose(v, (ahead - behind) / (2 * h_), atol=1e-6)
    # The accelerations at constant rates: central differences of the velocities along the motion.
    a, k = h.monitored_motion(D, D_dot)[3], 1e-5
    ahead, behind = h.monitored(D + k * D_dot, D_dot)[2], h.monitored(D - k * D_dot, D_dot)[2]
    np.testing.assert_allclose(a, (ahead - behind) / (2 * k), atol=1e-5)
    # A tool without width has its outline once.
    raw["tool"]["width"] = 0.0
    assert HydraulicModel(parse(raw)).monitored(D, D_dot)[0][len(plain) : len(plain) + 2] == [
        "tool_outline_0",
        "tool_outline_1",
    ]


@pytest.mark.parametrize(
    "where, value, named",
    [
        ("tool.outline", [0.1, 0.2, 0.3], "hydraulic_machine.tool.outline: expected [x, z] pairs"),
        ("tool.outline", [0.1, float("nan")], "hydraulic_machine.tool.outline[1]"),
        ("swing.tail_radius", -1.0, "hydraulic_machine.swing.tail_radius"),
        ("swing.tail_radius", 1.0, "hydraulic_machine.swing.tail_heights: tail_radius and tail_heights go"),
    ],
)
def test_the_optional_points_are_checked_naming_the_key(where: str, value, named: str) -> None:
    raw = section()
    part, key = where.split(".")
    raw[part][key] = value
    with pytest.raises(ConfigError) as error:
        parse(raw)
    assert str(error.value).startswith(named) and "\n" not in str(error.value), str(error.value)


def test_the_registry_hooks_give_the_points_and_the_surfaces() -> None:
    for name, scenario in SCENARIOS.items():
        record = machine(name)
        arm = record.model()
        points = record.monitored(arm)
        h = model(scenario)
        names, p, _ = h.monitored(h.reference, np.zeros(h.m))
        assert points.names == names
        np.testing.assert_allclose(points.positions(h.reference - h.zero_offset), p, atol=1e-12)
        guard = ZoneGuard.from_file(scenario.zones, names, h.max_speed, PERIOD, record.read_surface)
        assert [z.kind for z in guard.zones] == ["ceiling", "wall", "floor", "surface"]


def guard(scenario: Scenario, h: HydraulicModel) -> ZoneGuard:
    names = h.monitored(h.reference, np.zeros(h.m))[0]
    return ZoneGuard.from_file(scenario.zones, names, h.max_speed / STOP_TIME, PERIOD, read_landxml)


def run(
    scenario: Scenario,
    seconds: float,
    seed: int,
    timing: Timing = IDLE,
    opening: tuple | None = None,
    curved: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """hydraulic_velocity_ik's steps (its default condition threshold, stroke horizon and line
    gain: a constant target's drift off its line corrected, as the node does) and hydraulic_sim's
    ideal actuators (its default) in test/zone_loop.py's loop, after ``opening`` (default: the
    scenario's); the states, their monitored points and the zone factors."""
    h = model(scenario)
    plant = Plant(h.lower, h.upper, h.max_speed, h.reference, 0.0)
    rows = list(h.description.velocity_rows)
    targets = scenario.targets(seed, h.pose(h.reference)[:3], opening)
    line: list = [None]  # (twist, Q where its line began, its Q_dot)

    def command(D: np.ndarray, t: float) -> tuple[np.ndarray, ...]:
        measured = h.measured(D)
        Q = measured.Q
        twist = np.concatenate(targets(t, Q[:3]))
        q_dot = task_rates(D, twist, h.swing, h.description.has_angle)
        if line[0] is None or not np.array_equal(line[0][0], twist):
            line[0] = (twist, Q, q_dot)
        correction = toward_line(line[0][1], line[0][2], Q, rows, 2.0)
        if correction is None:  # moved, not drifted: a new line from here
            line[0], correction = (twist, Q, q_dot), np.zeros_like(Q)
        wanted = (q_dot + correction)[rows]
        rates = rate_command(measured.jc0[rows], D, wanted, h.lower, h.upper, h.max_speed, 100.0, 0.1)
        return rates.d_dot, *h.monitored_motion(D, rates.d_dot)[1:]

    states, scales = drive(plant, command, guard(scenario, h), seconds, timing, seed, curved)
    return states, h.monitored(states, np.zeros_like(states))[1], scales


#: The fast tier's short form: (machine, tool velocity, the zone it stops at): the loader's
#: bucket goes ahead as it lifts, so it meets the wall; the crane's tip goes straight ahead.
SHORT = [
    ("wheel_loader", np.array([0.0, 0.0, 0.6]), "wall"),
    ("knuckle_crane", np.array([0.6, 0.0, 0.0]), "road_edge"),
]


@pytest.mark.parametrize("name, velocity, zone", SHORT)
def test_straight_at_a_zone_stops_at_it(name: str, velocity: np.ndarray, zone: str) -> None:
    """The loop's short form for the fast tier: 3.5 s of one tool velocity."""
    scenario = SCENARIOS[name]
    _, points, scales = run(scenario, 3.5, seed=1, opening=((3.5, velocity),))
    clearance = scenario.clearances(points)[zone]
    assert 0.0 <= clearance.min() < 0.01 and scales[-1] == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_minutes_of_random_targets_never_cross_a_zone_and_reach_them(name: str) -> None:
    scenario = SCENARIOS[name]
    # The scenario's opening (straight at the zones: about 20 s), then random targets, with the
    # delays and stalls of a loaded machine between the processes.
    states, points, scales = run(scenario, 120.0, seed=34, timing=LOADED)
    clear = scenario.clearances(points)
    print(
        f"{name}: smallest clearances " + ", ".join(f"{z} {c.min() * 1e3:.4f} mm" for z, c in clear.items())
    )
    for zone, c in clear.items():
        assert c.min() >= -CURVE_TOLERANCE, f"{zone}: crossed by {-c.min():.4f} m"
    for zone in scenario.reached:
        assert clear[zone].min() < 0.03, f"{zone}: never came within 3 cm ({clear[zone].min():.3f} m)"
    # Stopped at times, not always; and it still moves about.
    assert 0.01 < np.mean(scales == 0.0) < 0.5 and np.mean(scales == 1.0) > 0.5
    h = model(scenario)
    cylinders = slice(1 if h.swing else 0, None)
    assert np.all(np.ptp(states, axis=0)[cylinders] > 0.3 * (h.upper - h.lower)[cylinders])


@pytest.mark.slow
def test_a_straight_prediction_lets_the_crane_creep_past_its_ceiling() -> None:
    """The crane lifted to its ceiling, then driven ahead along it: its points' paths curve up
    between commands. Taken as straight (the check in its first form) they cross; with their curvature
    they do not, and the tool still goes ahead along the ceiling (slowed: held to the ceiling,
    its path would rise into it within the horizon): at a loaded machine's timing, over half of
    the 1.6 m to the wall in 6 s; across processes, on a loaded machine, it crept far slower
    (hence the scenario's opening goes at the wall directly)."""
    scenario = SCENARIOS["knuckle_crane"]
    opening = ((14.0, np.array([0.0, 0.0, 0.6])), (6.0, np.array([0.6, 0.0, 0.0])))
    seconds = sum(t for t, _ in opening)
    straight = scenario.clearances(run(scenario, seconds, 34, LOADED, opening, curved=False)[1])
    curved = scenario.clearances(run(scenario, seconds, 34, LOADED, opening)[1])
    assert straight["power_line"].min() < -2e-4, straight["power_line"].min()
    assert curved["power_line"].min() >= -CURVE_TOLERANCE, curved["power_line"].min()
    assert curved["road_edge"].min() < 0.8, curved["road_edge"].min()


def test_a_machine_inside_a_zone_may_only_move_out() -> None:
    scenario = SCENARIOS["knuckle_crane"]
    h = model(scenario)
    zones = guard(scenario, h)
    D = h.reference.copy()
    up = rate_command(h.jc0(D), D, np.array([0.0, 0.0, 0.5]), h.lower, h.upper, h.max_speed, 100.0, 0.1).d_dot
    _, p, v = h.monitored(D, up)
    lifted = p + [0.0, 0.0, scenario.ceiling - p[:, 2].max() + 0.1]  # 10 cm into the margin
    verdict = zones.check(lifted, v, up)
    assert verdict.scale == 0.0 and verdict.state == STOPPED
    assert "inside zone power_line" in verdict.message and "only motion out" in verdict.message
    assert zones.check(lifted, -v, -up).scale == 1.0  # down and out: not slowed
