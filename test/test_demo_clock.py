"""The demo's pure pieces: the cycle clock held over gaps, the graph check's missing endpoints,
and the path deviation the summary and the progress lines judge by."""

from __future__ import annotations

import numpy as np
import pytest

from excavator_kinematics.demo.bucket_path import CycleClock, path_deviation
from excavator_kinematics.demo.demo import expected_graph, missing_endpoints

MS = 1_000_000  # ns


def test_clock_follows_stamps_without_gaps() -> None:
    clock = CycleClock(max_step=0.1)
    stamps = 5_000 * MS + 20 * MS * np.arange(51)  # 50 Hz for 1 s, from an arbitrary epoch
    times = [clock.tick(int(s)) for s in stamps]
    assert times[0] == 0.0
    assert times[-1] == pytest.approx(1.0, abs=1e-12)
    assert clock.held == 0.0
    assert clock.start_ns == stamps[0] and clock.last_ns == stamps[-1]


def test_clock_holds_over_a_gap_longer_than_the_step() -> None:
    clock = CycleClock(max_step=0.1)
    clock.tick(0)
    clock.tick(20 * MS)
    # 0.7 s without an acted-on pose: the machine stood still after 0.1 s, so 0.6 s are held.
    assert clock.tick(720 * MS) == pytest.approx(0.12)
    assert clock.held == pytest.approx(0.6)
    assert clock.tick(740 * MS) == pytest.approx(0.14)


def test_clock_ignores_a_stamp_going_backwards() -> None:
    clock = CycleClock(max_step=0.1)
    clock.tick(100 * MS)
    clock.tick(160 * MS)
    assert clock.tick(120 * MS) == pytest.approx(0.06)  # older stamp: no motion
    assert clock.tick(180 * MS) == pytest.approx(0.08)  # measured from the newest stamp seen


def test_missing_endpoints_names_node_kind_and_topic() -> None:
    graph = {("publishes", "cylinder_lengths"): {"excavator_sim"}}
    expected = [
        ("excavator_sim", "publishes", "cylinder_lengths"),
        ("excavator_velocity_ik", "subscribes to", "target_bucket_twist"),
        ("bag_recorder", "subscribes to", "cylinder_lengths"),
    ]
    missing = missing_endpoints(expected, lambda kind, topic: graph.get((kind, topic), set()))
    assert missing == [
        "excavator_velocity_ik subscribes to /target_bucket_twist",
        "bag_recorder subscribes to /cylinder_lengths",
    ]


def test_expected_graph_covers_every_process_and_recorded_topic() -> None:
    expected = expected_graph()
    nodes = {name for name, _, _ in expected}
    assert nodes == {"excavator_sim", "excavator_forward", "excavator_velocity_ik", "bag_recorder"}
    published = {topic for _, kind, topic in expected if kind == "publishes"}
    subscribed = {(name, topic) for name, kind, topic in expected if kind == "subscribes to"}
    # Every topic a process needs from another process is published by one of them.
    for name, topic in subscribed:
        if name != "bag_recorder" and topic != "target_bucket_twist":  # the driver publishes that
            assert topic in published, topic


def test_path_deviation_against_a_closed_form() -> None:
    # Reference: a straight line along x at 1 m/s; points 3 cm above it, running 0.5 s late.
    t_path = np.linspace(0.0, 10.0, 1001)
    path = np.stack([t_path, np.zeros_like(t_path), np.zeros_like(t_path)], axis=-1)
    t = np.linspace(2.0, 9.0, 15)
    points = np.stack([t - 0.5, np.zeros_like(t), np.full_like(t, 0.03)], axis=-1)
    np.testing.assert_allclose(path_deviation(points, t, path, t_path), 0.03, atol=1e-12)
    # 2 s late: the search reaches back to the path sample just before t - 1 s (the segment that
    # crosses the window's edge), 0.99 m ahead of the point.
    late = points.copy()
    late[:, 0] = t - 2.0
    np.testing.assert_allclose(path_deviation(late, t, path, t_path), np.hypot(0.99, 0.03), atol=1e-9)
