"""A measure-up of the CET200 (issue 33) writes a file the excavator nodes load (issue 31).

The calibrated file keeps the input's ``excavator`` section; the excavator's loader reads its
``hydraulic_machine`` section as the family core does (poses compared to 1e-12), zero offsets
included: both turn readings into true states (reading + offset). ``mk_calibrate --hold-offsets``
holds the cylinders' offsets at the file's values (sensors zeroed on the machine). The as-built
machine and its measurements are those of test_calibration (HydraulicModel, a tilted and
displaced instrument, 2 mm noise).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_calibration import EDGE, as_built, instrument, measure, poses, write_csv

from excavator_kinematics.core.kinematics import Excavator
from manipulator_kinematics.hydraulic import HydraulicModel, parse
from manipulator_kinematics.hydraulic.measure_up import main
from manipulator_kinematics.param_files import config_path, load_parameters

DRAWING = config_path("excavator_cet200.yaml")
pytestmark = pytest.mark.slow  # a fit each: 10 s on a shared machine


def _measured(tmp_path: Path) -> Path:
    """Tip and corners at 36 poses of a CET200 as built (pins and links 1-3 cm off the drawing),
    its cylinder sensors zeroed (true length = reading)."""
    rng = np.random.default_rng(3331)
    section, _ = as_built("CET200", rng)
    for cylinder in section["cylinders"].values():
        cylinder["zero_offset"] = 0.0
    section["swing"]["zero_offset"] = 0.0
    truth = HydraulicModel(parse(section))
    rows = measure(truth, instrument(rng), poses(truth, rng, 36), EDGE, rng, 0.002)
    return write_csv(tmp_path / "measured.csv", truth, rows)


def _calibrate(tmp_path: Path, *options: str) -> tuple[int, Path]:
    out = tmp_path / "calibrated.yaml"
    code = main(
        [
            str(DRAWING),
            str(_measured(tmp_path)),
            "-o",
            str(out),
            "--report",
            str(tmp_path / "r.json"),
            *options,
        ]
    )
    return code, out


def test_the_excavator_loads_a_calibrated_cet200_as_the_family_does(tmp_path: Path, capsys) -> None:
    code, out = _calibrate(tmp_path, "--hold-offsets")
    assert code == 0, capsys.readouterr().err
    assert "note:" not in capsys.readouterr().err  # every reader of the file loads it
    written = load_parameters(out)
    assert written["excavator"] == load_parameters(DRAWING)["excavator"]  # the extras kept
    cylinders = written["hydraulic_machine"]["cylinders"].values()
    assert all(c["zero_offset"] == 0.0 for c in cylinders)  # held

    excavator, family = Excavator.from_file(out), HydraulicModel.from_file(out)
    D = np.random.default_rng(5).uniform(excavator.limits.d_min, excavator.limits.d_max, (500, 4))
    np.testing.assert_allclose(excavator.pose(D), family.pose(D), rtol=0, atol=1e-12)
    np.testing.assert_allclose(excavator.jc0(D), family.jc0(D), rtol=0, atol=1e-12)
    # calibrated, not the drawing: the pins moved by centimetres, the tip by more than 1 cm somewhere
    moved = np.linalg.norm(excavator.pose(D)[:, :3] - Excavator.default().pose(D)[:, :3], axis=1)
    assert moved.max() > 0.01, moved.max()


def test_fitted_offsets_are_written_and_the_excavator_applies_them(tmp_path: Path, capsys) -> None:
    code, out = _calibrate(tmp_path)
    err = capsys.readouterr().err
    assert code == 0 and out.exists(), err
    assert "note:" not in err, err  # every reader of the file loads it
    excavator, family = Excavator.from_file(out), HydraulicModel.from_file(out)
    g = load_parameters(out)["hydraulic_machine"]
    written = [g["swing"]["zero_offset"], *(g["cylinders"][c]["zero_offset"] for c in g["actuators"])]
    np.testing.assert_array_equal(excavator.zero_offset, written)
    np.testing.assert_array_equal(excavator.zero_offset, family.zero_offset)
    true = np.random.default_rng(6).uniform(excavator.limits.d_min, excavator.limits.d_max, (500, 4))
    readings = true - excavator.zero_offset
    np.testing.assert_allclose(
        excavator.pose(excavator.true_state(readings)),
        family.pose(family.from_readings(readings)),
        rtol=0,
        atol=1e-12,
    )
