"""The excavator applies a machine file's zero offsets where sensor readings enter (issue 33, item 3).

true = reading + zero_offset per actuator; strokes and swing limits stay true values. A CET200 file
with offsets gives, through the nodes' boundary conversion (:meth:`Excavator.true_state` in,
:meth:`Excavator.readings` out), the pose the zero-offset file gives at reading + offset; the
family's model of the same file (which applies the offsets on its own) agrees; the bag tools read
cylinder_lengths / joint_states the same way.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from excavator_kinematics.core.geometry import StrokeError
from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.tools.scene import excavator_scene
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.bag.evaluate import Setup, evaluate_bag
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.synthetic import write_bag
from manipulator_kinematics.hydraulic import HydraulicModel, parse
from manipulator_kinematics.param_files import config_path, dump_parameters, load_parameters, parse_yaml
from manipulator_kinematics.registry import machine

#: Offsets of a measure-up: 0.5 deg on the swing, 1-2 cm on the cylinders.
OFFSETS = np.array([np.radians(0.5), 0.012, -0.018, 0.015])


def calibrated_sections(offsets: np.ndarray = OFFSETS) -> dict:
    """The shipped CET200 file's sections with ``offsets`` written as its zero offsets."""
    sections = copy.deepcopy(load_parameters(config_path("excavator_cet200.yaml")))
    g = sections["hydraulic_machine"]
    g["swing"]["zero_offset"] = float(offsets[0])
    for name, value in zip(g["actuators"], offsets[1:], strict=True):
        g["cylinders"][name]["zero_offset"] = float(value)
    return sections


@pytest.fixture(scope="module")
def models() -> tuple[Excavator, Excavator]:
    return Excavator.from_parameters(calibrated_sections()), Excavator.default()


def readings_inside(exc: Excavator, n: int, seed: int) -> np.ndarray:
    """Readings whose true states lie inside the stroke box, and so do the readings themselves
    (3 cm and 0.03 rad from every end: more than the offsets)."""
    true = np.random.default_rng(seed).uniform(exc.limits.d_min + 0.03, exc.limits.d_max - 0.03, (n, 4))
    return true - exc.zero_offset


def test_pose_of_readings_is_the_zero_offset_files_pose_at_reading_plus_offset(models) -> None:
    calibrated, zero = models
    np.testing.assert_array_equal(calibrated.zero_offset, OFFSETS)
    readings = readings_inside(calibrated, 1000, 1)
    D = calibrated.true_state(readings)
    np.testing.assert_allclose(calibrated.pose(D), zero.pose(readings + OFFSETS), rtol=0, atol=1e-12)
    # One state at a time, as the forward node converts a message.
    for r in readings[:20]:
        np.testing.assert_allclose(
            calibrated.pose(calibrated.true_state(r)), zero.pose(r + OFFSETS), atol=1e-12
        )
    # The offsets matter: the same readings on the zero-offset file are centimetres elsewhere.
    moved = np.linalg.norm(zero.pose(readings)[:, :3] - calibrated.pose(D)[:, :3], axis=1)
    assert moved.min() > 0.005, moved.min()


def test_readings_out_are_true_minus_offset_and_invert_true_state(models) -> None:
    calibrated, _ = models
    readings = readings_inside(calibrated, 200, 2)
    np.testing.assert_allclose(calibrated.readings(calibrated.true_state(readings)), readings, atol=1e-15)
    D = calibrated.true_state(readings)
    np.testing.assert_allclose(calibrated.readings(D), D - OFFSETS, atol=1e-15)


def test_the_stroke_box_is_of_true_lengths(models) -> None:
    calibrated, _ = models
    top = calibrated.limits.d_max.copy()
    top[0] = 0.0
    # The stroke end's reading is end - offset; that reading plus a millimetre is beyond the end,
    # and so is the end itself taken as a reading where the offset is positive (boom, bucket).
    calibrated.true_state(top - OFFSETS)
    with pytest.raises(StrokeError, match="bucket_cylinder"):
        calibrated.true_state(top - OFFSETS + [0, 0, 0, 0.001])
    with pytest.raises(StrokeError, match="boom_cylinder"):
        calibrated.true_state(top)
    calibrated.true_state(np.where(OFFSETS > 0, top - OFFSETS, top))  # the arm's end read as is


def test_the_familys_model_of_the_same_file_agrees(models) -> None:
    calibrated, _ = models
    family = HydraulicModel(parse(calibrated_sections()["hydraulic_machine"]))
    readings = readings_inside(calibrated, 500, 3)
    np.testing.assert_allclose(
        calibrated.pose(calibrated.true_state(readings)),
        family.pose(family.from_readings(readings)),
        rtol=0,
        atol=1e-12,
    )


def test_the_scene_draws_readings_at_their_true_state(models) -> None:
    calibrated, zero = models
    readings = readings_inside(calibrated, 50, 4)
    a, b = excavator_scene(calibrated, readings), excavator_scene(zero, readings + OFFSETS)
    for name in a.frames:
        np.testing.assert_allclose(a.frames[name], b.frames[name], atol=1e-12, err_msg=name)


@pytest.mark.slow  # 3-4 s alone (two evaluations of a bag): over 5 s on a shared machine
def test_mk_evaluate_reads_readings_of_a_calibrated_machine(models, tmp_path: Path) -> None:
    """A synthetic run of the calibrated machine (its sensors' readings on cylinder_lengths and
    joint_states, the forward node's outputs of the true states) evaluates to the round-off; read
    as the zero-offset machine the same bag is off by centimetres."""
    calibrated, zero = models
    write_bag(tmp_path / "bag", excavator_bag(calibrated, 100, 50.0))

    def position_error(model: Excavator) -> float:
        report, _ = evaluate_bag(BagReader(tmp_path / "bag"), Setup(models={"excavator": model}))
        (machine,) = [m for m in report["machines"] if m["kind"] == "excavator"]
        return machine["consistency"]["bucket_pose"]["position_m"]["max"]

    good, off = position_error(calibrated), position_error(zero)
    assert good < 1e-9 and off > 0.005, (good, off)


def test_the_registrys_monitored_points_take_readings(models) -> None:
    """machine_markers draws the zones' points of joint_states readings (registry hook)."""
    calibrated, zero = models
    readings = readings_inside(calibrated, 20, 5)
    points = machine("excavator").monitored(calibrated).positions(readings)
    np.testing.assert_allclose(points, MonitoredPoints(zero).positions(readings + OFFSETS), atol=1e-12)


def test_a_written_machine_file_quotes_what_rcl_reads_as_a_boolean() -> None:
    """mk_calibrate and mk_machine_check --convert write velocity_rows [x, y, z, alpha]: a plain y
    is a boolean to rcl, which then refuses the list; dump_parameters quotes it."""
    text = dump_parameters({"tool": {"velocity_rows": ["x", "y", "z", "alpha"], "angle": True}})
    assert '"y"' in text and "'x'" not in text and '"x"' not in text, text
    assert parse_yaml(text) == {"tool": {"velocity_rows": ["x", "y", "z", "alpha"], "angle": True}}
