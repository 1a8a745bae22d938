"""mk_asbuilt on a bag longer than its window: read in windows, the same tables and as-built grids
as the whole bag read at once, and the sweep between two windows is in the grid."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.asbuilt import AsBuilt, LowestElevation, lowest_elevation
from manipulator_kinematics.bag.asbuilt import merge_tables, process_bag
from manipulator_kinematics.bag.reader import BagReader, BagStream
from manipulator_kinematics.bag.synthetic import Topic, write_bag

RATE_HZ = 50.0
SAMPLES = 1000  # 20 s: five windows of 4 s


def sweep(n: int, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """A 1.2 m edge dragged along a curved, sloped path (site frame, UTM-sized coordinates)."""
    t = np.linspace(0.0, seconds, n)
    heading = 0.4 + 0.6 * np.sin(0.3 * t)
    mid = np.column_stack(
        [512_300.0 + 0.5 * t + 0.7 * np.sin(0.5 * t), 4_123_400.0 + 1.1 * np.cos(0.4 * t), 102.0 - 0.08 * t]
    )
    across = 0.6 * np.column_stack([-np.sin(heading), np.cos(heading), 0.1 * np.sin(t)])
    return mid + across, mid - across


def in_parts(left: np.ndarray, right: np.ndarray, cuts: list[int], cell: float) -> AsBuilt:
    run = LowestElevation(cell)
    for a, b in zip([0, *cuts], [*cuts, len(left)], strict=True):
        run.add(left[a:b], right[a:b])
    return run.result()


def assert_same_grid(a: AsBuilt, b: AsBuilt) -> None:
    assert a.z.shape == b.z.shape and (a.x0, a.y0) == pytest.approx((b.x0, b.y0), abs=1e-9)
    np.testing.assert_array_equal(np.isnan(a.z), np.isnan(b.z))
    np.testing.assert_allclose(a.z[np.isfinite(a.z)], b.z[np.isfinite(b.z)], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.hits, b.hits)


@pytest.mark.parametrize("cell", [0.1, 0.25])
def test_a_run_mapped_in_parts_is_the_run_mapped_whole(cell: float) -> None:
    left, right = sweep(3001, 30.0)
    left[1200:1210] = np.nan  # a gap in the record inside a part, and a part of nothing but gap
    cuts = [1, 700, 1200, 1210, 2999]  # a part of one sample, parts of every length
    assert_same_grid(in_parts(left, right, cuts, cell), lowest_elevation(left, right, cell))


def test_the_sweep_between_two_parts_is_in_the_grid() -> None:
    # A 1.2 m edge pushed sideways 0.5 m a sample (a 2 Hz record of a fast sweep), downhill.
    x = 0.013 + 0.5 * np.arange(21)
    left = np.column_stack([x, np.full(21, 0.637), 10.0 - 0.1 * x])
    right = np.column_stack([x, np.full(21, -0.563), 10.0 - 0.1 * x])
    cell = 0.1
    chunked = in_parts(left, right, [10], cell)
    assert_same_grid(chunked, lowest_elevation(left, right, cell))
    # What only the motion from sample 9 to sample 10 swept (densified between them):
    bridge = lowest_elevation(left[9:11], right[9:11], cell).on(chunked.x0, chunked.y0, chunked.z.shape)
    apart = AsBuilt.merge(
        [lowest_elevation(left[:10], right[:10], cell), lowest_elevation(left[10:], right[10:], cell)]
    ).on(chunked.x0, chunked.y0, chunked.z.shape)
    only_bridge = np.isfinite(bridge.z) & np.isnan(apart.z)
    assert only_bridge.sum() > 20  # the parts mapped separately leave a hole there
    assert np.all(np.isfinite(chunked.z[only_bridge]))
    np.testing.assert_allclose(chunked.z[only_bridge], bridge.z[only_bridge], atol=1e-12)


@pytest.fixture(scope="module")
def long_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("chunked") / "run"
    write_bag(path, excavator_bag(Excavator.default(), SAMPLES, RATE_HZ))
    return path


def test_the_windows_hold_every_message_with_its_margin(long_bag: Path) -> None:
    whole = BagReader(long_bag)
    stream = BagStream(long_bag)
    windows = list(stream.windows(4.0, 0.5))
    assert len(windows) == 5 and len(list(stream.windows(4.0, 0.5))) == 5  # a stream reads again
    assert windows[0].start is None and windows[-1].end is None
    for before, after in itertools.pairwise(windows):
        assert before.end == after.start  # the owned stamps partition the time line
    for window in windows:
        lo = (window.start if window.start is not None else -(2**62)) - 500_000_000
        hi = (window.end if window.end is not None else 2**62) + 500_000_000
        for topic in whole.topics:
            times = whole.log_times(topic)
            np.testing.assert_array_equal(window.log_times(topic), times[(times >= lo) & (times < hi)])


def with_a_gap(topics: dict[str, Topic], start_s: float, end_s: float) -> dict[str, Topic]:
    """``topics`` without the messages recorded from ``start_s`` to ``end_s`` after the first."""
    first = min(int(t.log_time[0]) for t in topics.values())
    out = {}
    for name, topic in topics.items():
        keep = ~((topic.log_time >= first + start_s * 1e9) & (topic.log_time < first + end_s * 1e9))
        out[name] = Topic(topic.msgtype, topic.log_time[keep], [r for r, k in zip(topic.raw, keep) if k])
    return out


@pytest.mark.slow  # two runs of the step per case, maps included: 3-11 s on the shared machine
@pytest.mark.parametrize("case", ["mcap", "sqlite3", "a gap of 7 s"])
def test_a_bag_read_in_windows_gives_the_whole_bags_table_and_surface(
    long_bag: Path, tmp_path: Path, case: str
) -> None:
    bag, samples, groups = long_bag, SAMPLES, 5
    if case == "sqlite3":  # not streamed: read whole, then cut into the same windows
        bag = tmp_path / "run"
        write_bag(bag, excavator_bag(Excavator.default(), SAMPLES, RATE_HZ), storage="sqlite3")
    if case == "a gap of 7 s":  # nothing recorded from 6 to 13 s: the window of 8 to 12 s is empty
        bag = tmp_path / "run"
        write_bag(bag, with_a_gap(excavator_bag(Excavator.default(), SAMPLES, RATE_HZ), 6.0, 13.0))
        samples, groups = SAMPLES - round(7 * RATE_HZ), 4
    whole = process_bag(bag, tmp_path / "whole", [], 0.25, chunk_seconds=None)
    parts = process_bag(bag, tmp_path / "parts", [], 0.25, chunk_seconds=4.0, chunk_margin=1.0)
    assert whole.error is None and parts.error is None
    a, b = (pq.read_table(r.tables[0]["file"]) for r in (whole, parts))
    assert pq.ParquetFile(parts.tables[0]["file"]).num_row_groups == groups  # window by window
    assert a.num_rows == b.num_rows == samples and a.schema == b.schema
    assert a.schema.metadata == b.schema.metadata
    for name in a.column_names:
        x, y = a[name].to_numpy(), b[name].to_numpy()
        if x.dtype.kind == "f":
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-12, err_msg=name)
        else:
            np.testing.assert_array_equal(y, x, err_msg=name)
    assert b["published"].to_numpy().all()  # the pose output, recorded after its input, was found
    assert whole.tables[0]["days"] == parts.tables[0]["days"]
    # The fleet's merged table, written row group by row group: the same rows with the key columns.
    assert merge_tables([parts], tmp_path / "fleet.parquet") == samples
    merged = pq.read_table(tmp_path / "fleet.parquet")
    assert set(merged["bag"].to_pylist()) == {str(bag)} and merged.select(a.column_names).equals(b)
    assert_same_grid(parts.grids["excavator"], whole.grids["excavator"])


@pytest.mark.parametrize("flag", ["--chunk-seconds=-1", "--chunk-seconds=nan", "--chunk-margin=-0.5"])
def test_bad_window_arguments_are_refused(tmp_path: Path, flag: str) -> None:
    from manipulator_kinematics.bag.asbuilt import parse_args

    with pytest.raises(SystemExit):
        parse_args([str(tmp_path), "-o", str(tmp_path / "o"), flag])
    assert (
        parse_args([str(tmp_path), "-o", str(tmp_path / "o"), "--chunk-seconds", "0"]).chunk_seconds is None
    )
