"""The generated URDFs against the package's kinematics, read by an independent parser.

Pinocchio (``pin``, test dependency only) parses each URDF with urdfdom, the parser
robot_state_publisher uses, mimic joints included; its forward kinematics at 1000 random states
inside the limits must give the package's frames (serial machines: every frame of
``model.frames`` and the tool; the excavator: every pin of ``Excavator.pins``, the bucket pose,
and the cut loops closing) to 1e-9.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from artefacts import xml_differences

from excavator_kinematics.core.kinematics import bucket_quaternion
from excavator_kinematics.core.urdf_joints import URDF_JOINTS, joint_positions
from manipulator_kinematics.model import quaternion_matrix
from manipulator_kinematics.registry import machine, machines
from manipulator_kinematics.urdf import (
    PRECISION,
    affine_map,
    machine_urdf,
    main,
    rotation_rpy,
    rpy,
    serial_urdf,
)

REPO = Path(__file__).resolve().parent.parent
SERIAL = ("scara", "tool_changer", "palletizer", "pump_boom")
# The hydraulic family's URDFs against Pinocchio: test/test_hydraulic_machines.py.
FAMILY = ("wheel_loader", "knuckle_crane")
STATES = 1000
TOL = 1e-9


def _pinocchio(text: str) -> tuple[pin.Model, pin.Data]:
    model = pin.buildModelFromXML(text, mimic=True)
    return model, model.createData()


def _frames(pm: pin.Model, data: pin.Data, names: list[str], values: dict[str, float]) -> np.ndarray:
    """4x4 of each frame in ``names`` for joint values by name (mimic joints follow by themselves)."""
    q = pin.neutral(pm)
    for name, value in values.items():
        q[pm.joints[pm.getJointId(name)].idx_q] = value
    pin.framesForwardKinematics(pm, data, q)
    return np.stack([data.oMf[pm.getFrameId(name)].homogeneous for name in names])


def _random_states(limits, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(limits.lower, limits.upper, (STATES, len(limits.names)))


def test_every_machine_has_a_urdf_and_the_shipped_files_are_current() -> None:
    """urdf/<machine>.urdf is what the shipped config generates (regenerate: mk_urdf --all urdf):
    the same XML exactly, every number within 1e-12 (the last bits differ between CPUs)."""
    assert set(machines()) == {"excavator", *SERIAL, *FAMILY}
    for name in machines():
        committed = REPO / "urdf" / f"{name}.urdf"
        differences = xml_differences(committed.read_text(), machine_urdf(name))
        assert not differences, f"{committed} is stale: run mk_urdf --all urdf; {differences[:5]}"
    assert machine_urdf("scara") == machine_urdf("scara")  # deterministic


def test_the_urdf_comparison_finds_every_kind_of_change() -> None:
    text = (REPO / "urdf" / "scara.urdf").read_text()
    assert xml_differences(text, text) == []
    assert xml_differences(text, text.replace('length="0.2"', 'length="0.2000000000001"')) == []
    changed = {
        "number": text.replace('length="0.2"', 'length="0.200000000002"'),
        "count": text.replace('xyz="0.1 0 0"', 'xyz="0.1 0"', 1),
        "word": text.replace('type="revolute"', 'type="continuous"', 1),
        "name": text.replace('name="shoulder_joint"', 'name="shoulder"', 1),
        "attribute": text.replace('effort="0"', 'effort2="0"', 1),
        "element": text.replace("</robot>", '<link name="extra" />\n</robot>'),
        "comment": text.replace("do not edit", "edit", 1),
    }
    for what, other in changed.items():
        assert other != text, what
        assert xml_differences(text, other), what


def test_urdf_numbers_have_fixed_precision() -> None:
    """At most 15 significant digits: no CPU-dependent last bits, config values as typed."""
    for name in machines():
        numbers = re.findall(r'"(-?[0-9][0-9.e+-]*(?: -?[0-9][0-9.e+-]*)*)"', machine_urdf(name))
        digits = [len(re.sub(r"e.*|[-.]", "", v).lstrip("0")) for n in numbers for v in n.split()]
        assert digits and max(digits) <= PRECISION, name
    assert 'xyz="0.6545196915 0 0"' in machine_urdf("excavator")  # 0.6545196914999999 with repr


def _serial_models():
    for name in SERIAL:
        yield name, machine(name).model()
    yield "palletizer_single", machine("palletizer").model().with_variant("single")


@pytest.mark.parametrize("name, model", list(_serial_models()), ids=lambda v: v if isinstance(v, str) else "")
def test_serial_urdf_fk_equals_the_package(name: str, model) -> None:
    hook = machine(name.split("_single")[0]).urdf
    pm, data = _pinocchio(hook(model))
    names = list(model.limits.names)
    # Only the machine's joints are free: passive and coupled joints are mimic joints.
    assert pm.nq == len(names)
    assert sorted(n for n in list(pm.names)[1:] if "mimic" not in n) == sorted(names)
    np.testing.assert_allclose(
        pm.lowerPositionLimit[[pm.joints[pm.getJointId(n)].idx_q for n in names]], model.limits.lower
    )
    q = _random_states(model.limits, np.random.default_rng(7))
    expected = model.frames(q)
    frame_names = [f"frame_{i}" for i in range(model.chain.n_rows + 1)] + ["tool"]
    if expected.shape[1] == model.chain.n_rows + 1:  # the tool is the last D-H frame
        expected = np.concatenate([expected, expected[:, -1:]], axis=1)
    worst = 0.0
    for k in range(STATES):
        got = _frames(pm, data, frame_names, dict(zip(names, q[k], strict=True)))
        worst = max(worst, float(np.max(np.abs(got - expected[k]))))
    assert worst < TOL, f"{name}: URDF frames differ from model.frames by {worst:.3g}"
    np.testing.assert_allclose(expected[:, -1], model.fkine(q), atol=1e-12)


def test_excavator_urdf_fk_equals_the_package() -> None:
    exc = machine("excavator").model()
    pm, data = _pinocchio(machine_urdf("excavator"))
    assert sorted(list(pm.names)[1:]) == sorted(URDF_JOINTS) and pm.nq == len(URDF_JOINTS)
    rng = np.random.default_rng(11)
    D = rng.uniform(exc.limits.d_min, exc.limits.d_max, (STATES, 4))
    values = joint_positions(exc, D)
    pins = exc.pins(D)
    pose = exc.pose(D)
    # The cut loops: the rod bodies end on the rod pins, the H-link on the bucket's pin.
    closures = {
        "boom_cylinder_rod_body": "boom_cylinder_rod",
        "arm_cylinder_rod_body": "arm_cylinder_rod",
        "bucket_cylinder_rod_body": "bucket_cylinder_rod",
        "h_link_pin": "h_link_pin_on_bucket",
    }
    names = list(pins) + list(closures)
    worst_position = worst_rotation = 0.0
    for k in range(STATES):
        frames = _frames(pm, data, names, dict(zip(URDF_JOINTS, values[k], strict=True)))
        targets = np.stack([pins[n][k] for n in pins] + [pins[p][k] for p in closures.values()])
        worst_position = max(worst_position, float(np.max(np.abs(frames[:, :3, 3] - targets))))
        tool = frames[names.index("bucket_tip")]
        rotation = quaternion_matrix(bucket_quaternion(D[k, 0], pose[k, 3]))
        worst_rotation = max(worst_rotation, float(np.max(np.abs(tool[:3, :3] - rotation))))
    assert worst_position < TOL and worst_rotation < TOL, (worst_position, worst_rotation)
    # Every value is inside the URDF's limits (the passive ranges cover the whole stroke box).
    index = [pm.joints[pm.getJointId(n)].idx_q for n in URDF_JOINTS]
    assert np.all(values >= pm.lowerPositionLimit[index]) and np.all(values <= pm.upperPositionLimit[index])


def test_excavator_joint_positions() -> None:
    exc = machine("excavator").model()
    D = np.array([[0.3, 2.0, 3.0, 2.2], [-2.0, 3.1, 2.6, 1.8]])
    values = joint_positions(exc, D)
    assert values.shape == (2, len(URDF_JOINTS))
    np.testing.assert_array_equal(values[:, [5, 7, 9]], D[:, 1:])  # the cylinders are the lengths
    np.testing.assert_allclose(values[:, 1:4], exc.joint_angles(D[:, 1:]), atol=1e-15)
    np.testing.assert_allclose(joint_positions(exc, D[1]), values[1], atol=1e-15)
    # The boom cylinder's barrel points from its base pin to its rod pin (an independent formula).
    p = exc.pins(D[0])
    d = p["boom_cylinder_rod"] - p["boom_cylinder_base"]
    assert values[0, 4] == pytest.approx(math.atan2(d[2], math.hypot(d[0], d[1])), abs=1e-12)


@pytest.mark.parametrize(
    "angles",
    [(0.1, 0.2, 0.3), (0.4, math.pi / 2, -1.0), (-0.3, -math.pi / 2, 2.0), (math.pi, 0.0, -math.pi / 2)],
)
def test_rpy_round_trip(angles: tuple[float, float, float]) -> None:
    rotation = rotation_rpy(angles)
    np.testing.assert_allclose(rotation_rpy(rpy(rotation)), rotation, atol=1e-15)


def test_affine_map_rejects_a_nonlinear_map() -> None:
    A, b = affine_map(lambda q: 2.0 * q + 1.0, 3)
    np.testing.assert_array_equal(A, 2.0 * np.eye(3))
    np.testing.assert_array_equal(b, np.ones(3))
    with pytest.raises(ValueError, match="not affine"):
        affine_map(np.sin, 3)


def test_serial_urdf_needs_a_joint_per_row() -> None:
    model = machine("scara").model()
    with pytest.raises(ValueError, match="one-to-one"):  # every joint scaled by 2: no row moves as q_j
        serial_urdf("scara", model, to_chain=lambda q: 2.0 * q)


def test_mk_urdf_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    params = tmp_path / "scara.yaml"
    shipped = (REPO / "config" / "scara.yaml").read_text()
    params.write_text(shipped.replace("l2: 0.30", "l2: 0.35"))
    assert main(["scara", "-o", str(tmp_path / "scara.urdf"), "--params-file", str(params)]) == 0
    text = (tmp_path / "scara.urdf").read_text()
    model = machine("scara").model(params)
    assert text == machine_urdf("scara", model) != machine_urdf("scara")
    assert main(["--all", str(tmp_path / "all")]) == 0
    assert sorted(p.name for p in (tmp_path / "all").iterdir()) == sorted(f"{n}.urdf" for n in machines())
    assert main(["scarra"]) == 2
    assert "did you mean 'scara'" in capsys.readouterr().err
