"""`mk_record --visuals` over DDS (ros tier); the visual topics built in-process are in
test_bag_visual.py."""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_harness import Probe
from sensor_msgs.msg import JointState
from test_bag_visual import chain, read, static_edges

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.registry import machine

pytestmark = pytest.mark.ros


def test_record_visuals_flag(tmp_path: Path) -> None:
    """``mk_record --visuals`` across processes: SCARA joint states recorded, then /tf added."""
    model = machine("scara").model()
    output = tmp_path / "recorded"
    command = [
        console_script("mk_record"),
        "-o",
        str(output),
        "--topics",
        "joint_states",
        "--type",
        "joint_states:=sensor_msgs/msg/JointState",
        "--visuals",
    ]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    probe = Probe("record_visuals_probe")
    try:
        pub = probe.node.create_publisher(
            JointState, "joint_states", QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        )
        probe.wait_until(
            lambda: pub.get_subscription_count() > 0 or process.poll() is not None,
            30.0,
            "the recorder's subscription",
        )
        assert process.poll() is None
        lo, hi = np.asarray(model.limits.lower), np.asarray(model.limits.upper)
        states = lo + (hi - lo) * np.linspace(0.1, 0.9, 20)[:, None]
        for k, q in enumerate(states):
            msg = JointState(name=list(model.joint_names), position=q.tolist())
            msg.header.stamp.sec, msg.header.stamp.nanosec = 100 + k, 0
            pub.publish(msg)

        def stored() -> bool:  # metadata.yaml is rewritten on every flush (0.5 s)
            meta = output / "metadata.yaml"
            return meta.is_file() and (yaml.safe_load(meta.read_text()) or {}).get(
                "rosbag2_bagfile_information", {}
            ).get("message_count", 0) >= len(states)

        probe.wait_until(stored, 30.0, "the recorder to store every message")
    finally:
        probe.close()
        process.send_signal(signal.SIGINT)
        log, _ = process.communicate(timeout=60)
    assert process.returncode == 0, log
    assert "added /tf" in log, log
    msgs = read(output, ["/tf", "/tf_static"])
    static = static_edges(msgs["/tf_static"])
    assert len(msgs["/tf"]) == len(states)
    for k, m in enumerate(msgs["/tf"]):
        np.testing.assert_allclose(chain(m, static, "tool"), model.fkine(states[k]), atol=1e-9)
