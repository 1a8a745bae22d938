"""The demo's planned move without ROS: the trajectory read from plan_path's points, the rate
law, the arrival check, and the whole way back planned and streamed into the simulator's plant."""

from __future__ import annotations

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import ACTUATORS, Excavator
from excavator_kinematics.core.path import plan_path
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.demo.bucket_path import to_task
from excavator_kinematics.demo.demo import PLAN_TIP_SPEED, demo_cycle
from excavator_kinematics.demo.planned_move import GAIN, LEAD, SETTLE, TOLERANCE, Trajectory, arrival


@pytest.fixture(scope="module")
def exc() -> Excavator:
    return Excavator.default()


def simple() -> Trajectory:
    t = [0.0, 1.0, 2.0]
    q = [[0.0, 1.0, 2.0, 3.0], [1.0, 1.5, 2.0, 3.0], [2.0, 2.0, 2.0, 3.0]]
    qd = [[0.0, 0.0, 0.0, 0.0], [1.0, 0.5, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]
    return Trajectory.from_points(list(ACTUATORS), t, q, qd)


def test_points_are_reordered_to_the_actuators() -> None:
    names = list(reversed(ACTUATORS))
    trajectory = Trajectory.from_points(names, [0.0], [[4.0, 3.0, 2.0, 1.0]], [[0.4, 0.3, 0.2, 0.1]])
    np.testing.assert_array_equal(trajectory.q[0], [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(trajectory.qd[0], [0.1, 0.2, 0.3, 0.4])
    with pytest.raises(ValueError, match="swing_joint"):
        Trajectory.from_points(names[:3], [0.0], [[1.0, 2.0, 3.0]], [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="points"):
        Trajectory.from_points(names, [], [], [])


def test_samples_between_and_after_the_end() -> None:
    trajectory = simple()
    q, qd = trajectory.at(0.5)
    np.testing.assert_allclose(q, [0.5, 1.25, 2.0, 3.0], atol=1e-15)
    np.testing.assert_allclose(qd, [0.5, 0.25, 0.0, 0.0], atol=1e-15)
    q, qd = trajectory.at(5.0)  # held: the last position, at rest
    np.testing.assert_array_equal(q, [2.0, 2.0, 2.0, 3.0])
    np.testing.assert_array_equal(qd, np.zeros(4))


def test_rate_law_is_feed_forward_plus_position_feedback() -> None:
    trajectory = simple()
    q, _ = trajectory.at(0.7)
    _, qd_ahead = trajectory.at(0.7 + LEAD)
    rates, planned = trajectory.command(0.7, q)
    np.testing.assert_allclose(rates, qd_ahead, atol=1e-15)
    np.testing.assert_array_equal(planned, q)
    offset = np.array([0.01, -0.02, 0.0, 0.03])
    rates, _ = trajectory.command(0.7, q - offset)
    np.testing.assert_allclose(rates, qd_ahead + GAIN * offset, atol=1e-15)


def test_arrival_measures_d_and_the_tip(exc: Excavator) -> None:
    start = exc.limits.reference
    assert arrival(exc, start, start).ok
    off = start + np.array([0.0, 0.0, 2 * TOLERANCE[2], 0.0])
    result = arrival(exc, off, start)
    assert not result.ok
    np.testing.assert_allclose(result.error, [0.0, 0.0, 2 * TOLERANCE[2], 0.0], atol=1e-15)
    expected = np.linalg.norm(exc.pose(off)[:3] - exc.pose(start)[:3])
    assert result.tip_error == pytest.approx(expected, rel=1e-12) and result.tip_error > 0.0


def test_the_way_back_within_the_limits_and_streamed_into_the_plant(exc: Excavator) -> None:
    # The demo's situation: over the truck with the bucket at its start angle.
    start = exc.limits.reference
    q0 = exc.pose(start)
    c0 = np.r_[np.hypot(q0[0], q0[1]), np.arctan2(q0[1], q0[0]), q0[2:]]
    level_end = to_task(demo_cycle(c0).segments[-1].end, np.zeros(4))[0]
    here = exc.ik(level_end).solution
    plan = plan_path(exc, [level_end[:3], q0[:3]], 0.05, PLAN_TIP_SPEED, 0.5, seed=here)
    assert plan.ok and not plan.truncated, plan.message
    timing = plan.timing
    np.testing.assert_allclose(timing.q[0], here, atol=1e-9)  # from where the machine is
    np.testing.assert_allclose(timing.q[-1], start, atol=1e-9)  # to the start
    assert np.all(np.abs(timing.qd) <= exc.limits.max_rates * (1 + 1e-9))
    assert np.max(np.abs(timing.qd) / exc.limits.max_rates) > 0.9  # an actuator's limit sets the pace
    # Streamed at 50 Hz into the simulator's plant (20 ms lag), one step of transport delay.
    trajectory = Trajectory(timing.t, timing.q, timing.qd)
    plant = Plant(exc.limits, here.copy(), 0.02)
    dt, t, rates = 0.02, 0.0, np.zeros(4)
    worst = np.zeros(4)
    while t <= trajectory.duration + SETTLE:
        plant.step(rates, dt)
        t += dt
        rates, q = trajectory.command(t, plant.d)
        worst = np.maximum(worst, np.abs(q - plant.d))
    assert arrival(exc, plant.d, start).ok, (plant.d - start, worst)
    assert np.all(worst < 0.01), worst  # on the way: within 1 cm (0.01 rad) of the plan
