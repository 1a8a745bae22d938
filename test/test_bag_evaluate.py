"""`mk_evaluate` without ROS: reported numbers against errors planted in otherwise exact bags, every
registered machine found in its own synthetic bag (and no other), and readable failures
(non-zero exit, one line, nothing overwritten) for bags and parameter files it cannot use."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml

from excavator_kinematics.core.kinematics import CYLINDERS, Excavator
from excavator_kinematics.tools.synthetic import excavator_bag
from manipulator_kinematics.bag.evaluate import Setup, evaluate_bag, load_setup
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.synthetic import (
    GOLDEN_RATE_HZ,
    GOLDEN_SAMPLES,
    OUTPUT_DELAY,
    Topic,
    golden_name,
    serial_bag,
    write_bag,
)
from manipulator_kinematics.bag.types import BagError, decode_messages, encode_messages
from manipulator_kinematics.param_files import config_path
from manipulator_kinematics.planar import yaw_quaternion
from manipulator_kinematics.registry import Machine, machines
from scara_kinematics.kinematics import Scara

DATA = Path(__file__).resolve().parent / "data"
EXC = Excavator.default()
SETUP = Setup()
SYNTHESIZED = [m for m in machines().values() if m.synthesize is not None]
RATE = 50.0


def changed(topic: Topic, change: Callable[[dict[str, np.ndarray]], None]) -> Topic:
    """``topic`` with its messages decoded, changed in place by ``change`` and encoded again."""
    fields = {path: np.array(values) for path, values in decode_messages(topic.msgtype, topic.raw).items()}
    change(fields)
    values = {
        path: (v[0] if v.ndim == 1 else list(v[0])) if v.dtype.kind == "U" else v
        for path, v in fields.items()
    }
    return Topic(topic.msgtype, topic.log_time, encode_messages(topic.msgtype, len(topic.raw), values))


def evaluated(tmp_path: Path, topics: dict[str, Topic]) -> dict:
    write_bag(tmp_path / "bag", topics, overwrite=True)
    report, _ = evaluate_bag(BagReader(tmp_path / "bag"), SETUP)
    return report


def only(report: dict, kind: str) -> dict:
    (machine,) = [m for m in report["machines"] if m["kind"] == kind]
    return machine


def test_golden_bags_are_consistent_to_rounding() -> None:
    report, plots = evaluate_bag(BagReader(DATA / "excavator_forward_golden"), SETUP)
    consistency = only(report, "excavator")["consistency"]
    assert {t: c["matched"] for t, c in consistency.items()} == {
        "bucket_pose": 100,
        "bucket_twist": 100,
        "bucket_accel": 99,
        "open_chain_joint_states": 100,
    }
    for entry in consistency.values():
        assert entry["unmatched"] == 0
        for stats in (v for v in entry.values() if isinstance(v, dict)):
            assert stats["max"] < 1e-12
    assert {p.name for p in plots} >= {"latency", "excavator_consistency", "excavator_cylinders"}


@pytest.mark.parametrize("machine", SYNTHESIZED, ids=[m.name for m in SYNTHESIZED])
def test_each_machine_is_found_alone_in_its_golden_bag(machine: Machine) -> None:
    """The golden bag is what scripts/make_golden_bags.py writes today (up to rounding), and
    evaluate finds this machine in it, no other, with outputs consistent to rounding."""
    bag = BagReader(DATA / golden_name(machine.name))
    fresh = machine.synthesize(machine.model(), GOLDEN_SAMPLES, GOLDEN_RATE_HZ)
    stored = bag.arrays()
    assert set(stored) == set(fresh)
    for topic, arrays in stored.items():
        values = decode_messages(fresh[topic].msgtype, fresh[topic].raw)
        for path, column in arrays.fields.items():
            if column.dtype.kind == "f":
                np.testing.assert_allclose(column, values[path], atol=1e-12, err_msg=f"{topic} {path}")
    report, _ = evaluate_bag(bag, SETUP)
    (found,) = report["machines"]
    assert found["kind"] == machine.name
    assert found["consistency"]
    for entry in found["consistency"].values():
        assert entry["matched"] >= GOLDEN_SAMPLES - 1  # the excavator's first acceleration is unknown
        assert entry["unmatched"] == 0
        for stats in (v for v in entry.values() if isinstance(v, dict)):
            assert stats["max"] < 1e-12


def test_the_scara_golden_bag_holds_the_closed_form_kinematics() -> None:
    """The generic serial bag against the SCARA's own closed form (paper 002), not fkine/jacob0."""
    arm = Scara.default()
    arrays = BagReader(DATA / "scara_forward_golden").arrays()
    js, pose, twist = (arrays[t] for t in ("/joint_states", "/tool_pose", "/tool_twist"))
    q, qd = js.by_name("position", arm.joint_names), js.by_name("velocity", arm.joint_names)
    x, xd = arm.fk(q), arm.velocity_fk(q, qd)
    np.testing.assert_allclose(pose["pose.position.x"], x[:, 0], atol=1e-12)
    np.testing.assert_allclose(pose["pose.position.y"], x[:, 1], atol=1e-12)
    np.testing.assert_allclose(pose["pose.position.z"], 0.0, atol=1e-12)
    quaternion = np.stack([pose[f"pose.orientation.{a}"] for a in "xyzw"], axis=-1)
    expected = yaw_quaternion(x[:, 2]) * np.sign(yaw_quaternion(x[:, 2])[:, 3:])  # same sign as w >= 0
    np.testing.assert_allclose(quaternion, expected, atol=1e-12)
    np.testing.assert_allclose(twist["twist.linear.x"], xd[:, 0], atol=1e-12)
    np.testing.assert_allclose(twist["twist.linear.y"], xd[:, 1], atol=1e-12)
    np.testing.assert_allclose(twist["twist.angular.z"], xd[:, 2], atol=1e-12)
    # Inside the limits, and every joint travels over a tenth of its range.
    assert arm.within_limits(q).all()
    assert np.all(np.ptp(q, axis=0) > 0.1 * (arm.limits.upper - arm.limits.lower))


