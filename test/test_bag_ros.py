"""mk_record and mk_replay as real processes over DDS: golden bags replayed into the real forward nodes
of every registered machine (a machine with a forward node and no golden bag fails),
recorded bags read by an independent reader, a recorder killed with SIGKILL, topics that appear
while recording, replay timing and topic handling (relative and absolute names). Every wait is on
a condition with a timeout."""

from __future__ import annotations

import importlib.util
import struct
import subprocess
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import RELIABLE_INPUTS, NodeProcess, Probe
from sensor_msgs.msg import JointState
from std_msgs.msg import Int64

from manipulator_kinematics.bag import replay
from manipulator_kinematics.bag.evaluate import Setup, evaluate_bag
from manipulator_kinematics.bag.reader import BagReader, TopicArrays
from manipulator_kinematics.bag.synthetic import (
    GOLDEN_RATE_HZ,
    GOLDEN_SAMPLES,
    OUTPUT_DELAY,
    Topic,
    golden_name,
    stamp_fields,
    write_bag,
)
from manipulator_kinematics.bag.topics import SETTINGS_KEY, decode_recorded_settings, package_topics
from manipulator_kinematics.bag.types import BagError, decode_messages, encode_messages
from manipulator_kinematics.bag.visual import add_visuals
from manipulator_kinematics.bag.writer import BagWriter
from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.param_files import flatten, unflatten
from manipulator_kinematics.registry import Machine, machines

pytestmark = pytest.mark.ros

DATA = Path(__file__).resolve().parent / "data"
QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
TIMEOUT = 60.0
# Outputs equal to the stored ones up to rounding; a changed machine is off by millimetres.
MATCH = 1e-9
TYPES = {
    "geometry_msgs/msg/PoseStamped": PoseStamped,
    "geometry_msgs/msg/TwistStamped": TwistStamped,
    "geometry_msgs/msg/AccelStamped": AccelStamped,
    "sensor_msgs/msg/JointState": JointState,
}


@pytest.fixture
def probe() -> Iterator[Probe]:
    probe = Probe("bag_test_probe")
    yield probe
    probe.close()


def stamp_ns(msg: object) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def values(msg: object) -> np.ndarray:
    """The numbers of a received output message, in the order of :func:`expected_values`."""
    if isinstance(msg, PoseStamped):
        p, o = msg.pose.position, msg.pose.orientation
        return np.array([p.x, p.y, p.z, o.x, o.y, o.z, o.w])
    if isinstance(msg, JointState):
        return np.concatenate([msg.position, msg.velocity])
    part = msg.twist if isinstance(msg, TwistStamped) else msg.accel
    return np.array(
        [part.linear.x, part.linear.y, part.linear.z, part.angular.x, part.angular.y, part.angular.z]
    )


def expected_values(arrays: TopicArrays) -> np.ndarray:
    f = arrays.fields
    if "pose.position.x" in f:
        keys = [f"pose.position.{a}" for a in "xyz"] + [f"pose.orientation.{a}" for a in "xyzw"]
    elif "position" in f:
        return np.hstack([f["position"], f["velocity"]])
    else:
        part = "twist" if "twist.linear.x" in f else "accel"
        keys = [f"{part}.{kind}.{a}" for kind in ("linear", "angular") for a in "xyz"]
    return np.column_stack([f[k] for k in keys])


def replay_into(
    probe: Probe, node: Sequence[str], bag: Path, inputs: Sequence[str], outputs: Sequence[str]
) -> dict[str, float]:
    """Run the node, replay ``inputs`` of ``bag`` into it, and return per output topic the largest
    difference between what it published and what the bag stores for the same stamp."""
    expected = BagReader(bag).arrays(outputs)
    received: dict[str, list] = {t: [] for t in outputs}
    for topic in outputs:
        probe.node.create_subscription(TYPES[expected[topic].msgtype], topic, received[topic].append, QOS)
    with NodeProcess(*node, *RELIABLE_INPUTS) as process:
        probe.wait_until(
            lambda: all(probe.node.count_publishers(t) for t in outputs) or not process.alive(),
            TIMEOUT,
            "the node's publishers",
        )
        assert process.alive(), process.log()
        player = NodeProcess(
            "mk_replay", args=(str(bag), "--topics", *inputs, "--wait-for-subscribers", "30")
        )
        try:
            probe.wait_until(
                lambda: (
                    all(len(received[t]) >= len(expected[t]) for t in outputs)
                    or player.process.poll() not in (None, 0)
                ),
                TIMEOUT,
                "every expected output",
            )
            assert player.process.wait(TIMEOUT) == 0, player.log()
        finally:
            player.stop()
        assert "Traceback" not in process.log()
    errors = {}
    for topic in outputs:
        want = expected[topic]
        rows = {s: i for i, s in enumerate(want.stamp_ns().tolist())}
        got = {stamp_ns(m): values(m) for m in received[topic]}
        assert set(got) == set(rows), f"{topic}: stamps differ from the bag's"
        errors[topic] = max(float(np.max(np.abs(v - expected_values(want)[rows[s]]))) for s, v in got.items())
    return errors


