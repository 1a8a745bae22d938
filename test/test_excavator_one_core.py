"""The excavator computed by the hydraulic family's numpy core (issue 31, item 1: one core).

``Excavator``'s numpy path, the reference of its compiled kernel, is the family core of the same
machine file (``Excavator.hydraulic``, a HydraulicModel): checked here bit for bit on the numpy
path (the excavator adds its checks of D and its names, no arithmetic of its own), on the states
only the excavator takes (within its stroke tolerance beyond an end, a continuous swing), and
against the paper's independent forms: J0 K = JC0 (eqs. 5, 7, 8) and K against central
differences of the joint angles.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from excavator_kinematics.core import kinematics
from excavator_kinematics.core.kinematics import Excavator, StrokeError
from excavator_kinematics.core.machine_file import PINS, STROKE_TOLERANCE
from excavator_kinematics.core.urdf_joints import joint_positions
from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.hydraulic.model import KERNEL
from manipulator_kinematics.param_files import config_path, load_parameters

EXC = Excavator.default()
LIM = EXC.limits
RNG = np.random.default_rng(3131)


@pytest.fixture
def numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """The excavator's compiled kernel set aside: its numpy path answers."""
    monkeypatch.setattr(kinematics.KERNEL, "ready", None)
    monkeypatch.setenv("MK_COMPILED", "0")


