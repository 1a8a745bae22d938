"""The excavator reads its linkage from the hydraulic family's section (issue 31, item 1).

config/excavator_cet200.yaml holds the CET200 once: a ``hydraulic_machine`` section (the family
form) and an ``excavator`` section (base_height, IMU mounts). The excavator's loader maps the
family section onto its topology (excavator_kinematics.core.machine_file); checked here against the
CET200's file of the old form (test/data, the pre-family file, read by the old keys), against the
family's own model of the same file, and for its refusals (one line, the key named).
"""

from __future__ import annotations

import copy
import logging
from pathlib import Path

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.machine_file import OLD_SCHEMA, SECTION, upgrade
from manipulator_kinematics.hydraulic import HydraulicModel
from manipulator_kinematics.hydraulic.check import main as machine_check
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.registry import machine, machines_described
from manipulator_kinematics.schema import validate

OLD_FILE = Path(__file__).parent / "data" / "excavator_cet200_old_form.yaml"
SHIPPED = config_path("excavator_cet200.yaml")
RNG = np.random.default_rng(31)


def _sections() -> dict:
    return copy.deepcopy(load_parameters(SHIPPED))


def _states(model: Excavator, n: int = 500) -> np.ndarray:
    return RNG.uniform(model.limits.d_min, model.limits.d_max, (n, 4))


def test_the_shipped_file_is_the_old_files_machine_digit_for_digit() -> None:
    """Every number of the description equals the old file's (read by the old keys), so every
    excavator figure, test and benchmark keeps its numbers."""
    new, old = Excavator.from_file(SHIPPED), Excavator.from_file(OLD_FILE)
    a, b = new.description, old.description
    for field, spec in a.__dataclass_fields__.items():
        # The family section as read is no geometry of its own (compare=False): the old file's
        # converted section has other chain limits, as joint_limits.
        if field in ("limits", "joint_limits") or not spec.compare:
            continue
        assert getattr(a, field) == getattr(b, field), field
    for field in a.limits.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(a.limits, field), getattr(b.limits, field), err_msg=field)
    old_section = validate(load_parameters(OLD_FILE)[SECTION], OLD_SCHEMA, SECTION)
    assert (
        a.foot == tuple(old_section["boom"]["foot_pin"])
        and a.h_link_length == old_section["h_link"]["length"]
    )
    np.testing.assert_array_equal(new.packed, old.packed)
    D = _states(new)
    np.testing.assert_array_equal(new.pose(D), old.pose(D))


def test_excavator_and_family_model_of_the_one_file_agree() -> None:
    exc, family = Excavator.from_file(SHIPPED), HydraulicModel.from_file(SHIPPED)
    D = _states(exc)
    np.testing.assert_allclose(exc.pose(D), family.pose(D), rtol=0, atol=1e-12)
    np.testing.assert_allclose(exc.jc0(D), family.jc0(D), rtol=0, atol=1e-12)
    assert family.description.outline == exc.description.bucket_outline
    assert family.description.tail == exc.description.tail


def test_an_old_file_is_converted_on_load_with_one_line_saying_how(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        Excavator.from_file(OLD_FILE)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "\n" not in lines[0], lines
    assert str(OLD_FILE) in lines[0] and "mk_machine_check OLD.yaml --convert NEW.yaml" in lines[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        Excavator.from_file(SHIPPED)
    assert not caplog.records  # the current form: nothing to say


def test_machine_check_converts_an_old_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``mk_machine_check OLD.yaml --convert NEW.yaml`` writes the current form and checks it: the
    same machine for the excavator and the family core, the excavator's own keys kept."""
    new = tmp_path / "new.yaml"
    assert machine_check([str(OLD_FILE), "--convert", str(new), "--no-png", "--grid", "3"]) == 0
    assert "dead-centre margin" in capsys.readouterr().out
    sections = load_parameters(new)
    assert set(sections) == {"hydraulic_machine", "excavator"}
    assert sections["excavator"] == load_parameters(SHIPPED)["excavator"]
    D = _states(Excavator.default())
    np.testing.assert_array_equal(Excavator.from_file(new).pose(D), Excavator.default().pose(D))
    np.testing.assert_allclose(
        HydraulicModel.from_file(new).pose(D), Excavator.default().pose(D), rtol=0, atol=1e-12
    )


def test_machine_check_says_how_to_convert_an_old_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert machine_check([str(OLD_FILE), "--no-png"]) == 1
    assert "--convert NEW.yaml" in capsys.readouterr().err


def _refused(sections: dict) -> str:
    with pytest.raises(ConfigError) as info:
        Excavator.from_parameters(sections)
    message = str(info.value)
    assert "\n" not in message, message
    return message


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda g: g["bodies"]["arm"]["pins"].pop("ilink_pin_on_arm"), "hydraulic_machine.bodies.arm.pins"),
        (lambda g: g["bodies"].update(stick={"pins": {}}), "hydraulic_machine.bodies.stick"),
        (
            lambda g: g["dyads"]["bkt_cyl_rod"].update(pivot="bucket_pin"),
            "hydraulic_machine.dyads.bkt_cyl_rod.pivot",
        ),
        (lambda g: g.update(actuators=["lift_cylinder"]), "hydraulic_machine.actuators"),
        (lambda g: g.pop("links"), "hydraulic_machine.links"),
        (lambda g: g.update(prismatic={"tele": {}}), "hydraulic_machine.prismatic"),
    ],
)
def test_another_topology_is_refused_naming_the_key_and_the_family_nodes(edit: object, key: str) -> None:
    sections = _sections()
    edit(sections["hydraulic_machine"])  # type: ignore[operator]
    message = _refused(sections)
    assert message.startswith(key) and "hydraulic_* nodes" in message and "HydraulicModel" in message, message


