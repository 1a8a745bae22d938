"""The excavator nodes and the family's nodes run the one CET200 file (issue 31, item 1).

Real processes: an excavator node reads both sections of config/excavator_cet200.yaml (declared
as its parameters), converts a file of the old form on load with one line, refuses a file without
the linkage section; a family node runs the same file and passes over its ``excavator`` section.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import yaml
from rcl_interfaces.srv import GetParameters
from ros_harness import NodeProcess, Probe

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics.param_files import config_path, load_parameters

pytestmark = pytest.mark.ros

TIMEOUT = 30.0
OLD_FILE = Path(__file__).parent / "data" / "excavator_cet200_old_form.yaml"
SHIPPED = load_parameters(config_path("excavator_cet200.yaml"))


@pytest.fixture(scope="module")
def probe() -> Probe:
    p = Probe("excavator_family_file_test")
    yield p
    p.close()


def get(probe: Probe, node: str, names: list[str]) -> list:
    client = probe.node.create_client(GetParameters, f"{node}/get_parameters")
    probe.wait_until(client.service_is_ready, TIMEOUT, f"{node}/get_parameters")
    return probe.call(client, GetParameters.Request(names=names), TIMEOUT).values


ARM_PIN = "hydraulic_machine.bodies.boom.pins.arm_pin"


def test_an_old_file_runs_converted_with_one_line_and_the_new_keys(probe: Probe) -> None:
    with NodeProcess("excavator_forward", "--params-file", str(OLD_FILE), "-r", "__ns:=/old") as process:
        arm_pin, base_height = get(probe, "/old/excavator_forward", [ARM_PIN, "excavator.base_height"])
        assert (
            list(arm_pin.double_array_value)
            == SHIPPED["hydraulic_machine"]["bodies"]["boom"]["pins"]["arm_pin"]
        )
        assert base_height.double_value == 0.0
        log = process.log()
    lines = [line for line in log.splitlines() if "old form" in line]
    assert len(lines) == 1 and "mk_machine_check OLD.yaml --convert NEW.yaml" in lines[0], log


def test_the_family_forward_node_runs_the_excavator_file(probe: Probe) -> None:
    file = str(config_path("excavator_cet200.yaml"))
    with NodeProcess("hydraulic_forward", "--params-file", file, "-r", "__ns:=/fam") as process:
        (name,) = get(probe, "/fam/hydraulic_forward", ["hydraulic_machine.name"])
        assert name.string_value == "CET200", process.log()
        assert process.alive(), process.log()


def test_a_file_without_the_linkage_section_is_refused_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "extras.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"excavator": SHIPPED["excavator"]}}}))
    result = subprocess.run(
        [console_script("excavator_forward"), "--ros-args", "--params-file", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, (result.returncode, result.stderr)
    assert "hydraulic_machine: missing" in lines[0], lines[0]