def _states(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    D = RNG.uniform(LIM.d_min, LIM.d_max, (n, 4))
    return D, RNG.uniform(-1, 1, (n, 4)) * LIM.max_rates, RNG.uniform(-1, 1, (n, 4)) * LIM.max_rates


def test_the_excavator_holds_the_family_model_of_its_file() -> None:
    family = HydraulicModel.from_file(config_path("excavator_cet200.yaml"))
    assert isinstance(EXC.hydraulic, HydraulicModel)
    assert EXC.hydraulic.actuator_names == family.actuator_names == kinematics.ACTUATORS
    np.testing.assert_array_equal(EXC.hydraulic.lower, LIM.d_min)
    np.testing.assert_array_equal(EXC.hydraulic.upper, LIM.d_max)
    D = _states(50)[0]
    np.testing.assert_array_equal(EXC.hydraulic.solve(D).Q, family.solve(D).Q)


@pytest.mark.usefixtures("numpy_path")
def test_the_numpy_path_is_the_family_core_bit_for_bit() -> None:
    D, V, A = _states(300)
    core = EXC.hydraulic.solve(D, V, A)
    state = EXC.state(D, V, A)
    for field in kinematics.BucketState._fields:
        np.testing.assert_array_equal(getattr(state, field), getattr(core, field), err_msg=field)
    np.testing.assert_array_equal(EXC.pose(D), core.Q)
    np.testing.assert_array_equal(EXC.jc0(D), core.jc0)
    np.testing.assert_array_equal(EXC.k_matrix(D), core.k)
    np.testing.assert_array_equal(EXC.joint_angles(D[:, 1:]), EXC.hydraulic.solve(D).theta[:, 1:])
    family_pins = EXC.hydraulic.pins(D)
    pins = EXC.pins(D)
    assert list(pins) == list(PINS)
    for name, pin in PINS.items():
        np.testing.assert_array_equal(pins[name], family_pins[pin], err_msg=name)
    theta = core.theta
    np.testing.assert_array_equal(EXC.j0(theta), EXC.hydraulic.j0(theta))
    np.testing.assert_array_equal(EXC.open_chain_pose(theta), EXC.hydraulic.open_chain_pose(theta))


@pytest.mark.usefixtures("numpy_path")
def test_the_paper_relations_hold_on_the_numpy_path() -> None:
    """J0 K = JC0 (eq. 8), and K's diagonal (eq. 7) and K1's (its derivative) against central
    differences of the joint angles (eqs. 1-2)."""
    D = _states(200)[0]
    D[:, 1:] = np.clip(D[:, 1:], LIM.stroke_min + 1e-4, LIM.stroke_max - 1e-4)
    theta = EXC.state(D, np.zeros(4)).theta
    np.testing.assert_allclose(EXC.j0(theta) @ EXC.k_matrix(D), EXC.jc0(D), rtol=0, atol=1e-12)
    h = 1e-5
    k, k1 = EXC.k_entries(D[:, 1:])
    ahead, behind, here = (EXC.joint_angles(D[:, 1:] + s) for s in (h, -h, 0.0))
    np.testing.assert_allclose(k, (ahead - behind) / (2 * h), rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(k1, (ahead - 2 * here + behind) / (h * h), rtol=1e-4, atol=1e-3)


@pytest.mark.usefixtures("numpy_path")
def test_within_the_stroke_tolerance_beyond_an_end_is_a_state() -> None:
    """The family's own model refuses a length beyond its stroke; the excavator takes one within
    STROKE_TOLERANCE (lengths from angles at an end) and its core solves it."""
    D = LIM.reference.copy()
    D[2] = LIM.stroke_max[1] + 0.5 * STROKE_TOLERANCE
    with pytest.raises(ValueError, match="arm_cylinder"):
        EXC.hydraulic.pose(D)
    assert np.all(np.isfinite(EXC.pose(D))) and np.all(np.isfinite(EXC.state(D, np.ones(4)).jc0))
    D[2] = LIM.stroke_max[1] + 2.0 * STROKE_TOLERANCE
    with pytest.raises(StrokeError, match="arm_cylinder length"):
        EXC.pose(D)


@pytest.mark.usefixtures("numpy_path")
def test_a_continuous_swing_is_wrapped_before_the_core() -> None:
    sections = copy.deepcopy(load_parameters(config_path("excavator_cet200.yaml")))
    sections["hydraulic_machine"]["swing"].update(min_angle=-math.inf, max_angle=math.inf)
    turning = Excavator.from_parameters(sections)
    assert (turning.hydraulic.lower[0], turning.hydraulic.upper[0]) == (-math.pi, math.pi)
    D = LIM.reference.copy()
    D[0] = 3.3
    wound = turning.pose(D)
    D[0] -= 2.0 * math.pi
    np.testing.assert_allclose(wound, turning.pose(D), rtol=0, atol=1e-12)
    np.testing.assert_allclose(wound, EXC.hydraulic.solve(D).Q, rtol=0, atol=1e-12)


def test_one_states_pins_and_joint_angles_are_the_batchs_within_round_off() -> None:
    """One state takes the family kernel (pins from its monitored points, angles from its state),
    a batch the numpy core: the same machine to 1e-12, and the URDF joints made of either agree."""
    KERNEL.get(wait=True)
    rng = np.random.default_rng(7)
    lower, upper = EXC.joint_limits.lower, EXC.joint_limits.upper
    D = lower + (upper - lower) * rng.random((20, 4))
    batch_pins, batch_angles = EXC.pins(D), EXC.joint_angles(D[:, 1:])
    for i, state in enumerate(D):
        pins = EXC.pins(state)
        assert list(pins) == list(batch_pins)
        for name, p in pins.items():
            np.testing.assert_allclose(p, batch_pins[name][i], rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(EXC.joint_angles(state[1:]), batch_angles[i], rtol=0, atol=1e-12)
    single = np.array([joint_positions(EXC, state) for state in D])
    np.testing.assert_allclose(single, joint_positions(EXC, D), rtol=0, atol=1e-12)


def test_one_state_a_round_off_past_a_stroke_end_is_taken_at_the_end() -> None:
    """The excavator accepts a length STROKE_TOLERANCE past an end (the family's model does not):
    one state's pins and joint angles (the family kernel's) are those of the end, as the batch's
    (the numpy core's) are within the round-off."""
    KERNEL.get(wait=True)
    D = EXC.limits.reference.copy()
    D[1:] = EXC.limits.stroke_max + 0.5 * STROKE_TOLERANCE
    batch = EXC.pins(D[None])
    for name, p in EXC.pins(D).items():
        np.testing.assert_allclose(p, batch[name][0], rtol=0, atol=1e-8, err_msg=name)
    np.testing.assert_allclose(EXC.joint_angles(D[1:]), EXC.joint_angles(D[None, 1:])[0], rtol=0, atol=1e-8)
