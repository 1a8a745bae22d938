"""mk_asbuilt: per-sample Parquet tables (read back with DuckDB), as-built surfaces, the fleet."""

from __future__ import annotations

import json
from pathlib import Path

import duckdb
import numpy as np
import pytest

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.grade.design_surface import cutting_edge
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.asbuilt import lowest_elevation
from manipulator_kinematics.bag.asbuilt import fleet_bags, main, merge_tables, process_bag
from manipulator_kinematics.bag.synthetic import write_bag

RATE_HZ = 50.0


def make_bag(path: Path, samples: int = 150) -> Path:
    exc = Excavator.default()
    write_bag(path, excavator_bag(exc, samples, RATE_HZ))
    return path


def test_the_table_holds_every_accepted_input_with_its_kinematics(tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "run1")
    result = process_bag(bag, tmp_path / "out", [], 0.1)
    assert result.error is None and len(result.tables) == 1
    file = result.tables[0]["file"]
    # An independent reader (DuckDB's own Parquet reader, not pyarrow).
    rows = duckdb.sql(
        "select swing_joint, boom_cylinder, arm_cylinder, bucket_cylinder, tip_x, tip_y, tip_z, "
        f"alpha, left_x, left_y, left_z, right_site_z, published, stamp_ns from '{file}' order by stamp_ns"
    ).fetchnumpy()
    assert len(rows["stamp_ns"]) == 150
    assert np.all(np.diff(rows["stamp_ns"]) > 0)
    actuators = ("swing_joint", "boom_cylinder", "arm_cylinder", "bucket_cylinder")
    D = np.column_stack([rows[c] for c in actuators])
    exc = Excavator.default()
    Q = exc.pose(D)
    np.testing.assert_allclose(
        np.column_stack([rows[c] for c in ("tip_x", "tip_y", "tip_z", "alpha")]), Q, atol=1e-12
    )
    edge = cutting_edge(Q[:, :3], D[:, 0], exc.bucket_width)
    np.testing.assert_allclose(
        np.column_stack([rows[c] for c in ("left_x", "left_y", "left_z")]), edge[:, 1], atol=1e-12
    )
    # The shipped settings place base_link at the site origin: the site frame is the base frame.
    np.testing.assert_allclose(rows["right_site_z"], edge[:, 2, 2], atol=1e-12)
    assert rows["published"].all()  # the synthetic bag carries the node's bucket_pose for each
    units = json.loads(
        duckdb.sql(f"select value from parquet_kv_metadata('{file}') where key = 'units'").fetchall()[0][0]
    )
    assert units["boom_cylinder"] == "m" and units["stamp_ns"] == "ns"
    assert units["left_site_z"] == "m (site frame)"


def test_the_as_built_surface_is_the_lowest_edge_per_cell(tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "run1")
    result = process_bag(bag, tmp_path / "out", [], 0.1)
    grid = result.grids["excavator"]
    file = result.tables[0]["file"]
    cols = duckdb.sql(
        f"select left_site_x, left_site_y, left_site_z, right_site_x, right_site_y, "
        f"right_site_z from '{file}' order by stamp_ns"
    ).fetchnumpy()
    left = np.column_stack([cols[c] for c in ("left_site_x", "left_site_y", "left_site_z")])
    right = np.column_stack([cols[c] for c in ("right_site_x", "right_site_y", "right_site_z")])
    again = lowest_elevation(left, right, 0.1)
    np.testing.assert_array_equal(np.isfinite(grid.z), np.isfinite(again.z))
    np.testing.assert_allclose(grid.z[np.isfinite(grid.z)], again.z[np.isfinite(again.z)], atol=1e-12)
    # No reached cell lies below the lowest corner of the run, none above the highest.
    reached = grid.z[np.isfinite(grid.z)]
    assert reached.min() >= min(left[:, 2].min(), right[:, 2].min()) - 1e-9
    assert reached.max() <= max(left[:, 2].max(), right[:, 2].max()) + 1e-9
    for suffix in (".xml", ".csv", ".png"):
        assert (tmp_path / "out" / "run1" / f"excavator_asbuilt{suffix}").stat().st_size > 0


@pytest.mark.slow
def test_fleet_merges_tables_skips_a_corrupt_bag_and_reports_per_day(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    bags = tmp_path / "bags"
    for name in ("a", "b"):
        make_bag(bags / name, 100)
    (bags / "broken").mkdir()
    (bags / "broken" / "metadata.yaml").write_text("rosbag2_bagfile_information: [1, 2\n")
    assert [p.name for p in fleet_bags(str(bags))] == ["a", "b", "broken"]
    out = tmp_path / "out"
    assert main([f"--fleet={bags}", "-o", str(out), "--workers", "2", "--cell", "0.2"]) == 0
    err = capsys.readouterr().err
    assert "skipped" in err and "broken" in err
    report = json.loads((out / "fleet.json").read_text())
    assert report["skipped"] == 1 and report["rows"] == 200
    assert report["machines"]["excavator"] == {"rows": 200, "bags": 2}
    assert sum(d["rows"] for d in report["days"].values()) == 200
    merged = duckdb.sql(
        f"select bag, count(*) as n from '{out / 'fleet.parquet'}' group by bag order by bag"
    ).fetchall()
    assert [(Path(b).name, n) for b, n in merged] == [("a", 100), ("b", 100)]
    assert (out / "fleet_asbuilt.xml").stat().st_size > 0


def test_merge_of_no_tables_writes_nothing(tmp_path: Path) -> None:
    assert merge_tables([], tmp_path / "x.parquet") == 0
    assert not (tmp_path / "x.parquet").exists()


def test_bad_arguments_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["--fleet", str(tmp_path / "none"), "-o", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err.count("\n") == 1
    with pytest.raises(SystemExit):
        main([str(tmp_path), "-o", str(tmp_path / "o"), "--cell", "0"])


def test_the_slope_example_maps_its_cut_against_the_design(tmp_path: Path) -> None:
    from excavator_kinematics.demo.slope_example import run
    from manipulator_kinematics.bag.reader import BagReader

    run(tmp_path, seconds=2.0, rate=25.0)
    file = tmp_path / "asbuilt" / "bag" / "excavator.parquet"
    table = duckdb.sql(
        f"select stamp_ns, grade_tip, grade_left, grade_right from '{file}' order by stamp_ns"
    ).fetchnumpy()
    recorded = BagReader(tmp_path / "bag").arrays(["/grade/tip", "/grade/left", "/grade/right"])
    for point in ("tip", "left", "right"):
        grade = recorded[f"/grade/{point}"]
        assert np.array_equal(grade.stamp_ns(), table["stamp_ns"])
        # The table places the machine with the true tilt, the bag's outputs with the cab IMU's
        # estimate (noise 0.05 deg: the example's stated error, max 18 mm over 8 s).
        np.testing.assert_allclose(table[f"grade_{point}"], grade["point.z"], atol=0.03)
    for suffix in (".xml", ".csv", ".png"):
        assert (tmp_path / "asbuilt" / "bag" / f"excavator_asbuilt{suffix}").stat().st_size > 0
