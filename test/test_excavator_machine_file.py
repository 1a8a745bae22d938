"""What the excavator machine file's signs and swing limits do (issue 28, item 5).

A wrong assembly branch (an orientation's sign) is refused with its key; open swing limits
(-.inf, .inf) make a continuous swing whose angles every consumer wraps to (-pi, pi]. Numbers are
checked against the open chain (paper eq. 3) and the CET200's check values (docs/excavator.md).
"""

from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.core.urdf_joints import excavator_urdf
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters

LIMITED = Excavator.default()


def _section() -> dict:
    """The shipped file's top-level sections (hydraulic_machine and excavator), a copy."""
    return copy.deepcopy(load_parameters(config_path("excavator_cet200.yaml")))


def _continuous() -> dict:
    section = _section()
    section["hydraulic_machine"]["swing"].update(min_angle=-math.inf, max_angle=math.inf)
    return section


CONTINUOUS = Excavator.from_parameters(_continuous())


@pytest.mark.parametrize(
    ("dyad", "says"),
    [
        ("boom_cyl_rod", "raise the boom"),
        ("arm_cyl_rod", "curl the arm in"),
        ("bkt_cyl_rod", "curl the bucket in"),
        ("hlink_pin_on_bucket", "crosses the bucket linkage"),
    ],
)
def test_a_flipped_orientation_is_refused_in_one_line_naming_the_key(dyad: str, says: str) -> None:
    section = _section()
    section["hydraulic_machine"]["dyads"][dyad]["orientation"] *= -1
    with pytest.raises(ConfigError) as info:
        Excavator.from_parameters(section)
    message = str(info.value)
    assert message.startswith(f"hydraulic_machine.dyads.{dyad}.orientation: ") and says in message, message
    assert "\n" not in message


def test_the_shipped_branches_move_the_documented_way() -> None:
    """The check values: extending each cylinder from the reference moves its joint the documented
    way, the tip in front of the swing axis (docs/excavator.md: r = 4.209 m)."""
    ref = LIMITED.limits.reference
    step = np.diag([0.0, 0.01, 0.01, 0.01])
    theta = LIMITED.joint_angles(ref[1:])
    moved = np.array([LIMITED.joint_angles((ref + step[i])[1:])[i - 1] for i in (1, 2, 3)])
    assert moved[0] > theta[0] and moved[1] < theta[1] and moved[2] < theta[2]
    np.testing.assert_allclose(LIMITED.pose(ref)[:3], [4.209238, 0.0, 1.008412], atol=1e-6)


def test_a_tip_behind_the_swing_axis_is_refused() -> None:
    """The boom's foot pin and cylinder base moved 10 m back: every cylinder still turns its joint
    the documented way, but the tip (4.2 m in front) ends up 5.8 m behind the swing axis."""
    section = _section()
    base = section["hydraulic_machine"]["bodies"]["upper_structure"]["pins"]
    base["boom_foot"][0] -= 10.0
    base["boom_cyl_base"][0] -= 10.0
    with pytest.raises(
        ConfigError, match=r"^hydraulic_machine\.cylinders\.boom_cylinder\.reference_length: .*behind"
    ):
        Excavator.from_parameters(section)


@pytest.mark.parametrize(
    ("limits", "key"),
    [
        ((-math.inf, 3.0), "hydraulic_machine.swing.max_angle"),  # the finite one is named
        ((-3.0, math.inf), "hydraulic_machine.swing.min_angle"),
    ],
)
def test_a_half_open_swing_is_refused(limits: tuple[float, float], key: str) -> None:
    section = _section()
    section["hydraulic_machine"]["swing"].update(min_angle=limits[0], max_angle=limits[1])
    with pytest.raises(ConfigError, match=rf"^{key}: a continuous swing has both limits open"):
        Excavator.from_parameters(section)


