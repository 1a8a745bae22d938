"""The hydraulic family in the registry (wheel_loader, knuckle_crane: machine files, no Python per
machine) with the serial-machine API the generic nodes and tools use, checked independently:
the tool pose against the model's Q, the twist Jacobian against finite differences of the pose,
IK round trips, the URDF read by Pinocchio (urdfdom) against the scene's frames, the scene's
cylinders pin to pin, and the velocity IK's direction rule and the simulated actuators."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from manipulator_kinematics.hydraulic.control import END_ZONE, STROKE, Plant, rate_command, toward_line
from manipulator_kinematics.hydraulic.drawing import family_urdf, urdf_joint_values
from manipulator_kinematics.model import IKStatus, RequestError
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.registry import by_section, machine, machines

FAMILY = ("knuckle_crane", "wheel_loader")
RNG = np.random.default_rng(31)


def states(arm, count: int) -> np.ndarray:
    h = arm.hydraulic
    return RNG.uniform(h.lower, h.upper, (count, h.m))


@pytest.fixture(scope="module", params=FAMILY)
def arm(request):
    return machine(request.param).model()


def test_both_machines_are_registered_from_their_files_alone() -> None:
    family = [m for m in machines().values() if m.section == "hydraulic_machine"]
    assert [m.name for m in family] == list(FAMILY)
    for m in family:
        section = load_parameters(config_path(m.config_file))["hydraulic_machine"]
        assert by_section("hydraulic_machine", section) is m
        assert m.describes(section) and m.node_arguments == ("--params-file", str(config_path(m.config_file)))
        assert m.factory.__module__ == "manipulator_kinematics.hydraulic.machine"
    assert machine("wheel_loader").model().joint_names == ("lift_cylinder", "tilt_cylinder")
    assert machine("knuckle_crane").model().joint_names == (
        "swing_joint",
        "lift_cylinder",
        "fold_cylinder",
        "tele_cylinder",
    )
    # A user's own machine of the family: the family's first record reads it (same factory).
    own = {**load_parameters(config_path("wheel_loader_wl20.yaml"))["hydraulic_machine"], "name": "WL25"}
    found = by_section("hydraulic_machine", own)
    assert found is machine("knuckle_crane")
    assert found.model_from(own).name == "WL25"
    assert by_section("scara") is machine("scara") and by_section("nothing") is None


def test_tool_pose_is_q_and_the_jacobian_its_derivative(arm) -> None:
    h = arm.hydraulic
    D = states(arm, 200)
    T = arm.fkine(D)
    Q = h.pose(D)
    np.testing.assert_allclose(T[:, :3, 3], Q[:, :3], atol=1e-12)
    np.testing.assert_allclose(
        T[:, :3, :3] @ np.swapaxes(T[:, :3, :3], -1, -2), np.broadcast_to(np.eye(3), (200, 3, 3)), atol=1e-12
    )
    if h.description.has_angle:  # the tool's x axis pitched up by alpha (REP 103: about -y)
        np.testing.assert_allclose(np.arctan2(T[:, 2, 0], T[:, 2, 2]), Q[:, 3], atol=1e-12)
    # Central differences of the pose along each actuator (step inside the box).
    J = arm.jacob0(D)
    step = 1e-6
    for i in range(h.m):
        e = np.zeros(h.m)
        e[i] = step
        inner = np.clip(D, h.lower + step, h.upper - step)
        plus, minus = arm.fkine(inner + e), arm.fkine(inner - e)
        Ji = arm.jacob0(inner)[:, :, i]
        np.testing.assert_allclose((plus[:, :3, 3] - minus[:, :3, 3]) / (2 * step), Ji[:, :3], atol=1e-6)
        dR = (
            (plus[:, :3, :3] - minus[:, :3, :3])
            / (2 * step)
            @ np.swapaxes(arm.fkine(inner)[:, :3, :3], -1, -2)
        )
        omega = np.stack((dR[:, 2, 1], dR[:, 0, 2], dR[:, 1, 0]), axis=-1)
        np.testing.assert_allclose(omega, Ji[:, 3:], atol=1e-6)
    assert J.shape == (200, 6, h.m)


def test_ik_round_trips_and_refusals(arm) -> None:
    h = arm.hydraulic
    D = states(arm, 100)
    T = arm.fkine(D)
    orient = h.description.has_angle
    seed = np.tile(h.reference, (100, 1))
    seed[:, -1] = D[:, -1]  # the crane's IK keeps the seed's telescope
    result = arm.solve_ik(T, use_orientation=orient, seed=seed)
    assert np.all(result.ok), result.status[~result.ok]
    # The crane's position IK may turn the swing half a turn (the pin behind the swing axis).
    reached = arm.fkine(result.solution)
    np.testing.assert_allclose(
        reached if orient else reached[:, :3, 3], T if orient else T[:, :3, 3], atol=1e-9
    )
    position = arm.solve_ik(T, use_orientation=False, seed=seed)
    np.testing.assert_allclose(arm.fkine(position.solution)[:, :3, 3], T[:, :3, 3], atol=1e-9)
    bad = T[:3].copy()
    bad[0, 0, 3] = np.nan
    bad[1, 2, 3] = 40.0  # out of reach
    out = arm.solve_ik(bad, use_orientation=orient, seed=seed[:3])
    assert out.status[:, 0].tolist() == [IKStatus.INVALID, IKStatus.UNREACHABLE, IKStatus.SUCCESS]
    with pytest.raises(RequestError, match="unknown mode"):
        arm.solve_ik(T[0], mode="other")
    if not orient:
        with pytest.raises(RequestError, match="no tool angle"):
            arm.solve_ik(T[0], use_orientation=True)
    else:  # a rotation off the boom plane is no state of the loader
        turned = T[0].copy()
        turned[:3, :3] = turned[:3, :3] @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        assert arm.solve_ik(turned).status[0] == IKStatus.UNREACHABLE


def test_urdf_frames_are_the_scene_frames_in_pinocchio(arm) -> None:
    entry = next(m for m in machines().values() if m.config_file and m.model().name == arm.name)
    text = family_urdf(arm)
    assert text == entry.urdf(arm)
    pm = pin.buildModelFromXML(text)
    data = pm.createData()
    D = states(arm, 100)
    scene = entry.scene(arm, D)
    # Every moving joint has a value; the actuated ones are D's names with D's values.
    assert sorted(pm.names[1:]) == sorted(scene.joints)
    for i, name in enumerate(arm.joint_names):
        np.testing.assert_array_equal(scene.joints[name], D[:, i])
    worst = 0.0
    for k in range(len(D)):
        q = pin.neutral(pm)
        for name, values in scene.joints.items():
            q[pm.joints[pm.getJointId(name)].idx_q] = values[k]
        pin.framesForwardKinematics(pm, data, q)
        for frame, pose in scene.frames.items():
            worst = max(worst, np.abs(data.oMf[pm.getFrameId(frame)].homogeneous - pose[k]).max())
    assert worst < 1e-9
    np.testing.assert_allclose(scene.tool_point(), arm.fkine(D)[:, :3, 3], atol=1e-12)
    assert set(urdf_joint_values(arm, D[0])) == set(scene.joints)


def test_scene_cylinders_run_pin_to_pin(arm) -> None:
    h = arm.hydraulic
    D = states(arm, 100)
    scene = machine(next(n for n in FAMILY if machine(n).model().name == arm.name)).scene(arm, D)
    segments = {s.name: s for s in scene.segments}
    pins = h.pins(D)
    for c in h.description.cylinders:
        barrel, rod = segments[f"{c.name}_barrel"], segments[f"{c.name}_rod"]
        np.testing.assert_allclose(barrel.start, pins[c.base], atol=1e-12)
        np.testing.assert_allclose(rod.end, pins[c.rod], atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(rod.end - barrel.start, axis=-1), D[:, c.index], atol=1e-9)


def test_rate_command_keeps_the_direction(arm) -> None:
    """Commanded rows move at scale x target (never bent), every speed within its limit, and a
    stroke end ahead stops the whole command."""
    h = arm.hydraulic
    rows = list(h.description.velocity_rows)
    for D in states(arm, 80):
        jc0 = h.jc0(D)[rows]
        target = RNG.normal(size=len(rows)) * 0.3
        cmd = rate_command(jc0, D, target, h.lower, h.upper, h.max_speed, 100.0, 0.1)
        assert np.all(np.abs(cmd.d_dot) <= h.max_speed)
        np.testing.assert_allclose(jc0 @ cmd.d_dot, cmd.scale * target, atol=1e-9 * np.linalg.norm(target))
    # At a stroke end, a command that needs that actuator further out stops.
    D = h.reference.copy()
    D[-1] = h.upper[-1] - END_ZONE / 2
    jc0 = h.jc0(D)[rows]
    outward = np.zeros(h.m)
    outward[-1] = 0.1
    cmd = rate_command(jc0, D, jc0 @ outward, h.lower, h.upper, h.max_speed, 100.0, 0.1)
    assert cmd.scale == 0.0 and np.all(cmd.d_dot == 0.0)
    if len(rows) == h.m:
        assert cmd.limit == STROKE and cmd.actuator == h.m - 1


def test_plant_saturates_and_stops_at_the_stroke_ends(arm) -> None:
    h = arm.hydraulic
    plant = Plant(h.lower, h.upper, h.max_speed, h.reference, 0.0)
    plant.step(10.0 * h.max_speed, 0.01)
    np.testing.assert_allclose(plant.d, h.reference + 0.01 * h.max_speed)
    for _ in range(2000):
        plant.step(h.max_speed, 0.05)
    np.testing.assert_array_equal(plant.d, h.upper)
    np.testing.assert_array_equal(plant.d_dot, 0.0)
    with pytest.raises(ValueError, match="finite"):
        plant.step(np.full(h.m, np.nan), 0.01)


def test_a_family_file_no_record_ships_runs_the_same_way() -> None:
    """The CET200 in the family form (alpha beyond a turn over its box): read by the family's
    record, IK with orientation round-trips (alpha taken modulo a turn), its URDF is Pinocchio's."""
    section = load_parameters(config_path("excavator_cet200.yaml"))["hydraulic_machine"]
    entry = by_section("hydraulic_machine", section)
    arm = entry.model_from(section)
    assert arm.name == "CET200" and arm.joint_names[0] == "swing_joint"
    D = states(arm, 300)
    T = arm.fkine(D)
    assert np.ptp(arm.hydraulic.pose(D)[:, 3]) > np.pi  # more than half a turn of bucket angle
    result = arm.solve_ik(T)
    assert np.all(result.ok)
    np.testing.assert_allclose(arm.fkine(result.solution), T, atol=1e-9)
    pm = pin.buildModelFromXML(entry.urdf(arm))
    data = pm.createData()
    scene = entry.scene(arm, D[:20])
    for k in range(20):
        q = pin.neutral(pm)
        for name, values in scene.joints.items():
            q[pm.joints[pm.getJointId(name)].idx_q] = values[k]
        pin.framesForwardKinematics(pm, data, q)
        np.testing.assert_allclose(data.oMf[pm.getFrameId("tool")].homogeneous, T[k], atol=1e-9)


