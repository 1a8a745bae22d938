"""`mk_evaluate` as a command (ros tier: each test runs the console script): its files, its one-line
refusals, recovery, the settings it reads from a bag; the in-process numbers are in
test_bag_evaluate.py."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_bag_evaluate import DATA, EXC, RATE, SETUP, changed, only

from excavator_kinematics.core.kinematics import CYLINDERS
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.bag.evaluate import evaluate_bag, load_setup
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.synthetic import (
    Topic,
    write_bag,
)
from manipulator_kinematics.bag.topics import SETTINGS_KEY, encode_recorded_settings
from manipulator_kinematics.bag.writer import BagWriter

pytestmark = pytest.mark.ros


def test_non_finite_cylinder_values_are_counted_per_field_not_dropped(tmp_path: Path) -> None:
    """A cylinder whose recorded values are all NaN keeps its row, with its NaN count (the fuzzer's
    bag had the boom cylinder vanish from the report); partly NaN fields are counted too."""
    topics = excavator_bag(EXC, 100, RATE)

    def spoil(f: dict[str, np.ndarray]) -> None:
        f["position"][:, 0] = np.nan  # boom length: every message
        f["velocity"][[2, 3, 4], 1] = np.inf  # arm speed: 3 messages

    topics["/cylinder_lengths"] = changed(topics["/cylinder_lengths"], spoil)
    write_bag(tmp_path / "bag", topics)
    result = evaluate_cli(str(tmp_path / "bag"), "-o", str(tmp_path / "out"), "--no-plots")
    assert result.returncode == 0, result.stderr
    actuators = json.loads((tmp_path / "out" / "report.json").read_text())["machines"][0]["actuators"]
    boom, arm, bucket = (actuators[name] for name in CYLINDERS)
    assert boom["samples"] == 100 and boom["non_finite_length"] == 100 and boom["length_max_m"] is None
    assert arm["non_finite_speed"] == 3 and arm["non_finite_length"] == 0 and arm["speed_max_mps"] is not None
    assert bucket["non_finite_length"] == bucket["non_finite_speed"] == 0
    row = next(line for line in result.stdout.splitlines() if line.startswith(CYLINDERS[0]))
    assert row.split()[-2:] == ["100", "0"], row
    assert f"{CYLINDERS[0]} length 100 of 100, {CYLINDERS[1]} speed 3 of 100" in result.stdout, result.stdout


def evaluate_cli(*args: str) -> subprocess.CompletedProcess:
    script = Path(sys.executable).parent / "mk_evaluate"
    command = (
        [str(script)] if script.exists() else [sys.executable, "-m", "manipulator_kinematics.bag.evaluate"]
    )
    return subprocess.run([*command, *args], capture_output=True, text=True, timeout=120)


def test_command_writes_table_json_and_plots(tmp_path: Path) -> None:
    result = evaluate_cli(str(DATA / "excavator_forward_golden"), "-o", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert (
        "consistency with the recomputed kinematics" in result.stdout
        and "bucket_pose position_m" in result.stdout
    )
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["messages"] == 599 and report["machines"][0]["kind"] == "excavator"
    for name in ("latency", "excavator_consistency", "excavator_cylinders"):
        assert (tmp_path / "out" / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def bad_bags(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """Bags evaluate must refuse, with the words its message must contain."""
    golden = excavator_bag(EXC, 100, RATE)
    bags: dict[str, tuple[Path, str]] = {}
    write_bag(tmp_path / "truncated", golden)
    data = tmp_path / "truncated" / "truncated.mcap"
    data.write_bytes(data.read_bytes()[:30000])
    bags["truncated"] = (tmp_path / "truncated", "--recover")
    write_bag(tmp_path / "corrupt", golden)
    data = tmp_path / "corrupt" / "corrupt.mcap"
    raw = bytearray(data.read_bytes())
    middle = len(raw) // 2
    raw[middle : middle + 400] = b"\xff" * 400  # longer than a message record: hits record headers
    data.write_bytes(bytes(raw))
    bags["corrupt"] = (tmp_path / "corrupt", "corrupt")
    with BagWriter(tmp_path / "empty") as writer:
        writer.add_topic("/cylinder_lengths", "sensor_msgs/msg/JointState")
    bags["empty"] = (tmp_path / "empty", "holds no messages")
    write_bag(tmp_path / "foreign", {"/chatter": golden["/joint_states"]})
    bags["missing topics"] = (tmp_path / "foreign", "none of the package's topics")
    write_bag(tmp_path / "wrong_type", {"/bucket_pose": golden["/bucket_twist"]})
    bags["wrong type"] = (tmp_path / "wrong_type", "has type geometry_msgs/msg/TwistStamped")
    bags["no bag"] = (tmp_path / "nothing_here", "no such bag")
    return bags


def test_bad_bags_fail_in_one_line_and_overwrite_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.json").write_text("earlier report")
    for what, (bag, words) in bad_bags(tmp_path).items():
        result = evaluate_cli(str(bag), "-o", str(out))
        assert result.returncode == 1, what
        assert result.stderr.startswith("mk_evaluate: error: "), (what, result.stderr)
        assert words in result.stderr, (what, result.stderr)
        assert "Traceback" not in result.stderr and result.stderr.count("\n") == 1, what
        assert (out / "report.json").read_text() == "earlier report" and len(list(out.iterdir())) == 1, what


def test_recover_evaluates_a_bag_without_its_summary(tmp_path: Path) -> None:
    write_bag(tmp_path / "bag", excavator_bag(EXC, 100, RATE))
    data = tmp_path / "bag" / "bag.mcap"
    data.write_bytes(data.read_bytes()[:-100])  # footer and part of the summary gone
    refused = evaluate_cli(str(tmp_path / "bag"), "--no-plots")
    assert refused.returncode == 1 and "--recover reads the 599 messages" in refused.stderr
    result = evaluate_cli(str(tmp_path / "bag"), "--no-plots", "--recover")
    assert result.returncode == 0, result.stderr
    assert "RECOVERED" in result.stdout and "599 messages" in result.stdout
    report = json.loads((tmp_path / "bag_evaluation" / "report.json").read_text())
    assert report["recovered"] and only(report, "excavator")["consistency"]["bucket_pose"]["matched"] == 100
    assert not list((tmp_path / "bag_evaluation").glob("*.png"))


def with_settings(bag: Path, settings: dict) -> Path:
    """``bag`` with node settings in its metadata's custom_data, as ``mk_record`` stores them."""
    meta = bag / "metadata.yaml"
    info = yaml.safe_load(meta.read_text(encoding="utf-8"))
    info["rosbag2_bagfile_information"]["custom_data"] = {SETTINGS_KEY: encode_recorded_settings(settings)}
    meta.write_text(yaml.safe_dump(info), encoding="utf-8")
    return bag