def test_open_limits_read_from_yaml_as_written_in_the_file(tmp_path) -> None:
    """``.inf`` in the file is the open limit (YAML 1.1 float infinity)."""
    text = config_path("excavator_cet200.yaml").read_text()
    data = yaml.safe_load(text)
    data["/**"]["ros__parameters"]["hydraulic_machine"]["swing"].update(
        min_angle=-math.inf, max_angle=math.inf
    )
    path = tmp_path / "continuous.yaml"
    path.write_text(yaml.safe_dump(data))
    assert "-.inf" in path.read_text()
    model = Excavator.from_file(path)
    assert model.limits.continuous_swing and not LIMITED.limits.continuous_swing


def test_a_continuous_swing_takes_any_angle_and_wraps_it() -> None:
    ref = CONTINUOUS.limits.reference
    for swing in (3.3, -3.3, 7.0, 100.0, math.pi, -math.pi):
        D = np.array([swing, *ref[1:]])
        wrapped = math.atan2(math.sin(swing), math.cos(swing))
        expected = LIMITED.open_chain_pose([wrapped, *LIMITED.joint_angles(ref[1:])])
        np.testing.assert_allclose(CONTINUOUS.pose(D), expected, atol=1e-12)
        state = CONTINUOUS.state(D, np.zeros(4))
        assert -math.pi < state.theta[0] <= math.pi
        np.testing.assert_allclose(math.cos(state.theta[0] - swing), 1.0, atol=1e-12)
    batch = np.tile(ref, (5, 1))
    batch[:, 0] = [3.3, -4.0, 0.5, 9.0, -math.pi]
    validated = CONTINUOUS.validate(batch)
    assert np.all((validated[:, 0] > -math.pi) & (validated[:, 0] <= math.pi))
    with pytest.raises(ValueError, match=r"swing_joint angle 3\.3 rad outside"):
        LIMITED.validate(np.array([3.3, *ref[1:]]))
    with pytest.raises(ValueError, match="not finite"):
        CONTINUOUS.validate(np.array([math.inf, *ref[1:]]))


def test_the_ik_of_a_continuous_swing_answers_in_the_wrapped_range_near_a_wound_up_seed() -> None:
    ref = CONTINUOUS.limits.reference.copy()
    ref[0] = 3.0
    target = CONTINUOUS.pose(ref)
    seed = ref.copy()
    seed[0] = 3.0 + 2.0 * math.pi  # the same heading, one turn on
    solution = CONTINUOUS.ik(target, seed=seed)
    selected = solution.solution
    np.testing.assert_allclose(selected, ref, atol=1e-9)
    np.testing.assert_allclose(CONTINUOUS.pose(selected), target, atol=1e-9)


def test_the_plant_turns_a_continuous_swing_on_and_stops_a_limited_one() -> None:
    start = CONTINUOUS.limits.reference.copy()
    start[0] = 3.0
    command = np.array([1.0, 0.0, 0.0, 0.0])
    turning, stopped = Plant(CONTINUOUS.limits, start), Plant(LIMITED.limits, start)
    for _ in range(100):  # 1 s at 1 rad/s
        turning.step(command, 0.01)
        stopped.step(command, 0.01)
    np.testing.assert_allclose(turning.d[0], 4.0 - 2.0 * math.pi, atol=1e-9)
    np.testing.assert_allclose(turning.d_dot[0], 1.0)
    assert stopped.d[0] == LIMITED.limits.swing_max and stopped.d_dot[0] == 0.0


def test_the_urdf_of_a_continuous_swing_has_a_continuous_joint() -> None:
    def swing(model: Excavator) -> ET.Element:
        joints = ET.fromstring(excavator_urdf(model)).iter("joint")
        return next(j for j in joints if j.get("name") == "swing_joint")

    assert swing(CONTINUOUS).get("type") == "continuous" and swing(CONTINUOUS).find("limit") is None
    assert swing(LIMITED).get("type") == "revolute"
    assert float(swing(LIMITED).find("limit").get("upper")) == pytest.approx(math.pi)
