"""`mk_evaluate` and `mk_replay` on damaged bags: the golden bags corrupted in a few hundred seeded ways
(bytes of the data file changed, the data file cut, metadata.yaml damaged, a record time beyond
int64) end in exit status 1 with one line on stderr, or, where the damage leaves a readable bag
(a changed number inside a message), in their normal result. Never a traceback, a numpy warning
or a hang, and the damaged files are left as they were.

Most cases run in-process (`mk_evaluate` whole, without plots; `mk_replay` up to where it would start
ROS); a few run the console scripts.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import io
import random
import shutil
import struct
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest
import yaml

from manipulator_kinematics.bag import evaluate, replay
from manipulator_kinematics.bag.cli import guarded
from manipulator_kinematics.bag.reader import BagReader

GOLDEN = sorted((Path(__file__).resolve().parent / "data").glob("*_golden"))
CASES = 300
SEED = 9_000


def read_for_replay(argv: Sequence[str]) -> int:
    replay.load(replay.parse_args(argv))
    return 0


def record_time_beyond_int64(bag: Path, rng: random.Random) -> str:
    """Set the top bit of one message's record time (the fuzzer's OverflowError)."""
    reader = BagReader(bag)
    topic = rng.choice([t for t, info in reader.topics.items() if info.count > 2])
    times = reader.log_times(topic)
    stamp = int(times[rng.randrange(1, len(times) - 1)])  # not the first or last: the chunk header has those
    data = data_file(bag)
    raw = bytearray(data.read_bytes())
    at = raw.find(struct.pack("<Q", stamp))  # the first is the message record's log_time
    raw[at + 7] |= 0x80
    data.write_bytes(bytes(raw))
    return f"record time {stamp} of a {topic} message + 2^63 at byte {at}"


def damage(bag: Path, rng: random.Random) -> tuple[str, bool]:
    """Corrupt ``bag`` in place: (what was done, whether reading it must fail)."""
    data, meta = data_file(bag), bag / "metadata.yaml"
    kind = rng.choices(["flip", "cut", "meta flip", "meta cut", "meta junk", "log time"], [8, 4, 3, 3, 1, 1])[
        0
    ]
    if kind == "log time":
        return record_time_beyond_int64(bag, rng), True
    target = meta if kind.startswith("meta") else data
    raw = bytearray(target.read_bytes())
    if kind.endswith("flip"):
        spots = sorted(rng.randrange(len(raw)) for _ in range(rng.choice([1, 1, 1, 2, 4])))
        for at in spots:
            raw[at] ^= rng.randrange(1, 256)
        what = f"{target.name}: bytes {spots} changed"
    elif kind.endswith("cut"):
        raw = raw[: rng.randrange(len(raw))]
        what = f"{target.name}: cut to {len(raw)} bytes"
    else:
        raw = bytearray(rng.randbytes(rng.randrange(1, 400)))
        what = f"{target.name}: {len(raw)} random bytes"
    target.write_bytes(bytes(raw))
    # A cut data file has no footer; random metadata names no data file: both must be refused.
    return what, kind in ("cut", "meta junk")


def data_file(bag: Path) -> Path:
    (data,) = bag.glob("*.mcap")
    return data


def contents(bag: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(bag.iterdir())}


def run_in_process(main: Callable[[Sequence[str]], int], argv: Sequence[str]) -> tuple[object, str, list]:
    """(exit status, stderr, warnings a console script would print) of ``main(argv)``."""
    err = io.StringIO()
    with (
        warnings.catch_warnings(record=True) as caught,
        contextlib.redirect_stdout(io.StringIO()),
        contextlib.redirect_stderr(err),
    ):
        warnings.simplefilter("always")
        status = main(argv)
    shown = [w for w in caught if not issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning))]
    return status, err.getvalue(), [f"{w.category.__name__}: {w.message}" for w in shown]


def check(name: str, what: str, must_fail: bool, status: object, stderr: str, shown: list) -> None:
    lines = stderr.strip().splitlines()
    assert "Traceback" not in stderr and not shown, f"{name} on {what}: {shown}\n{stderr}"
    if status == 1:
        assert len(lines) == 1 and lines[0].startswith(f"{name}: error: "), f"{name} on {what}:\n{stderr}"
    else:
        assert status == 0 and not must_fail, f"{name} on {what}: exit {status}\n{stderr}"
        assert len(lines) <= 1, f"{name} on {what}:\n{stderr}"  # evaluate names its report


@pytest.fixture(scope="module")
def config_parsed_once() -> Iterator[None]:
    """yaml.safe_load parses each text once: otherwise parsing the package's config files is most of
    an in-process evaluate. Callers get copies, so nothing they change leaks into the next case."""
    parse, parsed = yaml.safe_load, {}

    def safe_load(stream: object) -> object:
        text = stream if isinstance(stream, (str, bytes)) else stream.read()
        if text not in parsed:
            parsed[text] = parse(text)
        return copy.deepcopy(parsed[text])

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(yaml, "safe_load", safe_load)
        yield


@pytest.mark.timeout(60)
@pytest.mark.parametrize("case", range(CASES))
@pytest.mark.usefixtures("config_parsed_once")
def test_a_damaged_bag_fails_in_one_line_or_reads(case: int, tmp_path: Path) -> None:
    golden = GOLDEN[case % len(GOLDEN)]
    bag = tmp_path / golden.name
    shutil.copytree(golden, bag)
    what, must_fail = damage(bag, random.Random(SEED + case))
    before = contents(bag)
    for name, main, argv in (
        ("mk_evaluate", evaluate.main, [str(bag), "-o", str(tmp_path / "report"), "--no-plots"]),
        ("mk_replay", lambda argv: guarded("mk_replay", read_for_replay, argv), [str(bag)]),
    ):
        check(name, what, must_fail, *run_in_process(main, argv))
        assert contents(bag) == before, f"{name} changed the bag ({what})"


@pytest.mark.parametrize("where", ["absolute", "parent"])
def test_metadata_naming_a_file_outside_the_bag_is_refused(tmp_path: Path, where: str) -> None:
    """A metadata.yaml whose relative_file_paths leads out of the bag directory (absolute, or
    ``../../x``) is refused in one line naming the key, by both tools; the file it names (a
    readable bag file, so a reader that opened it would succeed) is not read."""
    outside = tmp_path / "elsewhere" / "x.mcap"
    outside.parent.mkdir()
    shutil.copyfile(data_file(GOLDEN[0]), outside)
    bag = tmp_path / "a" / "b" / "bag"
    shutil.copytree(GOLDEN[0], bag)
    data_file(bag).unlink()
    name = str(outside) if where == "absolute" else "../../../elsewhere/x.mcap"
    assert (bag / name).resolve() == outside.resolve()
    meta = bag / "metadata.yaml"
    info = yaml.safe_load(meta.read_text(encoding="utf-8"))
    info["rosbag2_bagfile_information"]["relative_file_paths"] = [name]
    meta.write_text(yaml.safe_dump(info), encoding="utf-8")
    for tool, main, argv in (
        ("mk_evaluate", evaluate.main, [str(bag), "-o", str(tmp_path / "report"), "--no-plots"]),
        ("mk_replay", lambda argv: guarded("mk_replay", read_for_replay, argv), [str(bag)]),
    ):
        status, stderr, shown = run_in_process(main, argv)
        check(tool, f"relative_file_paths {name}", True, status, stderr, shown)
        assert status == 1 and "relative_file_paths" in stderr and name in stderr, stderr