def golden(name: str) -> Path:
    return DATA / golden_name(name)


def split_golden(bag: Path) -> tuple[list[str], list[str]]:
    """(inputs, outputs) of a golden bag: outputs are recorded OUTPUT_DELAY after their stamp
    (bag/synthetic.py), inputs at or just after it."""
    arrays = BagReader(bag).arrays()
    outputs = sorted(t for t, a in arrays.items() if np.all(a.log_time - a.stamp_ns() == OUTPUT_DELAY))
    return sorted(set(arrays) - set(outputs)), outputs


def output_differences(a: dict[str, Topic], b: dict[str, Topic]) -> dict[str, float]:
    """Per topic the largest difference of the values of equal stamps of two synthetic bags."""

    def arrays(topic: str, t: Topic) -> TopicArrays:
        return TopicArrays(topic, t.msgtype, t.log_time, decode_messages(t.msgtype, t.raw))

    out = {}
    for topic in a:
        x, y = arrays(topic, a[topic]), arrays(topic, b[topic])
        assert np.array_equal(x.stamp_ns(), y.stamp_ns()), topic
        out[topic] = float(np.max(np.abs(expected_values(x) - expected_values(y))))
    return out


def _numbers(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _changes(base: dict) -> Iterator[tuple[str, object]]:
    """(key, value) with one number of the section 2 % larger: scalars, then list items."""
    for key, value in flatten(base).items():
        if _numbers(value) and value:
            yield key, float(f"{value * 1.02:.6g}")
        elif isinstance(value, list) and value and all(_numbers(v) for v in value):
            for i, item in enumerate(value):
                if item:
                    items = [float(v) for v in value]
                    items[i] = float(f"{item * 1.02:.6g}")
                    yield key, items


def changed_value(machine: Machine) -> tuple[str, dict[str, float]]:
    """``-p`` argument changing the first number of the machine's shipped section (by 2 %) that
    leaves the golden inputs alone and moves an output by over 1 mm (or 1 mrad), and the output
    differences the numpy core predicts for it."""
    base = machine.parameters()
    reference = machine.synthesize(machine.model(), GOLDEN_SAMPLES, GOLDEN_RATE_HZ)
    inputs, _ = split_golden(golden(machine.name))
    for key, new in _changes(base):
        try:  # a value the schema or the model refuses, or a motion the changed machine cannot make
            model = machine.model_from(unflatten({**flatten(base), key: new}))
            topics = machine.synthesize(model, GOLDEN_SAMPLES, GOLDEN_RATE_HZ)
        except ValueError:
            continue
        if any(topics[t].raw != reference[t].raw for t in inputs):
            continue
        differences = output_differences(topics, reference)
        if max(differences.values()) > 1e-3:
            text = f"[{', '.join(map(repr, new))}]" if isinstance(new, list) else repr(new)
            outputs = {t: d for t, d in differences.items() if t not in inputs}
            # a key of another section the machine reads (the excavator's hydraulic_machine) is its own
            name = key if key.split(".", 1)[0] in machine.also else f"{machine.section}.{key}"
            return f"{name}:={text}", outputs
    raise AssertionError(f"{machine.name}: no number of its section changes its outputs")


FORWARD = [m for m in machines().values() if m.forward_node]


@pytest.mark.parametrize("machine", FORWARD, ids=[m.name for m in FORWARD])
def test_forward_node_reproduces_its_golden_bag(probe: Probe, machine: Machine) -> None:
    bag = golden(machine.name)
    assert bag.is_dir(), f"{machine.name}: a forward node but no golden bag (scripts/make_golden_bags.py)"
    inputs, outputs = split_golden(bag)
    assert inputs and outputs
    errors = replay_into(probe, [machine.forward_node, *machine.node_arguments], bag, inputs, outputs)
    assert max(errors.values()) < MATCH, errors


@pytest.mark.parametrize("machine", FORWARD, ids=[m.name for m in FORWARD])
def test_a_changed_machine_value_fails_the_golden_comparison(probe: Probe, machine: Machine) -> None:
    change, predicted = changed_value(machine)
    inputs, outputs = split_golden(golden(machine.name))
    node = [machine.forward_node, *machine.node_arguments, "-p", change]
    errors = replay_into(probe, node, golden(machine.name), inputs, outputs)
    # The node runs the changed machine: each output is off by what the numpy core predicts.
    assert max(errors.values()) > 1e-3, (change, errors)
    for topic in outputs:
        assert errors[topic] == pytest.approx(predicted[topic], abs=1e-9), (change, topic)


# ------------------------------------------------------------------------------------------ record


def joint_state(i: int) -> JointState:
    names = ["boom_cylinder", "arm_cylinder", "bucket_cylinder"] if i % 3 else ["swing_joint"]
    msg = JointState(
        name=names, position=[i + 0.5 * k for k in range(len(names))], velocity=[-float(i)] * len(names)
    )
    msg.header.stamp.sec, msg.header.frame_id = i, "base_link" if i % 2 else ""
    return msg


def flushed_count(bag: Path) -> int:
    try:
        return yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"][
            "message_count"
        ]
    except (OSError, TypeError, KeyError, yaml.YAMLError):
        return -1


