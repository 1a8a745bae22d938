"""Bag I/O across a process (ros tier): a writer killed mid-run leaves a readable bag up to its last
flush; the in-process codec, writer and reader tests are in test_bag_io.py."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.bag.types import BagError

pytestmark = pytest.mark.ros


KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from manipulator_kinematics.bag.types import encode_messages
    from manipulator_kinematics.bag.writer import BagWriter
    path, storage = sys.argv[1], sys.argv[2]
    raws = encode_messages("sensor_msgs/msg/JointState", 300, {"header.stamp.sec": list(range(300)),
                                                             "position": [[float(i)] for i in range(300)]})
    writer = BagWriter(path, storage, flush_interval=1e9)
    writer.add_topic("/x", "sensor_msgs/msg/JointState")
    for i in range(200):
        writer.write("/x", i, raws[i])
    writer.flush()
    for i in range(200, 300):  # written but never flushed: lost with the process
        writer.write("/x", i, raws[i])
    os.kill(os.getpid(), signal.SIGKILL)
""")


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_killed_writer_leaves_everything_up_to_its_last_flush(tmp_path: Path, storage: str) -> None:
    result = subprocess.run([sys.executable, "-c", KILLED_WRITER, str(tmp_path / "bag"), storage])
    assert result.returncode == -9
    meta = (tmp_path / "bag" / "metadata.yaml").read_text()
    assert "message_count: 200" in meta and "/x" in meta
    refusal = {
        "mcap": "without its summary and footer.*--recover reads the 200 messages",
        "sqlite3": "interrupted transaction .* --recover rolls it back",
    }[storage]
    with pytest.raises(BagError, match=refusal):
        BagReader(tmp_path / "bag")
    bag = BagReader(tmp_path / "bag", recover=True)
    assert bag.recovered
    x = bag.arrays()["/x"]
    np.testing.assert_array_equal(x["position"][:, 0], np.arange(200.0))
    np.testing.assert_array_equal(x.log_time, np.arange(200))