def test_planted_pose_errors_are_reported_exactly(tmp_path: Path) -> None:
    topics = excavator_bag(EXC, 100, RATE)

    def shift_and_turn(f: dict[str, np.ndarray]) -> None:
        f["pose.position.x"][10:20] += 1e-3  # 10 of 100 messages 1 mm off
        # Message 50 turned by 0.02 rad about z: q' = q * (0, 0, sin 0.01, cos 0.01).
        x, y, z, w = (f[f"pose.orientation.{a}"][50] for a in "xyzw")
        s, c = np.sin(0.01), np.cos(0.01)
        for a, v in zip("xyzw", (x * c + y * s, y * c - x * s, z * c + w * s, w * c - z * s)):
            f[f"pose.orientation.{a}"][50] = v

    topics["/bucket_pose"] = changed(topics["/bucket_pose"], shift_and_turn)
    pose = only(evaluated(tmp_path, topics), "excavator")["consistency"]["bucket_pose"]
    assert pose["position_m"]["max"] == pytest.approx(1e-3, abs=1e-12)
    assert pose["position_m"]["rms"] == pytest.approx(1e-3 * np.sqrt(10 / 100), abs=1e-12)
    assert pose["orientation_rad"]["max"] == pytest.approx(0.02, abs=1e-10)
    assert pose["orientation_rad"]["rms"] == pytest.approx(0.02 / np.sqrt(100), abs=1e-10)


def test_tracking_error_of_a_planted_command_offset(tmp_path: Path) -> None:
    topics = excavator_bag(EXC, 100, RATE, target_every=1, target_lead=0.0)
    exact = only(evaluated(tmp_path, topics), "excavator")["tracking"]
    assert exact["matched"] == 100 and exact["linear_mps"]["max"] < 1e-12

    def offset(f: dict[str, np.ndarray]) -> None:
        f["twist.linear.x"][:50] += 0.02
        f["twist.angular.z"][:] -= 0.1

    topics["/target_bucket_twist"] = changed(topics["/target_bucket_twist"], offset)
    tracking = only(evaluated(tmp_path, topics), "excavator")["tracking"]
    assert tracking["linear_mps"]["max"] == pytest.approx(0.02, abs=1e-12)
    assert tracking["linear_mps"]["rms"] == pytest.approx(0.02 * np.sqrt(0.5), abs=1e-12)
    assert tracking["angular_radps"]["rms"] == pytest.approx(0.1, abs=1e-12)