def test_toward_line_corrects_across_the_line_only() -> None:
    start = np.array([1.0, 0.0, 1.0, 0.2])
    q_dot = np.array([0.1, 0.0, 0.0, 0.05])
    rows = [0, 1, 2, 3]
    # 0.5 m along the line (5 s of it), 1 cm off across, 2 mrad off the angle it should have.
    Q = start + np.array([0.5, 0.01, 0.0, 0.25 + 0.002])
    np.testing.assert_allclose(toward_line(start, q_dot, Q, rows, 2.0), [0.0, -0.02, 0.0, -0.004], atol=1e-12)
    assert toward_line(start, q_dot, start + [0.5, 0.2, 0.0, 0.25], rows, 2.0) is None  # moved: new line
    np.testing.assert_array_equal(toward_line(start, np.array([0, 0, 0, 0.1]), Q, rows, 2.0), 0.0)
    # The loader's rows (z, alpha): a 1-D linear part has no across; the angle is held.
    np.testing.assert_allclose(
        toward_line(start, np.array([0.0, 0.0, 0.1, 0.0]), start + [0.3, 0.0, 0.1, 0.01], [2, 3], 2.0),
        [0.0, 0.0, 0.0, -0.02],
        atol=1e-12,
    )


def test_the_line_correction_keeps_a_sampled_loop_on_its_line() -> None:
    """The crane's pin driven at 5 Hz (rates held between samples, as a loaded node does) along a
    slanted line: with the correction it stays within a few mm of the line, without it drifts."""
    arm = machine("knuckle_crane").model()
    h = arm.hydraulic
    rows = list(h.description.velocity_rows)
    target = np.array([0.06, 0.05, 0.06])
    limits = (h.lower, h.upper, h.max_speed, 100.0, 0.1)

    def run(gain: float) -> float:
        plant = Plant(h.lower, h.upper, h.max_speed, h.reference, 0.0)
        start = h.pose(plant.d)
        q_dot = target
        u = target / np.linalg.norm(target)
        worst = 0.0
        for _ in range(30):  # 6 s
            now = h.measured(plant.d)  # one solve: Q and JC0
            offset = now.Q - start
            worst = max(worst, float(np.linalg.norm(offset - (offset @ u) * u)))
            correction = toward_line(start, q_dot, now.Q, rows, gain)
            cmd = rate_command(now.jc0[rows], plant.d, (q_dot + correction)[rows], *limits)
            plant.step(cmd.d_dot, 0.2)
        return worst

    with_gain, without = run(2.0), run(0.0)
    print(f"largest distance from the line: {with_gain * 1e3:.2f} mm corrected, {without * 1e3:.2f} mm not")
    assert with_gain < 0.001 and without > 4.0 * with_gain, (with_gain, without)


