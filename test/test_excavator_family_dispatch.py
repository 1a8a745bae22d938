"""Which node the excavator's executables run (excavator_kinematics.nodes.family): the family's
for a params file with a ``hydraulic_machine`` section and no ``excavator`` section, the
excavator's for anything else, a file with both sections included. The processes themselves:
test_hydraulic_plan_ros.py."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from excavator_kinematics.nodes.family import family_file
from manipulator_kinematics.param_files import config_path


def argv(*files: Path | str) -> list[str]:
    return ["excavator_forward", "--ros-args", *(a for f in files for a in ("--params-file", str(f)))]


def test_a_family_file_runs_the_family_node() -> None:
    for name in ("wheel_loader_wl20.yaml", "knuckle_crane_kc100.yaml"):
        assert family_file(argv(config_path(name)))
    # With the excavator's node settings too: still a family machine.
    assert family_file(argv(config_path("wheel_loader_wl20.yaml"), config_path("excavator_nodes.yaml")))


def test_the_excavator_file_and_anything_else_runs_the_excavator_node(tmp_path: Path) -> None:
    assert not family_file(argv(config_path("excavator_cet200.yaml")))
    assert not family_file(argv())
    assert not family_file(["excavator_forward"])
    # Both sections (the CET200 file with its family geometry and the excavator's extras): the
    # excavator's node.
    loader = yaml.safe_load(config_path("wheel_loader_wl20.yaml").read_text())
    excavator = yaml.safe_load(config_path("excavator_cet200.yaml").read_text())
    both = tmp_path / "both.yaml"
    params = {**loader["/**"]["ros__parameters"], **excavator["/**"]["ros__parameters"]}
    both.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    assert not family_file(argv(both))
    # Two files, one of each: the excavator's too.
    assert not family_file(argv(config_path("wheel_loader_wl20.yaml"), config_path("excavator_cet200.yaml")))


@pytest.mark.parametrize("text", ["{not yaml: [", "- a list\n"])
def test_an_unreadable_file_is_left_to_the_excavator_node(tmp_path: Path, text: str) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    assert not family_file(argv(bad))  # the excavator node refuses it with the reason


def test_each_old_name_has_the_family_node_of_its_role() -> None:
    """The dispatch maps excavator_<role> to the family's <role> main (hydraulic_<role>)."""
    from excavator_kinematics.nodes import forward_node, ik_server_node, sim_node, velocity_ik_node
    from manipulator_kinematics.nodes import hydraulic

    names = {module.NODE for module in (forward_node, ik_server_node, sim_node, velocity_ik_node)}
    assert names == {f"excavator_{role}" for role in ("forward", "velocity_ik", "sim", "ik_server")}
    for name in names:
        role = getattr(hydraulic, name.removeprefix("excavator_"))
        assert callable(role) and role.__module__ == hydraulic.__name__