def test_rates_gaps_and_latency_of_topics(tmp_path: Path) -> None:
    topics = excavator_bag(EXC, 100, RATE)
    keep = np.r_[0:50, 55:100]  # 5 cylinder messages lost: one gap of 6 periods
    cyl = topics["/cylinder_lengths"]
    topics["/cylinder_lengths"] = Topic(cyl.msgtype, cyl.log_time[keep], [cyl.raw[i] for i in keep])
    report = evaluated(tmp_path, topics)
    stats = report["topics"]["/cylinder_lengths"]
    assert stats["count"] == 95 and stats["gaps"] == 1
    assert stats["gap_max_s"] == pytest.approx(6 / RATE)
    assert report["topics"]["/bucket_pose"]["rate_hz"] == pytest.approx(RATE)
    assert report["topics"]["/bucket_pose"]["latency_s"]["median"] == pytest.approx(OUTPUT_DELAY * 1e-9)
    # Outputs of the lost inputs have nothing to be compared with.
    assert only(report, "excavator")["consistency"]["bucket_pose"]["unmatched"] == 5


def test_cylinder_speed_and_stroke_statistics(tmp_path: Path) -> None:
    topics = excavator_bag(EXC, 100, RATE)
    lim = EXC.limits

    def abuse(f: dict[str, np.ndarray]) -> None:
        f["velocity"][[3, 4, 5], 0] = 1.5 * lim.max_cylinder_speed[0]  # boom over speed 3 times
        f["position"][[7, 8], 2] = lim.stroke_max[2] + 0.01  # bucket beyond its stroke twice

    topics["/cylinder_lengths"] = changed(topics["/cylinder_lengths"], abuse)
    lengths = decode_messages(topics["/cylinder_lengths"].msgtype, topics["/cylinder_lengths"].raw)[
        "position"
    ]
    machine = only(evaluated(tmp_path, topics), "excavator")
    boom, bucket = (machine["actuators"][name] for name in (CYLINDERS[0], CYLINDERS[2]))
    assert boom["over_speed"] == 3 and boom["speed_max_mps"] == pytest.approx(1.5 * lim.max_cylinder_speed[0])
    assert bucket["beyond_end"] == 2 and bucket["length_max_m"] == pytest.approx(lim.stroke_max[2] + 0.01)
    used = (lengths[:, 0].max() - lengths[:, 0].min()) / (lim.stroke_max[0] - lim.stroke_min[0])
    assert boom["stroke_used"] == pytest.approx(used)
    # The node rejects states beyond a stroke end; so does the recomputation.
    assert machine["accepted_inputs"] == 98


def test_machines_are_found_per_namespace(tmp_path: Path) -> None:
    named = {f"/site/exc1{t}": v for t, v in excavator_bag(EXC, 60, RATE).items()}
    named |= {f"/arm{t}": v for t, v in serial_bag(Scara.default(), 60, RATE).items()}
    # Joint states alone are enough to find a serial machine (its joint names).
    changer = SETUP.model(machines()["tool_changer"])
    named |= {"/cell/joint_states": serial_bag(changer, 60, RATE)["/joint_states"]}
    report, plots = evaluate_bag(BagReader(write_bag_at(tmp_path, named)), SETUP)
    assert [(m["kind"], m["namespace"]) for m in report["machines"]] == [
        ("scara", "/arm"),
        ("tool_changer", "/cell"),
        ("excavator", "/site/exc1"),
    ]
    assert only(report, "excavator")["consistency"]["bucket_pose"]["position_m"]["max"] < 1e-12
    assert only(report, "scara")["consistency"]["tool_pose"]["matched"] == 60
    assert only(report, "tool_changer")["joint_states"] == 60
    assert {"arm_scara_consistency", "site_exc1_excavator_consistency"} <= {p.name for p in plots}


