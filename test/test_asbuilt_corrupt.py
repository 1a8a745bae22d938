"""mk_asbuilt's windowed read on damaged bags: the golden excavator bag corrupted in seeded ways
(as test_bag_corrupt.py does for mk_evaluate) gives a result or an error for that bag, never an
exception or a numpy warning, and a bag that turns out unreadable leaves no partial table."""

from __future__ import annotations

import random
import shutil
import warnings
from pathlib import Path

import pytest
from test_bag_corrupt import damage

from manipulator_kinematics.bag.asbuilt import process_bag

GOLDEN = Path(__file__).resolve().parent / "data" / "excavator_forward_golden"
SEED = 7_000


@pytest.mark.parametrize("case", range(24))
def test_a_damaged_bag_read_in_windows_is_a_result_or_an_error(case: int, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(GOLDEN, bag)
    what, must_fail = damage(bag, random.Random(SEED + case))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy warning or any other is a failure here
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        # The golden bag is 2 s: windows of 0.5 s stream it in four parts.
        result = process_bag(bag, tmp_path / "out", [], 0.25, chunk_seconds=0.5, chunk_margin=0.1)
    assert result.error or not must_fail, what
    if result.error:
        assert "\n" not in result.error
        assert not list((tmp_path / "out").rglob("*.parquet")), what
    else:
        assert result.tables and result.tables[0]["rows"] > 0, what