def test_a_calibrated_file_reads_its_sensors_through_the_zero_offsets() -> None:
    """A calibrated machine file (issue 33: true = reading + zero_offset): the joint values are
    sensor readings; the pose of readings q is the model's Q at D = q + offset, the IK answers
    readings, the limits are the stroke box in readings, the scene draws D."""
    section = load_parameters(config_path("wheel_loader_wl20.yaml"))["hydraulic_machine"]
    offsets = {"lift_cylinder": 0.013, "tilt_cylinder": -0.008}
    for name, offset in offsets.items():
        section["cylinders"][name]["zero_offset"] = offset
    entry = by_section("hydraulic_machine", section)
    arm = entry.model_from(section)
    h = arm.hydraulic
    offset = np.array([offsets[n] for n in arm.joint_names])
    D = states(arm, 200)
    q = D - offset
    np.testing.assert_allclose(arm.fkine(q)[:, :3, 3], h.pose(D)[:, :3], atol=1e-12)
    np.testing.assert_allclose(arm.limits.lower, h.lower - offset)
    np.testing.assert_allclose(arm.limits.upper, h.upper - offset)
    result = arm.solve_ik(arm.fkine(q), seed=q)
    assert np.all(result.ok)
    np.testing.assert_allclose(result.solution, q, atol=1e-9)
    scene = entry.scene(arm, q[:5])
    for name, i in (("lift_cylinder", 0), ("tilt_cylinder", 1)):
        np.testing.assert_allclose(scene.joints[name], D[:5, i], atol=1e-12)