def write_bag_at(tmp_path: Path, topics: dict[str, Topic]) -> Path:
    write_bag(tmp_path / "bag", topics, overwrite=True)
    return tmp_path / "bag"


def test_planted_serial_errors_are_reported_exactly(tmp_path: Path) -> None:
    arm = Scara.default()
    topics = serial_bag(arm, 100, RATE)

    def shift(f: dict[str, np.ndarray]) -> None:
        f["pose.position.z"][:25] += 2e-3  # a quarter of the poses 2 mm high

    def spin(f: dict[str, np.ndarray]) -> None:
        f["twist.angular.x"][7] += 0.3  # one twist with a roll rate the arm cannot have

    topics["/tool_pose"] = changed(topics["/tool_pose"], shift)
    topics["/tool_twist"] = changed(topics["/tool_twist"], spin)
    machine = only(evaluated(tmp_path, topics), "scara")
    pose, twist = machine["consistency"]["tool_pose"], machine["consistency"]["tool_twist"]
    assert pose["position_m"]["max"] == pytest.approx(2e-3, abs=1e-12)
    assert pose["position_m"]["rms"] == pytest.approx(2e-3 * np.sqrt(0.25), abs=1e-12)
    assert pose["orientation_rad"]["max"] < 1e-12 and twist["linear_mps"]["max"] < 1e-12
    assert twist["angular_radps"]["max"] == pytest.approx(0.3, abs=1e-12)
    assert twist["angular_radps"]["rms"] == pytest.approx(0.3 / 10, abs=1e-12)
    assert machine["outside_limits"] == 0


# ------------------------------------------------------------------------------------------ command line


def test_params_files_set_the_machine_and_the_node_settings(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(
        "/**:\n  ros__parameters:\n    hydraulic_machine:\n      bodies:\n        bucket:\n          pins:\n"
        "            tip: [1.36, 0.0]\n"
        "/**/excavator_forward:\n  ros__parameters:\n    acceleration_time_constant: 0.03\n"
    )
    base = yaml.safe_load(config_path("excavator_cet200.yaml").read_text())["/**"]["ros__parameters"]
    full = tmp_path / "machine.yaml"
    full.write_text(yaml.safe_dump({"/**": {"ros__parameters": base}}))
    setup = load_setup([full, params])
    assert setup.node_settings["excavator_forward"]["acceleration_time_constant"] == 0.03
    assert setup.node_settings["excavator_forward"]["swing_max_age"] == 0.1  # from the package's config
    report, _ = evaluate_bag(BagReader(DATA / "excavator_forward_golden"), setup)
    consistency = only(report, "excavator")["consistency"]
    # The golden outputs are for the 1.309 m bucket: 51 mm longer moves the tip by centimetres.
    assert consistency["bucket_pose"]["position_m"]["max"] > 0.01
    assert "acceleration_time_constant 0.03" in consistency["bucket_accel"]["not_compared"]


def test_a_serial_machine_from_params_changes_the_numbers(tmp_path: Path) -> None:
    base = yaml.safe_load(config_path("scara.yaml").read_text())["/**"]["ros__parameters"]
    base["scara"]["l3"] = 0.26  # forearm 1 cm longer: the tool point moves by up to 1 cm
    path = tmp_path / "scara.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": base}}))
    report, _ = evaluate_bag(BagReader(DATA / "scara_forward_golden"), load_setup([path]))
    position = only(report, "scara")["consistency"]["tool_pose"]["position_m"]
    assert position["max"] == pytest.approx(0.01, abs=1e-12)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("/**:\n  ros__parameters:\n    scara:\n      l1: 0.2\n", "scara.l2"),  # incomplete
        ("/**:\n  ros__parameters:\n    scarra:\n      l1: 0.2\n", "did you mean 'scara'"),
    ],
)
def test_params_files_with_a_bad_machine_section_are_refused(tmp_path: Path, text: str, words: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(BagError, match="--params") as error:
        load_setup([path])
    assert words in str(error.value)
