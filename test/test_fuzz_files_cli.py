"""Fuzzed file inputs given to the console scripts (ros tier: each test starts a process): one line
naming the key, never a traceback; the in-process fuzz is in test_fuzz_files.py."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from ros_harness import IK_FK, start_with_services
from sensor_msgs.msg import JointState
from test_fuzz_files import (
    HERE,
    YAML_SEEDS,
    cases,
)

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK
from pump_boom_kinematics.kinematics import PumpBoom

pytestmark = pytest.mark.ros


# ------------------------------------------------------------------- the console scripts, one line
def one_line(command: list[str], code: int = 2) -> str:
    """stderr of ``command``, which must exit ``code`` with one line on it."""
    result = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert result.returncode == code, (command, result.returncode, result.stderr[-2000:])
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr, result.stderr[-2000:]
    return result.stderr


@pytest.mark.parametrize(
    "seed",
    [
        "missing",
        "directory",
        "tabs",
        "not_utf8",
        "python_tag",
        "deep_nesting",
        "alias_bomb",
        "fifo",
        "dev_zero",
    ],
)
def test_mk_urdf_refuses_a_bad_params_file_in_one_line(tmp_path: Path, seed: str) -> None:
    path = next(p for name, p in cases({seed: YAML_SEEDS[seed]}, b"", tmp_path, 0) if name == seed)
    assert str(path) in one_line([console_script("mk_urdf"), "scara", "--params-file", str(path)])


@pytest.mark.parametrize("seed", ["deep_nesting", "alias_bomb"])
def test_mk_evaluate_refuses_a_bad_params_file_in_one_line(tmp_path: Path, seed: str) -> None:
    path = tmp_path / "params.yaml"
    path.write_bytes(YAML_SEEDS[seed])
    line = one_line(
        [
            console_script("mk_evaluate"),
            str(HERE / "data" / "scara_forward_golden"),
            "--params",
            str(path),
            "--output",
            str(tmp_path / "out"),
        ],
        code=1,
    )
    assert str(path) in line, line


@pytest.mark.parametrize("seed", ["fifo", "alias_bomb", "dev_zero"])
def test_a_node_refuses_a_bad_params_file_in_one_line(tmp_path: Path, seed: str) -> None:
    path = next(p for name, p in cases({seed: YAML_SEEDS[seed]}, b"", tmp_path, 0) if name == seed)
    assert str(path) in one_line([console_script("scara_forward"), "--ros-args", "--params-file", str(path)])


def test_pump_boom_regions_lists_a_table_that_is_not_yaml_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "table.yaml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n not a table")
    line = one_line([console_script("pump_boom_regions"), "--list", "--output", str(path)])
    assert f"{path}: not UTF-8 text (byte 0)" in line, line


def test_pump_boom_ik_server_given_a_table_that_is_not_yaml_serves_fk(tmp_path: Path, probe) -> None:
    """The table is read at start-up: a warning naming the file and its reason, no traceback; FK
    serves, IK answers failure with that reason (kinematics.PumpBoom.table)."""
    table = tmp_path / "table.yaml"
    table.write_bytes(b"\x89PNG\r\n\x1a\n not a table")
    process, (ik, fk) = start_with_services(
        probe,
        "pump_boom_ik_server",
        "-p",
        f"pump_boom.regions.table_file:={table}",
        services=IK_FK,
        timeout=20.0,
    )
    try:
        request = SolveIK.Request()
        request.target.pose.position.x, request.target.pose.position.z = 20.0, 17.5
        answer = probe.call(ik, request, 20.0)
        assert not answer.success and f"{table}: not UTF-8 text (byte 0)" in answer.message, answer.message
        boom = PumpBoom.default()
        joints = JointState(name=list(boom.limits.names), position=[0.4, 1.0, 2.5, 2.8, 3.3, 2.6])
        answer = probe.call(fk, SolveFK.Request(joint_state=joints), 20.0)
        assert answer.success, answer.message
        assert process.alive()
    finally:
        log = process.stop()
    assert "solve_ik and plan_path will fail" in log and "Traceback" not in log, log
