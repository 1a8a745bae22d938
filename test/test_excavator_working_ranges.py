"""Working ranges of the CET200: optima against a dense grid and against hand checks."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from excavator_kinematics.tools.working_ranges import QUANTITIES, WorkingRanges, main
from manipulator_kinematics.registry import machine


@pytest.fixture(scope="module")
def ranges() -> WorkingRanges:
    excavator = machine("excavator")
    return WorkingRanges(excavator.model(), excavator.parameters()["base_height"])


@pytest.fixture(scope="module")
def table(ranges: WorkingRanges) -> dict:
    return ranges.table()


@pytest.mark.slow
def test_no_sample_of_a_dense_grid_beats_an_optimum(ranges: WorkingRanges, table: dict) -> None:
    dense = WorkingRanges(ranges.model, ranges.base_height, grid=81)  # 531 441 states, another grid
    for key in ranges.problems():
        best = table[key]["optimum"].value
        sampled = dense.sampled(key).value
        if key == "min_front_swing_radius":
            assert best <= sampled + 1e-9, key
        else:
            assert best >= sampled - 1e-9, key
        assert abs(best - sampled) < 0.01, key  # and the grid comes close: the optimum is the global one


def test_hand_checks(ranges: WorkingRanges, table: dict) -> None:
    """Closed-form positions of the stretched / vertical links (docs/visualisation.md)."""
    exc = ranges.model
    lo, hi = exc.limits.stroke_min, exc.limits.stroke_max
    t2_min, t2_max = exc.joint_angles(lo)[0], exc.joint_angles(hi)[0]
    t3_out = exc.joint_angles(lo)[1]  # arm cylinder retracted: arm stretched out
    # Boom foot -> bucket pin with the arm stretched, then the bucket in line with it.
    rho = abs(exc.l2 + exc.l3 * complex(math.cos(t3_out), math.sin(t3_out)))
    assert table["max_digging_reach"]["optimum"].value == pytest.approx(exc.l1 + rho + exc.l4, abs=1e-7)
    radius = rho + exc.l4
    ground = math.sqrt(radius**2 - exc.l0**2)
    assert table["max_reach_at_ground"]["optimum"].value == pytest.approx(exc.l1 + ground, abs=1e-7)
    # Boom at its lowest, arm and bucket pointing straight down.
    depth = exc.l3 + exc.l4 - exc.l0 - exc.l2 * math.sin(t2_min) - ranges.base_height
    assert table["max_digging_depth"]["optimum"].value == pytest.approx(depth, abs=1e-7)
    assert table["max_vertical_wall_depth"]["optimum"].value == pytest.approx(depth, abs=1e-7)
    # Boom up, arm out: the bucket pin's highest point; dumped, the teeth hang l4 below it.
    pin = exc.l0 + exc.l2 * math.sin(t2_max) + exc.l3 * math.sin(t2_max + t3_out)
    assert table["bucket_pin_height"]["optimum"].value == pytest.approx(pin, abs=1e-7)
    assert table["max_dumping_height"]["optimum"].value == pytest.approx(pin - exc.l4, abs=1e-7)
    # Cutting height: a corner of the stroke box (boom up, arm out, bucket open).
    t = exc.joint_angles([hi[0], lo[1], lo[2]])
    cut = exc.l0 + exc.l2 * math.sin(t[0]) + exc.l3 * math.sin(t[0] + t[1]) + exc.l4 * math.sin(t.sum())
    assert table["max_cutting_height"]["optimum"].value == pytest.approx(cut, abs=1e-9)


def test_states_attain_their_values(ranges: WorkingRanges, table: dict) -> None:
    for key in QUANTITIES:
        best = table[key]["optimum"]
        assert np.all(best.state[1:] >= ranges.lo - 1e-12) and np.all(best.state[1:] <= ranges.hi + 1e-12)
        objective, equality = ranges.problems()[key]
        value = float(objective(best.state[1:]))
        assert (-value if key == "min_front_swing_radius" else value) == pytest.approx(best.value, abs=1e-12)
        if equality is not None:
            assert abs(float(equality(best.state[1:]))) < 1e-9


def test_ground_moves_with_base_height(ranges: WorkingRanges, table: dict) -> None:
    raised = WorkingRanges(ranges.model, ranges.base_height + 0.5)
    assert raised.optimum("max_cutting_height").value == pytest.approx(
        table["max_cutting_height"]["optimum"].value + 0.5, abs=1e-9
    )
    assert raised.optimum("max_digging_depth").value == pytest.approx(
        table["max_digging_depth"]["optimum"].value - 0.5, abs=1e-9
    )


def test_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ranges.json"
    assert main(["--json", str(out), "--plot", str(tmp_path / "ranges.png")]) == 0
    data = json.loads(out.read_text())
    assert list(data) == list(QUANTITIES)
    for entry in data.values():
        assert set(entry["state"]) == {"swing_joint", "boom_cylinder", "arm_cylinder", "bucket_cylinder"}
        assert entry["value"] > 0
    assert "max digging reach" in capsys.readouterr().out
    assert (tmp_path / "ranges.png").stat().st_size > 10_000
    assert main(["--params-file", str(tmp_path / "missing.yaml")]) == 2