def record_some(probe: Probe, bag: Path, topic: str, count: int, *extra: str) -> NodeProcess:
    """A recorder of ``topic`` that has stored (flushed) ``count`` messages from this probe.

    The publisher exists first and the recorder finds its type in the graph, so the recorder's
    reader matches it when created; a reader created first can be matched by the writer before it
    matches the writer, and DDS drops what is sent in between.
    """
    publisher = probe.node.create_publisher(JointState, topic, QOS)
    recorder = NodeProcess("mk_record", args=("-o", str(bag), "--topics", topic, *extra))
    probe.wait_until(
        lambda: publisher.get_subscription_count() > 0 or not recorder.alive(), TIMEOUT, "the recorder"
    )
    assert recorder.alive(), recorder.stop()
    for i in range(count):
        publisher.publish(joint_state(i))
    probe.wait_until(lambda: flushed_count(bag) == count, TIMEOUT, f"{count} messages flushed to {bag}")
    return recorder


def test_recorded_bag_reads_back_with_the_mcap_library(probe: Probe, tmp_path: Path) -> None:
    recorder = record_some(probe, tmp_path / "bag", "/record_test", 200)
    log = recorder.stop()
    assert "200 messages on 1 topics" in log, log
    with open(tmp_path / "bag" / "bag.mcap", "rb") as stream:
        decoded = [
            m
            for _, _, _, m in make_reader(
                stream, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages()
        ]
    assert len(decoded) == 200
    for i, msg in enumerate(decoded):
        sent = joint_state(i)
        assert (msg.header.stamp.sec, msg.header.frame_id, list(msg.name)) == (
            i,
            sent.header.frame_id,
            sent.name,
        )
        assert list(msg.position) == list(sent.position) and list(msg.velocity) == list(sent.velocity)
    ours = BagReader(tmp_path / "bag").arrays()["/record_test"]
    np.testing.assert_array_equal(ours["header.stamp.sec"], np.arange(200))


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_recorder_killed_with_sigkill_leaves_its_flushed_messages(
    probe: Probe, tmp_path: Path, storage: str
) -> None:
    recorder = record_some(probe, tmp_path / "bag", "/kill_test", 300, "-s", storage)
    recorder.process.kill()
    recorder.process.wait(TIMEOUT)
    recorder.stop()
    if storage == "mcap":  # no summary and footer; sqlite had committed all and has nothing to roll back
        with pytest.raises(BagError, match="--recover"):
            BagReader(tmp_path / "bag")
    arrays = BagReader(tmp_path / "bag", recover=True).arrays()["/kill_test"]
    np.testing.assert_array_equal(arrays["header.stamp.sec"], np.arange(300))
    np.testing.assert_array_equal(arrays["velocity"][:, 0], -np.arange(300.0))


def started(recorder: NodeProcess) -> bool:
    """Whether the recorder has opened its bag (its first line)."""
    return " each of " in recorder.log() or not recorder.alive()


def test_record_writes_at_once_and_adds_a_late_topic_with_its_first_message(
    probe: Probe, tmp_path: Path
) -> None:
    """Topics relative (resolved in the recorder's namespace), absolute and typed with a relative
    name; none has a publisher when the recorder starts. The bag is open before any appears; each
    is subscribed to when its publisher appears, with one line, and the publisher's first message
    (sent once the recorder's reader matched it) is in the bag."""
    bag = tmp_path / "bag"
    args = (
        "-o",
        str(bag),
        "--topics",
        "late_rel",
        "/late_abs",
        "/late/typed",
        "--type",
        "typed:=std_msgs/msg/Int64",
    )
    with NodeProcess("mk_record", "-r", "__ns:=/late", args=args) as recorder:
        probe.wait_until(lambda: started(recorder), TIMEOUT, "the recorder's first line")
        assert recorder.alive(), recorder.log()
        assert (bag / "metadata.yaml").is_file() and flushed_count(bag) == 0
        assert "recording /late" not in recorder.log()
        publishers = {
            "/late/late_rel": probe.node.create_publisher(JointState, "/late/late_rel", QOS),
            "/late_abs": probe.node.create_publisher(PoseStamped, "/late_abs", QOS),
            "/late/typed": probe.node.create_publisher(Int64, "/late/typed", QOS),
        }
        probe.wait_until(
            lambda: all(p.get_subscription_count() for p in publishers.values()) or not recorder.alive(),
            TIMEOUT,
            "the recorder's subscriptions",
        )
        publishers["/late/late_rel"].publish(joint_state(0))
        pose = PoseStamped()
        pose.header.stamp.sec = 7
        publishers["/late_abs"].publish(pose)
        publishers["/late/typed"].publish(Int64(data=42))
        probe.wait_until(lambda: flushed_count(bag) == 3 or not recorder.alive(), TIMEOUT, "3 messages")
    log = recorder.log()
    qos = "(reliable, volatile, depth 1000; 1 publishers)"
    for line in (
        f"mk_record: recording /late/late_rel [sensor_msgs/msg/JointState] {qos}",
        f"mk_record: recording /late_abs [geometry_msgs/msg/PoseStamped] {qos}",
        f"mk_record: recording /late/typed [std_msgs/msg/Int64] {qos}",
        "mk_record: 3 messages on 3 topics in ",
    ):
        assert line in log, log
    arrays = BagReader(bag).arrays()
    assert arrays["/late/late_rel"]["header.stamp.sec"].tolist() == [0]
    assert arrays["/late_abs"]["header.stamp.sec"].tolist() == [7]
    assert arrays["/late/typed"]["data"].tolist() == [42]


def test_record_discovers_types_resolves_namespaces_and_refuses_to_overwrite(
    probe: Probe, tmp_path: Path
) -> None:
    publisher = probe.node.create_publisher(PoseStamped, "/discovered", QOS)
    with NodeProcess("mk_record", args=("-o", str(tmp_path / "a"), "--topics", "/discovered")) as recorder:
        probe.wait_until(
            lambda: publisher.get_subscription_count() > 0 or not recorder.alive(), TIMEOUT, "recorder"
        )
    assert BagReader(tmp_path / "a").topics["/discovered"].msgtype == "geometry_msgs/msg/PoseStamped"

    # Default topics: every topic of the package's nodes, in the recorder's namespace; those that
    # get a publisher are recorded, the others are named at the end.
    expected = [f"/machine7/{t}" for t in package_topics()]
    published = {"/machine7/joint_states": JointState, "/machine7/tool_pose": PoseStamped}
    assert set(published) <= set(expected)
    publishers = [probe.node.create_publisher(kind, topic, QOS) for topic, kind in published.items()]
    with NodeProcess("mk_record", "-r", "__ns:=/machine7", args=("-o", str(tmp_path / "b"))) as recorder:
        probe.wait_until(
            lambda: all(p.get_subscription_count() for p in publishers) or not recorder.alive(),
            TIMEOUT,
            "recorder",
        )
    assert set(BagReader(tmp_path / "b").topics) == set(published)
    log = recorder.log()
    first = next(line for line in log.splitlines() if " each of " in line)
    assert first.endswith(f"publisher of it appears: {', '.join(expected)}"), first
    absent = ", ".join(t for t in expected if t not in published)
    assert f"mk_record: no publisher of {absent} appeared: not in the bag" in log, log

    before = sorted((p.name, p.stat().st_size) for p in (tmp_path / "a").iterdir())
    for args, words in (
        ([str(tmp_path / "a")], "exists; not overwriting"),
        ([str(tmp_path / "c"), "--topics", "bad name"], "'bad name' is not a topic name"),
        ([str(tmp_path / "c"), "--topics", "/x", "--type", "y:=std_msgs/msg/Int64"], "/y is not a recorded"),
    ):
        result = subprocess.run(
            [console_script("mk_record"), "-o", *args], capture_output=True, text=True, timeout=TIMEOUT
        )
        assert result.returncode == 1, result.stderr
        assert result.stderr.strip().splitlines()[-1].startswith("mk_record: error: "), result.stderr
        assert words in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert sorted((p.name, p.stat().st_size) for p in (tmp_path / "a").iterdir()) == before

    # A topic nobody publishes: an empty bag and a line saying so, at once and at the end.
    result = subprocess.run(
        [console_script("mk_record"), "-o", str(tmp_path / "d"), "--topics", "nobody", "--duration", "0.5"],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert result.returncode == 0, result.stderr
    assert "no publisher of /nobody appeared: not in the bag" in result.stderr, result.stderr
    assert BagReader(tmp_path / "d").topics == {}


# ------------------------------------------------------------------------------------------ replay


def numbered_bag(path: Path, topics: Sequence[str], count: int, period_ns: int) -> None:
    stamp = 10**18 + np.arange(count) * period_ns
    raws = encode_messages(
        "sensor_msgs/msg/JointState",
        count,
        {**stamp_fields(stamp), "name": ["n"], "position": np.arange(count)[:, None] * 1.0},
    )
    write_bag(path, {t: Topic("sensor_msgs/msg/JointState", stamp, raws) for t in topics})


def test_replay_keeps_timing_with_rate_offset_selection_and_remapping(probe: Probe, tmp_path: Path) -> None:
    numbered_bag(tmp_path / "bag", ["/rp_a", "/rp_b"], 40, 25_000_000)
    arrivals: dict[str, list[tuple[float, float]]] = {t: [] for t in ("/rp_out", "/rp_a", "/rp_b")}
    for topic, log in arrivals.items():
        probe.node.create_subscription(
            JointState, topic, lambda m, log=log: log.append((time.monotonic(), m.position[0])), QOS
        )
    player = NodeProcess(
        "mk_replay",
        args=(
            str(tmp_path / "bag"),
            # Bag topics with or without the leading slash; a relative target in the root namespace.
            "--topics",
            "rp_a",
            "--remap",
            "/rp_a:=rp_out",
            "--rate",
            "2",
            "--start-offset",
            "0.25",
            "--wait-for-subscribers",
            "30",
        ),
    )
    try:
        probe.wait_until(
            lambda: len(arrivals["/rp_out"]) >= 30 or player.process.poll() not in (None, 0),
            TIMEOUT,
            "30 replayed messages",
        )
        assert player.process.wait(TIMEOUT) == 0, player.log()
    finally:
        player.stop()
    times, numbers = np.array(arrivals["/rp_out"]).T
    # Messages at 0..225 ms are before the 0.25 s offset; the rest come at 12.5 ms (25 ms / 2).
    np.testing.assert_array_equal(numbers, np.arange(10, 40))
    # 29 intervals of 12.5 ms; rate 1 would take 725 ms, no timing a few ms.
    assert 0.6 * 29 * 0.0125 < times[-1] - times[0] < 1.6 * 29 * 0.0125
    assert arrivals["/rp_a"] == [] and arrivals["/rp_b"] == []


def test_replay_loops_until_stopped(probe: Probe, tmp_path: Path) -> None:
    numbered_bag(tmp_path / "bag", ["/loop"], 5, 10_000_000)
    numbers: list[float] = []
    probe.node.create_subscription(JointState, "/loop", lambda m: numbers.append(m.position[0]), QOS)
    with NodeProcess(
        "mk_replay", args=(str(tmp_path / "bag"), "--loop", "--wait-for-subscribers", "30")
    ) as player:
        probe.wait_until(lambda: len(numbers) >= 12 or not player.alive(), TIMEOUT, "three passes")
    assert numbers[:12] == [0, 1, 2, 3, 4] * 2 + [0, 1]


def flip_a_record_time(bag: Path, index: int, bit: int) -> int:
    """Flip ``bit`` of message ``index``'s record time in the bag's mcap file (the first copy of
    it: the message record's); the new record time."""
    (data,) = bag.glob("*.mcap")
    stamp = BagReader(bag).log_times(BagReader(bag).select(None)[0])[index]
    raw = bytearray(data.read_bytes())
    at = raw.find(struct.pack("<Q", int(stamp)))
    raw[at : at + 8] = struct.pack("<Q", int(stamp) ^ (1 << bit))
    data.write_bytes(bytes(raw))
    return int(stamp) ^ (1 << bit)


def test_replay_refuses_a_gap_longer_than_the_limit_or_skips_it(probe: Probe, tmp_path: Path) -> None:
    """One flipped bit of a record time (2^36 ns = 68.7 s) makes a gap: refused in one line before
    anything is published, or with --skip-gaps played across without the wait."""
    numbered_bag(tmp_path / "bag", ["/gap"], 5, 10_000_000)
    flipped = flip_a_record_time(tmp_path / "bag", 2, 36)
    times = sorted(BagReader(tmp_path / "bag").log_times("/gap").tolist())
    assert flipped in times and 68.0 < max(np.diff(times)) * 1e-9 < 69.0
    refused = subprocess.run(
        [console_script("mk_replay"), str(tmp_path / "bag")], capture_output=True, text=True, timeout=TIMEOUT
    )
    assert refused.returncode == 1, refused.stderr
    [line] = refused.stderr.splitlines()
    assert line.startswith("mk_replay: error: ") and "68.7 s of record time without a message" in line, line
    assert "--max-gap 10 s" in line and "--skip-gaps" in line, line
    numbers: list[float] = []
    probe.node.create_subscription(JointState, "/gap", lambda m: numbers.append(m.position[0]), QOS)
    # A limit above the gap plays it as recorded: what comes before it, then a wait of 68.7 s.
    with NodeProcess(
        "mk_replay", args=(str(tmp_path / "bag"), "--max-gap", "100", "--wait-for-subscribers", "30")
    ) as patient:
        probe.wait_until(lambda: len(numbers) >= 1 or not patient.alive(), TIMEOUT, "the first message")
        assert patient.alive() and len(numbers) < 5, patient.log()
    numbers.clear()
    # Skipped, the whole bag is played within TIMEOUT (60 s), less than the gap.
    with NodeProcess(
        "mk_replay", args=(str(tmp_path / "bag"), "--skip-gaps", "--wait-for-subscribers", "30")
    ) as player:
        probe.wait_until(lambda: len(numbers) == 5 or not player.alive(), TIMEOUT, "all five messages")
        probe.wait_until(lambda: not player.alive(), TIMEOUT, "the end of the replay")
    assert sorted(numbers) == [0, 1, 2, 3, 4]
    assert player.process.returncode == 0, player.log()
    [skipped] = [line for line in player.log().splitlines() if "skipping" in line]
    assert skipped.startswith("mk_replay: skipping 68.7 s of record time without a message"), skipped


def test_replay_refuses_what_it_cannot_play(tmp_path: Path) -> None:
    numbered_bag(tmp_path / "bag", ["/x"], 5, 10_000_000)
    with BagWriter(tmp_path / "empty") as writer:
        writer.add_topic("/x", "sensor_msgs/msg/JointState")
    cases = (
        ([str(tmp_path / "bag"), "--topics", "/nope"], "no topic /nope in the bag"),
        ([str(tmp_path / "bag"), "--topics", "nope"], "no topic /nope in the bag"),
        ([str(tmp_path / "bag"), "--remap", "nope:=/x"], "--remap of /nope: not in the bag"),
        ([str(tmp_path / "bag"), "--start-offset", "9"], "past the end"),
        ([str(tmp_path / "empty")], "no messages to play"),
        ([str(tmp_path / "missing")], "no such bag"),
    )
    for args, words in cases:
        result = subprocess.run(
            [console_script("mk_replay"), *args], capture_output=True, text=True, timeout=TIMEOUT
        )
        assert result.returncode == 1 and words in result.stderr and "Traceback" not in result.stderr, (
            result.stderr
        )


@pytest.mark.skipif(importlib.util.find_spec("tf2_msgs") is not None, reason="tf2_msgs is installed here")
def test_replay_refuses_a_chosen_topic_whose_type_it_cannot_publish(tmp_path: Path) -> None:
    """Skipping is for topics nobody chose: one named in --topics is an error, and so is a bag
    with nothing playable."""
    with BagWriter(tmp_path / "bag") as writer:
        writer.add_topic("/tf", "tf2_msgs/msg/TFMessage")
    for args, words in (
        (["--topics", "tf"], "cannot publish /tf [tf2_msgs/msg/TFMessage]: no Python message module"),
        ([], "no topic of the bag has a type this ROS installation can publish"),
    ):
        with pytest.raises(BagError) as error:
            replay.load(replay.parse_args([str(tmp_path / "bag"), *args]))
        assert words in str(error.value), error.value


def test_replay_takes_bag_topics_with_or_without_the_leading_slash(tmp_path: Path) -> None:
    """The README's command: bags store absolute names; ``joint_states`` means ``/joint_states``,
    and a remap target keeps its form (a relative one is resolved in the replayer's namespace)."""
    numbered_bag(tmp_path / "run1", ["/cylinder_lengths", "/joint_states", "/bucket_pose"], 5, 10_000_000)
    for args in (
        ["--topics", "cylinder_lengths", "joint_states", "--remap", "joint_states:=/m1/joint_states"],
        ["--topics", "/cylinder_lengths", "/joint_states", "--remap", "/joint_states:=/m1/joint_states"],
        ["--topics", "cylinder_lengths", "/joint_states", "--remap", "/joint_states:=/m1/joint_states"],
    ):
        playlist = replay.load(replay.parse_args([str(tmp_path / "run1"), "--rate", "2", *args]))
        assert playlist.names == {
            "/cylinder_lengths": "/cylinder_lengths",
            "/joint_states": "/m1/joint_states",
        }
        assert {topic for topic, _, _ in playlist.messages} == {"/cylinder_lengths", "/joint_states"}
    playlist = replay.load(replay.parse_args([str(tmp_path / "run1"), "--remap", "bucket_pose:=pose"]))
    assert playlist.names["/bucket_pose"] == "pose" and len(playlist.messages) == 15


def test_record_widens_a_subscription_a_later_publisher_cannot_serve(probe: Probe, tmp_path: Path) -> None:
    """A topic first seen with only a latched (reliable, transient-local) publisher is subscribed
    that way; a best-effort, volatile publisher appearing later matches no such reader. The recorder
    says so and subscribes again with a profile both match: it records the later publisher's
    messages (the demo-bag test recorded none of a replay once, with a leftover publisher)."""
    from rclpy.qos import DurabilityPolicy

    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    sensor = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
    first = probe.node.create_publisher(JointState, "/widened", latched)
    first.publish(JointState(name=["latched"], position=[0.0]))
    recorded = tmp_path / "widened"
    with NodeProcess("mk_record", args=("-o", str(recorded), "--topics", "/widened")) as recorder:
        probe.wait_until(
            lambda: "(reliable, transient local" in recorder.log() or not recorder.alive(),
            TIMEOUT,
            "the latched subscription",
        )
        later = probe.node.create_publisher(JointState, "/widened", sensor)
        probe.wait_until(
            lambda: "recording /widened now best effort, volatile" in recorder.log() or not recorder.alive(),
            TIMEOUT,
            "the widened subscription",
        )
        probe.wait_until(lambda: later.get_subscription_count() > 0, TIMEOUT, "the recorder matching")
        sent = 0

        def send_and_count() -> bool:
            nonlocal sent
            later.publish(JointState(name=["later"], position=[float(sent)]))
            sent += 1
            return recorded_count(recorded, "/widened") >= 21

        # Best effort: sent until 20 beyond the latched one are in the bag (a few may be lost).
        probe.wait_until(send_and_count, TIMEOUT, "20 messages of the later publisher recorded")
        log = recorder.log()
    assert "Traceback" not in log, log


# ------------------------------------------------------------------------- demo bag, node settings


def recorded_count(bag: Path, topic: str) -> int:
    """Messages of ``topic`` the recorder has flushed (its metadata.yaml), -1 before it is there."""
    try:
        info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    except (OSError, TypeError, KeyError, yaml.YAMLError):
        return -1
    return counts.get(topic, -1)


def recorder_matches(probe: Probe, topic: str) -> bool:
    """The recorder's subscription to ``topic`` takes volatile publishers (the replay's). The
    stand-ins' matched count alone can include a reader left over from an earlier test."""
    from rclpy.qos import DurabilityPolicy

    return any(
        info.node_name == "bag_recorder" and info.qos_profile.durability == DurabilityPolicy.VOLATILE
        for info in probe.node.get_subscriptions_info_by_topic(topic)
    )


def demo_like_bag(path: Path) -> Path:
    """The golden excavator inputs with the visual topics ``record --visuals`` adds, as the demo's
    bag has them: /tf and /tf_static (tf2_msgs, which rclpy here cannot publish), /robot_description,
    machine_markers. Made in about 2 s."""
    golden_bag = BagReader(golden("excavator"))
    chosen = ["/cylinder_lengths", "/joint_states"]
    messages = list(golden_bag.messages(chosen))
    write_bag(
        path.parent / "inputs",
        {
            topic: Topic(
                golden_bag.topics[topic].msgtype,
                np.array([t for name, t, _ in messages if name == topic]),
                [raw for name, _, raw in messages if name == topic],
            )
            for topic in chosen
        },
    )
    add_visuals(path.parent / "inputs", path)
    return path


def test_demo_bag_replays_skipping_tf_and_the_recorded_settings_reach_evaluate(
    probe: Probe, tmp_path: Path
) -> None:
    """Issue 28: ``mk_replay`` of a bag with /tf plays every other topic and names the skipped ones
    in one line; ``mk_record`` stores the forward node's settings (a filtered acceleration, as the
    demo runs it) in the bag and ``evaluate`` uses them without ``--params``."""
    demo = demo_like_bag(tmp_path / "demo")
    topics = BagReader(demo).topics
    assert topics["/tf"].msgtype == "tf2_msgs/msg/TFMessage"
    # tf2_msgs has no PyPI wheel: in the venv /tf and /tf_static are skipped; on a ROS install played.
    tf_here = importlib.util.find_spec("tf2_msgs") is not None
    playable = {t: i for t, i in topics.items() if tf_here or i.msgtype != "tf2_msgs/msg/TFMessage"}
    heard: dict[str, int] = dict.fromkeys(playable, 0)
    for topic, info in playable.items():
        qos = replay.publisher_qos(info.qos)
        probe.node.create_subscription(
            replay.message_class(info.msgtype), topic, lambda _, t=topic: heard.update({t: heard[t] + 1}), qos
        )
    last = int(BagReader(demo).arrays(["/cylinder_lengths"])["/cylinder_lengths"].stamp_ns()[-1])
    poses: list[PoseStamped] = []
    probe.node.create_subscription(PoseStamped, "/bucket_pose", poses.append, QOS)
    settings = {"/**/excavator_forward": {"ros__parameters": {"acceleration_time_constant": 0.03}}}
    recorded = tmp_path / "recorded"
    # Publishers of the inputs before the recorder: it subscribes to them at once, not when the
    # replay's publishers appear (and would then miss the first messages).
    inputs = ("/cylinder_lengths", "/joint_states")
    # With the QoS the replay will offer: the recorder subscribes with what it sees offered first
    # (a reliable stand-in for a best-effort replay recorded nothing, twice in full runs).
    stand_ins = [
        probe.node.create_publisher(JointState, topic, replay.publisher_qos(topics[topic].qos))
        for topic in inputs
    ]
    chosen = ("cylinder_lengths", "joint_states", "bucket_pose", "bucket_accel")
    with NodeProcess("excavator_forward", *RELIABLE_INPUTS, params=settings) as node:
        probe.wait_until(
            lambda: probe.node.count_publishers("/bucket_accel") > 0 or not node.alive(),
            TIMEOUT,
            "the forward node",
        )
        recorder = NodeProcess("mk_record", args=("-o", str(recorded), "--topics", *chosen))
        try:
            probe.wait_until(
                # This probe, the forward node and the recorder.
                lambda: (
                    (
                        "parameters of /excavator_forward" in recorder.log()
                        and all(p.get_subscription_count() >= 3 for p in stand_ins)
                        and all(recorder_matches(probe, topic) for topic in inputs)
                    )
                    or not recorder.alive()
                ),
                TIMEOUT,
                "the recorder's subscriptions and the forward node's settings",
            )
            player = subprocess.run(
                [console_script("mk_replay"), str(demo), "--wait-for-subscribers", "30"],
                capture_output=True,
                text=True,
                timeout=2 * TIMEOUT,
            )
            assert player.returncode == 0, player.stderr
            try:
                probe.wait_until(
                    lambda: all(heard[t] >= i.count for t, i in playable.items()),
                    TIMEOUT,
                    "every playable message",
                )
                # The replay waits for one subscriber per topic (this probe): on a loaded machine the
                # forward node may match the replayer later and miss the first inputs. Its outputs
                # come in order: the last input's pose is the last one.
                probe.wait_until(lambda: poses and stamp_ns(poses[-1]) == last, TIMEOUT, "the last pose")
                probe.wait_until(
                    lambda: recorded_count(recorded, "/bucket_pose") == len(poses),
                    TIMEOUT,
                    "the forward node's poses recorded",
                )
            except TimeoutError as error:
                counts = {t: recorded_count(recorded, t) for t in ("/cylinder_lengths", "/bucket_pose")}
                raise AssertionError(
                    f"{error}: heard {heard}, {len(poses)} poses, recorded {counts}\n"
                    f"{player.stderr}\n{recorder.log()}\n{node.log()}"
                ) from None
        finally:
            log = recorder.stop()
    skipped = [line for line in player.stderr.splitlines() if "skipping" in line]
    tf = "tf2_msgs/msg/TFMessage"
    assert (
        skipped == []
        if tf_here
        else [
            f"mk_replay: skipping /tf [{tf}], /tf_static [{tf}]: no Python message module for its type here"
        ]
    ), player.stderr
    assert f"published {sum(i.count for i in playable.values())} messages on {len(playable)} topics" in (
        player.stderr
    )
    assert heard == {t: i.count for t, i in playable.items()}, heard
    assert "stored the" in log and "Traceback" not in log, log

    bag = BagReader(recorded)
    stored = decode_recorded_settings(bag.custom_data[SETTINGS_KEY])["/excavator_forward"]
    assert stored["acceleration_time_constant"] == pytest.approx(0.03)
    assert stored["grade"]["enabled"] is False  # nested as in the params files
    report, _ = evaluate_bag(bag, Setup())
    (machine,) = report["machines"]
    # Without accepted inputs there is no consistency entry: say what the bag held instead.
    assert "consistency" in machine, (machine, {t: i.count for t, i in bag.topics.items()})
    assert machine["settings_sources"]["excavator_forward"] == "recorded in the bag"
    assert machine["settings_used"]["excavator_forward.acceleration_time_constant"] == pytest.approx(0.03)
    assert "acceleration_time_constant 0.03 s" in machine["consistency"]["bucket_accel"]["not_compared"]
    assert machine["consistency"]["bucket_pose"]["position_m"]["max"] < 1e-9
    pose = machine["inputs_to_outputs"]["bucket_pose"]
    # Every recorded pose is an answer to a recorded input (or to one the recorder had not matched).
    unmatched = machine["consistency"]["bucket_pose"]["unmatched"]
    assert pose["missing"] == 0 and pose["answered"] + unmatched == len(poses), (pose, unmatched)
