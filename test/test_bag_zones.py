"""mk_evaluate's avoidance-zone report from a recorded zone_clearance topic (no ROS): the smallest
clearance per zone with its point and time, and each transgression, against a planted sequence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.bag.evaluate import Setup, evaluate_bag, render
from manipulator_kinematics.bag.reader import BagReader, TopicArrays
from manipulator_kinematics.bag.synthetic import Topic, write_bag
from manipulator_kinematics.bag.types import decode_messages, encode_messages
from manipulator_kinematics.bag.zones import zone_report

DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
RATE = 50.0
N = 100


def planted() -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, list[str]]]:
    """Stamps (ns) and per zone its clearance and point: the ceiling is entered twice (up to 7.8 cm
    at 0.44-0.54 s, 5 mm at 1.2 s), the wall never."""
    t = np.arange(N) / RATE
    ceiling = 0.3 - 0.7 * t
    ceiling[t > 0.55] = 0.1
    ceiling[60] = -0.005
    wall = 1.0 + 0.1 * np.sin(t)
    points = {
        "power_line": ["arm_pin" if c < 0.05 else "bucket_tip" for c in ceiling],
        "road_edge": ["right_corner"] * N,
    }
    return (t * 1e9).astype(np.int64) + 1_000_000_000, {"power_line": ceiling, "road_edge": wall}, points


def messages(
    stamp: np.ndarray, clearance: dict[str, np.ndarray], points: dict[str, list[str]]
) -> list[bytes]:
    raws = []
    for k, ns in enumerate(stamp):
        values: dict[str, object] = {
            "header.stamp.sec": np.array([ns // 10**9]),
            "header.stamp.nanosec": np.array([ns % 10**9]),
            "header.frame_id": "",
        }
        for i, zone in enumerate(clearance):
            for path, value in {
                "level": np.array([0], np.uint8),
                "name": zone,
                "message": points[zone][k],
                "hardware_id": "CET200",
                "values[0].key": "clearance",
                "values[0].value": f"{clearance[zone][k]:.6g}",
                "values[1].key": "point",
                "values[1].value": points[zone][k],
            }.items():
                values[f"status[{i}].{path}"] = value
        raws += encode_messages(DIAGNOSTICS, 1, values)
    return raws


def test_zone_report_finds_the_minimum_and_every_transgression() -> None:
    stamp, clearance, points = planted()
    raws = messages(stamp, clearance, points)
    topic = TopicArrays("/zone_clearance", DIAGNOSTICS, stamp, decode_messages(DIAGNOSTICS, raws))
    report = zone_report(topic, int(stamp[0]))
    ceiling, wall = report["power_line"], report["road_edge"]
    assert ceiling["messages"] == wall["messages"] == N
    k = int(np.argmin(clearance["power_line"]))
    assert ceiling["min_clearance_m"] == pytest.approx(clearance["power_line"][k], abs=1e-6)
    assert ceiling["at_s"] == pytest.approx(k / RATE) and ceiling["point"] == "arm_pin"
    inside = np.flatnonzero(clearance["power_line"] < 0)
    assert ceiling["transgressions"] == 2 and ceiling["messages_inside"] == len(inside)
    first, second = ceiling["listed"]
    assert first["start_s"] == pytest.approx(inside[0] / RATE) and second["start_s"] == pytest.approx(1.2)
    assert first["deepest_m"] == pytest.approx(clearance["power_line"][inside[inside < 60]].min(), abs=1e-6)
    assert wall["transgressions"] == 0 and wall["min_clearance_m"] == pytest.approx(1.0, abs=1e-6)


def test_mk_evaluate_reports_the_zones_of_a_recorded_run(tmp_path: Path) -> None:
    topics = excavator_bag(Excavator.default(), N, RATE)
    stamp, clearance, points = planted()
    log_time = next(iter(topics.values())).log_time
    topics["/zone_clearance"] = Topic(DIAGNOSTICS, log_time, messages(stamp, clearance, points))
    write_bag(tmp_path / "bag", topics, overwrite=True)
    report, _ = evaluate_bag(BagReader(tmp_path / "bag"), Setup())
    (machine,) = report["machines"]
    assert machine["zones"]["power_line"]["transgressions"] == 2
    text = render(report)
    assert "avoidance zones" in text and text.count("TRANSGRESSION power_line: arm_pin") == 2
