"""The one node style (manipulator_kinematics.nodes.base): machine and settings rules, read-only
parameters, across processes with the SCARA's generic nodes (any registered machine behaves alike)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import yaml
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
from ros_harness import NodeProcess, Probe

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.nodes.base import params_files
from manipulator_kinematics.param_files import SHOWN, ConfigError, config_path, load_parameters, shown
from manipulator_kinematics.schema import Number, validate

pytestmark = pytest.mark.ros

TIMEOUT = 15.0
SCARA = load_parameters(config_path("scara.yaml"))["scara"]


def machine_file(tmp_path: Path, section: dict, name: str = "machine.yaml") -> str:
    path = tmp_path / name
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"scara": section}}}))
    return str(path)


def start_fails(*ros_args: str, exe: str = "scara_ik_server") -> str:
    """Run ``exe`` with ``ros_args``; it must refuse to start: exit 2, one line on stderr."""
    result = subprocess.run(
        [console_script(exe), "--ros-args", *ros_args], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    return lines[0]


def get(probe: Probe, node: str, names: list[str]) -> list:
    client = probe.node.create_client(GetParameters, f"/{node}/get_parameters")
    probe.wait_until(client.service_is_ready, TIMEOUT, "get_parameters")
    return probe.call(client, GetParameters.Request(names=names), TIMEOUT).values


def test_params_files_are_read_from_ros_args_only() -> None:
    argv = [
        "exe",
        "--params-file",
        "not_ros.yaml",
        "--ros-args",
        "-p",
        "a:=1",
        "--params-file",
        "a.yaml",
        "--",
        "--ros-args",
        "--params-file",
        "b.yaml",
    ]
    assert params_files(argv) == [Path("a.yaml"), Path("b.yaml")]


def test_without_a_machine_file_the_default_runs_and_p_changes_one_value(probe: Probe) -> None:
    with NodeProcess("scara_ik_server", "-p", "scara.l2:=0.35") as process:
        values = get(probe, "scara_ik_server", ["scara.l1", "scara.l2", "scara.l3"])
        assert [v.double_value for v in values] == [SCARA["l1"], 0.35, SCARA["l3"]], process.log()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda s: s.pop("l3"), "scara.l3: missing"),
        (lambda s: s.update(l22=0.3), "scara.l22: unknown key (did you mean 'l2'?)"),
        (lambda s: s.update(l1=True), "scara.l1: expected a number (m), got True"),
    ],
)
def test_a_given_machine_file_must_be_complete_and_known(tmp_path: Path, change, message: str) -> None:
    section = dict(SCARA)
    change(section)
    assert message in start_fails("--params-file", machine_file(tmp_path, section))


def test_a_given_machine_file_is_completed_by_p_never_by_the_default(tmp_path: Path, probe: Probe) -> None:
    section = {k: v for k, v in SCARA.items() if k != "l3"} | {"l2": 0.33}
    with NodeProcess(
        "scara_ik_server", "--params-file", machine_file(tmp_path, section), "-p", "scara.l3:=0.2"
    ) as process:
        values = get(probe, "scara_ik_server", ["scara.l1", "scara.l2", "scara.l3"])
        assert [v.double_value for v in values] == [SCARA["l1"], 0.33, 0.2], process.log()


def test_unknown_and_invalid_settings_are_refused() -> None:
    assert "topics.joint_state: unknown key (did you mean 'joint_states'?)" in start_fails(
        "-p", "topics.joint_state:=js", exe="scara_forward"
    )
    assert "qos_depth = 0 is outside [1, 100000]" in start_fails("-p", "qos_depth:=0", exe="scara_forward")
    assert "base_frame: must not be empty" in start_fails("-p", "base_frame:=''")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("/**:\n  ros__parameters:\n", "expected a mapping 'ros__parameters:'"),
        ("a: [\n", "not valid YAML (line 2)"),
        ("/**:\n  ros__parameters:\n    scara: {}\n", "scara = {} is not a ROS parameter value"),
        ("/**:\n  ros__parameters:\n    scara: {l1: [1, x]}\n", "scara.l1 = [1, 'x'] is not"),
        ("[1, 2]\n", "expected sections"),
        (b"/**:\n  ros__parameters:\n    frame: '\xff'\n", "not UTF-8 text (byte 36)"),
    ],
)
def test_a_params_file_rcl_cannot_take_is_one_line(tmp_path: Path, text: str | bytes, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    assert message in start_fails("--params-file", str(path))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--params-file", "no_such_file.yaml"), "no_such_file.yaml: No such file or directory"),
        (("-p", "l1"), "-p 'l1': expected NAME:=VALUE"),
        (("--params-file",), "--params-file: a value must follow it"),
        (("--no-such-ros-argument",), "invalid ROS arguments"),
    ],
)
def test_rcl_argument_errors_are_one_line(args: tuple[str, ...], message: str) -> None:
    assert message in start_fails(*args)


def test_a_renamed_node_keeps_its_settings_defaults(probe: Probe) -> None:
    with NodeProcess("scara_forward", "-r", "__node:=renamed_forward") as process:
        values = get(probe, "renamed_forward", ["base_frame", "topics.tool_pose"])
        assert [v.string_value for v in values] == ["base_link", "tool_pose"], process.log()


def test_parameters_are_read_only_and_a_set_is_refused_with_a_reason(probe: Probe) -> None:
    with NodeProcess("scara_ik_server") as process:
        describe = probe.node.create_client(DescribeParameters, "/scara_ik_server/describe_parameters")
        setter = probe.node.create_client(SetParameters, "/scara_ik_server/set_parameters")
        probe.wait_until(
            lambda: describe.service_is_ready() and setter.service_is_ready(), TIMEOUT, "parameter services"
        )
        descriptors = probe.call(
            describe, DescribeParameters.Request(names=["scara.l2", "base_frame"]), TIMEOUT
        ).descriptors
        assert all(d.read_only for d in descriptors)
        assert descriptors[0].description == "upper arm, shoulder to elbow (m)"
        assert descriptors[1].description.startswith("frame of targets and results")
        value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=0.5)
        request = SetParameters.Request(parameters=[ParameterMsg(name="scara.l2", value=value)])
        result = probe.call(setter, request, TIMEOUT).results[0]
        assert not result.successful and "read-only" in result.reason, result.reason
        assert get(probe, "scara_ik_server", ["scara.l2"])[0].double_value == SCARA["l2"]
        assert process.alive()


def test_an_oversized_params_value_is_refused_before_anything_parses_it(tmp_path: Path) -> None:
    """A 100,000-element list (78 s and a 500,070-character line before): refused by its key,
    read only up to item 10,001: the broken YAML after the list is never reached."""
    path = tmp_path / "big.yaml"
    items = ", ".join(["0.2"] * 100_000)
    path.write_text(f"/**:\n  ros__parameters:\n    scara:\n      l2: 0.3\n      l1: [{items}]\n    x: [\n")
    line = start_fails("--params-file", str(path))
    assert "/**: scara.l1 (line 5): more than the 10000 items a list or mapping may have" in line, line
    assert len(line) < 300, line
    huge = tmp_path / "huge.yaml"
    huge.write_text("#" * (5 << 20) + "\n/**:\n  ros__parameters: {}\n")
    line = start_fails("--params-file", str(huge))
    assert "5.0 MiB, more than the 4 MiB such a file may have" in line, line


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ([0.2] * 9000, "scara.l1: expected a number (m), got [0.2, 0.2, 0.2, "),
        ("x" * 100_000, "scara.l1: expected a number (m), got 'xxxx"),
    ],
)
def test_values_in_error_lines_are_cut(tmp_path: Path, value, message: str) -> None:
    line = start_fails("--params-file", machine_file(tmp_path, dict(SCARA) | {"l1": value}))
    assert message in line and "..." in line and len(line) < 300, line[:400]


def test_shown_cuts_long_values_only() -> None:
    assert shown([1.0, 2.0]) == "[1.0, 2.0]" and shown("a" * 98) == repr("a" * 98)  # 100 characters
    assert shown("a" * 99) == "'" + "a" * 79 + "..." + "a" * 11 + "'"
    text = shown(list(range(100_000)))
    assert text.startswith("[0, 1, 2, ") and text.endswith("...9998, 99999] (100000 items)")
    assert len(text) < SHOWN + 20
    with pytest.raises(ConfigError, match=r"^scara\.'x{79}\.\.\.x{11}': unknown key") as refused:
        validate({"x" * 100_000: 1.0}, {"l1": Number()}, "scara")
    assert len(str(refused.value)) < 300
