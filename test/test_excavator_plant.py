"""Numpy pieces of the simulator and the forward node: plant integration, swing hold, accelerations."""

from __future__ import annotations

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.nodes.state_input import InputError, RateDifferentiator, SwingHold
from manipulator_kinematics.param_files import ConfigError

LIMITS = Excavator.default().limits
REF = LIMITS.reference


def test_ideal_plant_integrates_the_held_rate() -> None:
    plant = Plant(LIMITS, REF)
    command = np.array([0.2, 0.05, -0.1, 0.12])
    for _ in range(100):
        plant.step(command, 0.01)
    np.testing.assert_allclose(plant.d, REF + command * 1.0, atol=1e-12)
    np.testing.assert_allclose(plant.d_dot, command)


def test_lagged_plant_matches_the_first_order_step_response() -> None:
    """Twenty steps of 10 ms equal the closed-form step response of a first-order lag at 0.2 s."""
    command = np.array([0.5, 0.1, -0.1, 0.15])
    tau, t = 0.05, 0.2
    plant = Plant(LIMITS, REF, time_constant=tau)
    for _ in range(20):
        plant.step(command, 0.01)
    np.testing.assert_allclose(plant.d_dot, command * (1 - np.exp(-t / tau)), atol=1e-12)
    np.testing.assert_allclose(plant.d, REF + command * (t - tau * (1 - np.exp(-t / tau))), atol=1e-12)


def test_each_actuator_saturates_at_its_own_speed() -> None:
    plant = Plant(LIMITS, REF)
    command = np.array([-5.0, 1.0, 0.01, -1.0])
    plant.step(command, 0.1)
    expected = np.array(
        [-LIMITS.max_swing_speed, LIMITS.max_cylinder_speed[0], 0.01, -LIMITS.max_cylinder_speed[2]]
    )
    np.testing.assert_allclose(plant.d_dot, expected)
    np.testing.assert_allclose(plant.d, REF + 0.1 * expected)


def test_actuators_stop_at_their_stroke_ends() -> None:
    plant = Plant(LIMITS, REF)
    command = np.array([0.0, 0.15, -0.18, 0.0])
    for _ in range(100):
        plant.step(command, 0.1)
    assert plant.d[1] == LIMITS.stroke_max[0] and plant.d[2] == LIMITS.stroke_min[1]
    np.testing.assert_allclose(plant.d_dot, 0.0)
    plant.step(-command, 0.1)  # and leave them again
    np.testing.assert_allclose(plant.d[1:3], [LIMITS.stroke_max[0] - 0.015, LIMITS.stroke_min[1] + 0.018])


def test_start_state_outside_the_limits_is_a_config_error() -> None:
    bad = REF.copy()
    bad[3] = LIMITS.stroke_max[2] + 0.01
    with pytest.raises(ConfigError, match="outside the limits"):
        Plant(LIMITS, bad)
    with pytest.raises(ConfigError, match="finite"):
        Plant(LIMITS, np.array([0.0, np.nan, 3.0, 2.0]))


def test_swing_hold_extrapolates_and_expires() -> None:
    hold = SwingHold(max_age=0.1)
    with pytest.raises(InputError, match="no swing state"):
        hold.at(0)
    hold.update(1_000_000_000, 0.5, 0.2, 0.01)
    angle, rate, acceleration = hold.at(1_050_000_000)
    assert angle == pytest.approx(0.5 + 0.2 * 0.05) and rate == 0.2 and acceleration == 0.01
    assert hold.at(950_000_000)[0] == pytest.approx(0.5 - 0.2 * 0.05)
    with pytest.raises(InputError, match="max age"):
        hold.at(1_100_000_001)


def test_differences_of_rates_over_stamps() -> None:
    diff = RateDifferentiator(time_constant=0.0, max_gap=0.2)
    assert diff.update(1_000_000_000, np.array([0.1, 0.2])) is None
    np.testing.assert_allclose(diff.update(1_010_000_000, np.array([0.11, 0.18])), [1.0, -2.0])
    np.testing.assert_allclose(diff.update(1_030_000_000, np.array([0.11, 0.19])), [0.0, 0.5])
    assert diff.update(1_030_000_000, np.array([0.2, 0.2])) is None  # stamp did not increase: restart
    assert diff.update(1_300_000_000, np.array([0.2, 0.2])) is None  # gap too long: restart
    np.testing.assert_allclose(diff.update(1_301_000_000, np.array([0.201, 0.2])), [1.0, 0.0])


def test_low_pass_of_the_differences() -> None:
    tau, dt = 0.05, 0.01
    diff = RateDifferentiator(time_constant=tau, max_gap=0.2)
    diff.update(0, np.array([0.0]))
    first = diff.update(10_000_000, np.array([0.01]))  # 1 m/s^2, the filter starts there
    np.testing.assert_allclose(first, [1.0])
    out = diff.update(20_000_000, np.array([0.01]))  # raw 0: decays by exp(-dt / tau)
    np.testing.assert_allclose(out, [np.exp(-dt / tau)])


def test_speeds_and_stroke_ends_hold_exactly_for_random_commands() -> None:
    """10,000 random steps (commands up to 10 x the speeds, steps up to 1 s, with and without lag):
    D stays inside its ends and D_dot inside its speeds exactly; a non-finite command is refused."""
    rng = np.random.default_rng(5)
    outside = 0
    for tau in (0.0, 0.05):
        plant = Plant(LIMITS, REF, time_constant=tau)
        for _ in range(5_000):
            plant.step(rng.uniform(-10.0, 10.0, 4) * LIMITS.max_rates, float(rng.uniform(0.0, 1.0)))
            outside += int(np.any(plant.d < LIMITS.d_min) or np.any(plant.d > LIMITS.d_max))
            outside += int(np.any(np.abs(plant.d_dot) > LIMITS.max_rates))
    assert outside == 0
    for bad in (np.array([np.nan, 0.0, 0.0, 0.0]), np.array([0.0, np.inf, 0.0, 0.0])):
        with pytest.raises(ValueError, match="finite"):
            plant.step(bad, 0.01)
    assert np.all(np.isfinite(plant.d))
