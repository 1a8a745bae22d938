"""The console scripts on damaged bags, as processes (ros tier: each test starts mk_evaluate or
mk_replay); the damage itself and the in-process checks are in test_bag_corrupt.py."""

from __future__ import annotations

import random
import shutil
import subprocess
from pathlib import Path

import pytest
from test_bag_corrupt import GOLDEN, SEED, check, contents, data_file, record_time_beyond_int64

from manipulator_kinematics.node_util import console_script

pytestmark = pytest.mark.ros


def test_console_scripts_fail_in_one_line_on_damaged_bags(tmp_path: Path) -> None:
    rng = random.Random(SEED)
    bags = {}
    for kind in ("cut", "log time", "metadata"):
        bag = tmp_path / kind.replace(" ", "_") / GOLDEN[0].name
        shutil.copytree(GOLDEN[0], bag)
        if kind == "cut":
            data = data_file(bag)
            data.write_bytes(data.read_bytes()[: data.stat().st_size * 6 // 10])
        elif kind == "log time":
            record_time_beyond_int64(bag, rng)
        else:
            (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {relative_file_paths: 7}\n")
        bags[kind] = (bag, contents(bag))
    runs = {
        (kind, name): subprocess.Popen(
            [console_script(name), str(bag), *(["-o", str(bag.parent / "report")] * (name == "mk_evaluate"))],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for kind, (bag, _) in bags.items()
        for name in ("mk_evaluate", "mk_replay")
    }
    for (kind, name), process in runs.items():
        _, stderr = process.communicate(timeout=120)
        check(name, kind, True, process.returncode, stderr, [])
        assert contents(bags[kind][0]) == bags[kind][1]
        assert not (bags[kind][0].parent / "report").exists()
