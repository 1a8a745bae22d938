"""The drawing description (manipulator_kinematics.scene, excavator_kinematics.tools.scene) against the
kinematics it draws: link ends on the FK frames, cylinder ends on the pins at the commanded
lengths, link lengths from the machine file, marker poses that turn z onto each segment."""

from __future__ import annotations

import numpy as np
import pytest

from excavator_kinematics.core.kinematics import bucket_quaternion
from manipulator_kinematics.model import quaternion_matrix
from manipulator_kinematics.registry import machine, machines
from manipulator_kinematics.scene import cylinder_pose, middle_state, serial_scene, solids

# The hydraulic family's scenes (drawn from pins): test/test_hydraulic_machines.py.
SERIAL = [name for name, m in machines().items() if name != "excavator" and m.section != "hydraulic_machine"]
RNG = np.random.default_rng(13)


def random_states(model, count: int) -> np.ndarray:
    lo, hi = np.asarray(model.limits.lower), np.asarray(model.limits.upper)
    return lo + (hi - lo) * RNG.random((count, len(lo)))


def excavator_states(model, count: int) -> np.ndarray:
    return model.limits.d_min + (model.limits.d_max - model.limits.d_min) * RNG.random((count, 4))


def test_every_machine_has_a_scene_hook() -> None:
    assert set(SERIAL) >= {"scara", "tool_changer", "palletizer", "pump_boom"}
    for m in machines().values():
        assert m.scene is not None, m.name


@pytest.mark.parametrize("name", SERIAL)
def test_serial_scene_lies_on_the_fk_frames(name: str) -> None:
    m = machine(name)
    model = m.model()
    q = random_states(model, 200)
    scene = m.scene(model, q)
    origins = model.frames(q)[..., :3, 3]
    np.testing.assert_allclose(scene.tool_point(), model.fkine(q)[..., :3, 3], atol=1e-12)
    np.testing.assert_allclose(scene.frames["tool"], model.fkine(q), atol=1e-12)
    # Every link joins two consecutive frame origins; together they run from the base to the tool.
    ends = {tuple(np.round(p, 9)) for s in scene.segments for p in (s.start[0], s.end[0])}
    assert tuple(np.round(origins[0, 0], 9)) in ends and tuple(np.round(origins[0, -1], 9)) in ends
    total = sum(s.length for s in scene.segments)
    chain = np.linalg.norm(np.diff(origins, axis=-2), axis=-1).sum(axis=-1)
    np.testing.assert_allclose(total, chain, atol=1e-9)
    assert scene.shape == (200,)
    # Radii do not change with the state (read at the middle of the ranges).
    one = m.scene(model, q[7])
    assert [s.radius for s in one.segments] == [s.radius for s in scene.segments]
    np.testing.assert_allclose(one.points(), scene.points()[7], atol=1e-12)


def test_excavator_cylinders_run_pin_to_pin_at_the_commanded_length() -> None:
    m = machine("excavator")
    model = m.model()
    D = excavator_states(model, 500)
    scene = m.scene(model, D)
    seg = {s.name: s for s in scene.segments}
    for i, name in enumerate(("boom_cylinder", "arm_cylinder", "bucket_cylinder")):
        barrel, rod = seg[f"{name}_barrel"], seg[f"{name}_rod"]
        # Barrel from the base pin, rod to the rod pin; both on one line; pin distance = length.
        np.testing.assert_allclose(np.linalg.norm(rod.end - barrel.start, axis=-1), D[:, i + 1], atol=1e-9)
        direction = (rod.end - barrel.start) / D[:, i + 1, None]
        for p in (barrel.end, rod.start):
            np.testing.assert_allclose(np.cross(p - barrel.start, direction), 0.0, atol=1e-9)
        # Fixed lengths: the rod slides out of the barrel as the cylinder lengthens.
        shortest = model.limits.stroke_min[i]
        np.testing.assert_allclose(barrel.length, 0.9 * shortest, atol=1e-9)
        np.testing.assert_allclose(rod.length, shortest, atol=1e-9)
        exposed = np.linalg.norm(rod.end - barrel.end, axis=-1)
        np.testing.assert_allclose(exposed, D[:, i + 1] - 0.9 * shortest, atol=1e-9)
        assert np.all(np.einsum("ij,ij->i", rod.start - barrel.start, direction) < barrel.length)  # overlap


def test_excavator_linkage_and_frames_match_the_machine_file_and_pose() -> None:
    m = machine("excavator")
    model, params = m.model(), m.parameters()
    D = excavator_states(model, 500)
    scene = m.scene(model, D)
    seg = {s.name: s for s in scene.segments}
    links, bodies = params["hydraulic_machine"]["links"], params["hydraulic_machine"]["bodies"]
    np.testing.assert_allclose(seg["side_link"].length, links["side_link"]["length"], atol=1e-9)
    np.testing.assert_allclose(seg["h_link"].length, links["h_link"]["length"], atol=1e-9)
    # arm pin -> side-link pivot: the pivot's distance in the arm frame
    pivot = bodies["arm"]["pins"]["ilink_pin_on_arm"]
    np.testing.assert_allclose(seg["arm_1"].length, np.hypot(*pivot), atol=1e-9)
    pose = model.pose(D)
    np.testing.assert_allclose(scene.tool_point(), pose[:, :3], atol=1e-12)
    expected = quaternion_matrix(bucket_quaternion(D[:, 0], pose[:, 3]))
    np.testing.assert_allclose(scene.frames["bucket_tip"][:, :3, :3], expected, atol=1e-12)
    np.testing.assert_allclose(scene.frames["bucket"][:, :3, 3], model.pins(D)["bucket_pin"], atol=1e-12)
    boom = scene.frames["boom"]
    np.testing.assert_allclose(
        np.linalg.norm(model.pins(D)["arm_pin"] - boom[:, :3, 3], axis=-1),
        bodies["boom"]["pins"]["arm_pin"][0],
        atol=1e-9,
    )
    for pose4 in scene.frames.values():  # proper rotations
        np.testing.assert_allclose(np.linalg.det(pose4[:, :3, :3]), 1.0, atol=1e-12)


def test_cylinder_pose_turns_z_onto_the_segment() -> None:
    start = RNG.normal(size=(300, 3))
    d = RNG.normal(size=(300, 3))
    d[0], d[1], d[2] = [0, 0, -2.0], [0, 0, 3.0], [0, 0, 0]
    centre, q, length = cylinder_pose(start, start + d)
    np.testing.assert_allclose(centre, start + 0.5 * d)
    np.testing.assert_allclose(length, np.linalg.norm(d, axis=-1))
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0)
    z = quaternion_matrix(q)[..., :, 2]
    np.testing.assert_allclose(z[3:] * length[3:, None], d[3:], atol=1e-12)
    np.testing.assert_allclose(z[:2], [[0, 0, -1], [0, 0, 1]], atol=1e-12)


def test_solids_list_every_segment_and_sphere_once() -> None:
    m = machine("scara")
    model = m.model()
    scene = serial_scene(model, np.stack([middle_state(model)] * 3))
    parts = solids(scene)
    rows = len(scene.segments) + len(scene.spheres)
    assert parts.position.shape == (3, rows, 3) and parts.color.shape == (rows, 4)
    assert parts.cylinder.sum() == len(scene.segments)
    lengths = np.stack([s.length for s in scene.segments], -1)
    np.testing.assert_allclose(parts.scale[:, : len(scene.segments), 2], lengths)
    np.testing.assert_allclose(
        parts.scale[0, len(scene.segments) :, 0], [2 * s.radius for s in scene.spheres]
    )