def test_the_wheel_loader_is_not_an_excavator() -> None:
    sections = {
        **load_parameters(config_path("wheel_loader_wl20.yaml")),
        "excavator": _sections()["excavator"],
    }
    message = _refused(sections)
    assert message.startswith("hydraulic_machine.") and "hydraulic_* nodes" in message, message


def test_a_number_out_of_range_is_refused_without_the_topology_hint() -> None:
    sections = _sections()
    sections["hydraulic_machine"]["cylinders"]["arm_cylinder"]["max_speed"] = 50.0
    message = _refused(sections)
    assert (
        message.startswith("hydraulic_machine.cylinders.arm_cylinder.max_speed = 50")
        and "nodes" not in message
    )


@pytest.mark.parametrize(
    ("body", "pin", "value"),
    [("boom", "boom_foot", [0.1, 0.0]), ("arm", "bucket_pin", [2.9, 0.05]), ("bucket", "tip", [-1.3, 0.0])],
)
def test_a_link_frame_not_along_its_pins_is_refused(body: str, pin: str, value: list[float]) -> None:
    sections = _sections()
    sections["hydraulic_machine"]["bodies"][body]["pins"][pin] = value
    assert _refused(sections).startswith(
        f"hydraulic_machine.bodies.{body}.pins.{pin}: the excavator's link frames"
    )


def test_joint_limits_narrower_than_the_stroke_are_refused() -> None:
    """theta2 spans [-31, 60] deg over the boom stroke (docs/excavator.md): a 50 deg stop is refused."""
    sections = _sections()
    sections["hydraulic_machine"]["chain"]["theta2"]["limits"] = [-0.6, 0.8726646]
    message = _refused(sections)
    assert message.startswith("hydraulic_machine.chain.theta2.limits: ") and "outside its limits" in message


@pytest.mark.parametrize("where", ["swing", "cylinders.bucket_cylinder"])
def test_zero_offsets_are_read_in_the_order_of_D(where: str) -> None:
    """A calibrated file's zero offset (issue 33) reaches the model, in the order of D."""
    sections = _sections()
    part = sections["hydraulic_machine"]
    for name in where.split("."):
        part = part[name]
    part["zero_offset"] = 0.01
    expected = np.zeros(4)
    expected[0 if where == "swing" else 3] = 0.01
    np.testing.assert_array_equal(Excavator.from_parameters(sections).zero_offset, expected)
    np.testing.assert_array_equal(Excavator.from_file(SHIPPED).zero_offset, np.zeros(4))


@pytest.mark.parametrize("missing", ["excavator", "hydraulic_machine"])
def test_a_file_without_one_of_the_two_sections_is_refused(missing: str) -> None:
    sections = _sections()
    del sections[missing]
    assert _refused(sections).startswith(f"{missing}: missing")


def test_the_old_form_beside_a_family_section_is_refused_naming_the_old_key() -> None:
    sections = _sections()
    sections["excavator"]["boom"] = {"length": 5.7}
    assert _refused(sections).startswith("excavator.boom: unknown key")


def test_upgrade_leaves_a_current_file_alone() -> None:
    sections = _sections()
    assert upgrade(sections) == sections


def test_the_registry_reads_the_file_as_one_excavator() -> None:
    """Both sections are the excavator's: no family machine besides it, the model the same."""
    found = machines_described(load_parameters(SHIPPED))
    assert list(found) == ["excavator"]
    record = machine("excavator")
    D = _states(Excavator.default(), 20)
    np.testing.assert_array_equal(record.model().pose(D), Excavator.default().pose(D))
    np.testing.assert_array_equal(
        record.model_of(load_parameters(OLD_FILE)).pose(D), Excavator.default().pose(D)
    )