def test_node_settings_come_from_the_bag_else_are_named_as_assumed(tmp_path: Path) -> None:
    """Without settings in the bag the report says it assumed the package's defaults; with them
    (a filtered acceleration, as the demo runs) it uses them; ``--params`` wins over the bag."""
    result = evaluate_cli(str(DATA / "excavator_forward_golden"), "-o", str(tmp_path / "a"), "--no-plots")
    assert (
        "node settings of excavator_forward, excavator_velocity_ik: not in the bag, assumed the "
        "package's defaults"
    ) in result.stdout, result.stdout
    assert "excavator_forward.acceleration_time_constant 0," in result.stdout, result.stdout

    shutil.copytree(DATA / "excavator_forward_golden", tmp_path / "bag")
    bag = with_settings(
        tmp_path / "bag",
        {
            "/excavator_forward": {"acceleration_time_constant": 0.03, "grade": {"enabled": False}},
            "/elsewhere/excavator_forward": {"acceleration_time_constant": 7.0},  # another namespace
        },
    )
    report, _ = evaluate_bag(BagReader(bag), SETUP)
    machine = only(report, "excavator")
    assert machine["settings_sources"] == {
        "excavator_forward": "recorded in the bag",
        "excavator_velocity_ik": "not in the bag, assumed the package's defaults",
    }
    assert "acceleration_time_constant 0.03 s" in machine["consistency"]["bucket_accel"]["not_compared"]
    assert machine["settings_used"]["excavator_forward.swing_max_age"] == 0.1  # the rest from the package

    params = tmp_path / "params.yaml"
    params.write_text("/**/excavator_forward:\n  ros__parameters:\n    acceleration_time_constant: 0.0\n")
    report, _ = evaluate_bag(BagReader(bag), load_setup([params]))
    machine = only(report, "excavator")
    assert machine["settings_sources"]["excavator_forward"] == "recorded in the bag, --params"
    assert machine["consistency"]["bucket_accel"]["linear_mps2"]["max"] < 1e-12


def test_inputs_without_outputs_are_counted_and_a_shortfall_flagged(tmp_path: Path) -> None:
    """The fuzzer's bag had 1491 cylinder_lengths and 1163 bucket_pose unflagged. Outputs lost in
    the middle are missing; the first ones (before the recorder had the output topic) are not."""
    topics = excavator_bag(EXC, 100, RATE)
    pose = topics["/bucket_pose"]
    keep = np.r_[3:40, 45:100]  # 3 at the start (recording not yet there), 5 lost in the middle
    topics["/bucket_pose"] = Topic(pose.msgtype, pose.log_time[keep], [pose.raw[i] for i in keep])
    write_bag(tmp_path / "bag", topics)
    result = evaluate_cli(str(tmp_path / "bag"), "-o", str(tmp_path / "out"), "--no-plots")
    assert result.returncode == 0, result.stderr
    machine = json.loads((tmp_path / "out" / "report.json").read_text())["machines"][0]
    counts = machine["inputs_to_outputs"]
    assert counts["bucket_pose"] == {
        "recorded": 100,
        "accepted": 100,
        "due": 97,
        "answered": 92,
        "missing": 5,
        "outside_recording": 3,
    }
    assert counts["bucket_twist"]["missing"] == 0 and counts["bucket_accel"]["due"] == 99
    assert "SHORTFALL: 5 of 97 due inputs have no bucket_pose" in result.stdout, result.stdout
    assert result.stdout.count("SHORTFALL") == 1
