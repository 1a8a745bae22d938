"""Palletizer core: the reference note's home/P0 values, FK(IK) round trips over every branch,
the Jacobian against finite differences, eqs. (7)-(8) against the shared planar 2R solver, the
axis angles against their geometric meaning, the selection rule, every failure path, config."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manipulator_kinematics.compiled import enabled
from manipulator_kinematics.model import (
    IKStatus,
    RequestError,
    SerialModel,
    pose_matrix,
    quaternion_matrix,
    select,
)
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.planar import two_link_ik, wrap_angle
from manipulator_kinematics.registry import machine
from manipulator_kinematics.schema import ConfigError
from palletizer_kinematics.kinematics import (
    BRANCHES,
    HOME_DH,
    Palletizer,
    axis_from_dh,
    compiled_kernel,
    dh_from_axis,
)

DEG = math.pi / 180
RNG = np.random.default_rng(460)


@pytest.fixture(scope="module")
def model() -> Palletizer:
    return Palletizer.default()


def level_target(position, yaw) -> np.ndarray:
    """TCP poses (..., 4, 4) with the flange level: x6 at ``yaw``, z6 straight down."""
    position = np.asarray(position, dtype=float)
    yaw = np.broadcast_to(np.asarray(yaw, dtype=float), position.shape[:-1])
    target = np.zeros(position.shape[:-1] + (4, 4))
    c, s = np.cos(yaw), np.sin(yaw)
    target[..., 0, 0], target[..., 1, 0] = c, s
    target[..., 0, 1], target[..., 1, 1] = s, -c
    target[..., 2, 2] = -1.0
    target[..., :3, 3] = position
    target[..., 3, 3] = 1.0
    return target


def random_axes(model: Palletizer, n: int) -> np.ndarray:
    return RNG.uniform(model.limits.lower, model.limits.upper, size=(n, 4))


def test_home_is_p0_with_all_axis_angles_zero(model: Palletizer) -> None:
    # The note: P0 = (1505, 0, 1436) mm is the home pose with d1 = 742.5 mm; every axis angle 0.
    np.testing.assert_allclose(model.fkine(np.zeros(4)), level_target([1.505, 0.0, 1.436], 0.0), atol=1e-15)
    for variant in ("single", "double"):
        np.testing.assert_allclose(axis_from_dh(HOME_DH, variant), 0.0, atol=1e-15)
    solutions = model.solve_ik(level_target([1.505, 0.0, 1.436], 0.0))
    assert solutions.ok and BRANCHES[int(solutions.selected)] == "front_elbow_up"
    np.testing.assert_allclose(solutions.solution, 0.0, atol=1e-12)
    dh = model.solve_ik(level_target([1.505, 0.0, 1.436], 0.0), mode="dh").solution
    np.testing.assert_allclose(dh, [0.0, -90 * DEG, 90 * DEG, 0.0], atol=1e-12)


def test_passive_joint_and_level_flange(model: Palletizer) -> None:
    q = random_axes(model, 200)
    theta = model.dh_angles(q)
    rows = model.chain.row_variables(theta)
    np.testing.assert_allclose(rows[:, 3], -(theta[:, 1] + theta[:, 2]), atol=1e-15)
    pose = model.fkine(q)
    # eq. (2): z6 straight down, yaw = theta1 - theta5, TCP height independent of axes 1 and 6.
    np.testing.assert_allclose(pose[:, :3, 2], np.tile([0.0, 0.0, -1.0], (200, 1)), atol=1e-14)
    yaw = np.arctan2(pose[:, 1, 0], pose[:, 0, 0])
    np.testing.assert_allclose(wrap_angle(yaw - (theta[:, 0] - theta[:, 3])), 0.0, atol=1e-12)
    g = model.geometry
    z = g.d1 - g.a2 * np.sin(theta[:, 1]) - g.a3 * np.sin(theta[:, 1] + theta[:, 2]) - g.d6
    np.testing.assert_allclose(pose[:, 2, 3], z, atol=1e-14)


def test_frames_are_base_joints_and_tool(model: Palletizer) -> None:
    q = random_axes(model, 5)
    frames = model.frames(q)
    assert frames.shape == (5, 7, 4, 4)
    np.testing.assert_allclose(frames[:, 0], np.tile(np.eye(4), (5, 1, 1)))
    np.testing.assert_allclose(frames[:, -1], model.fkine(q), atol=1e-15)
    # Frame {2} sits on axis 2 at (a1, 0, d1) rotated by theta1.
    g = model.geometry
    np.testing.assert_allclose(
        frames[:, 2, :3, 3],
        np.stack([g.a1 * np.cos(q[:, 0]), g.a1 * np.sin(q[:, 0]), np.full(5, g.d1)], axis=-1),
        atol=1e-15,
    )


@pytest.mark.parametrize("variant", ["single", "double"])
def test_jacobian_against_finite_differences(variant: str) -> None:
    model = Palletizer.default(variant)
    h = 1e-6
    for q in random_axes(model, 20):
        jacobian = model.jacob0(q)
        pose = model.fkine(q)
        for i in range(4):
            step = np.zeros(4)
            step[i] = h
            plus, minus = model.fkine(q + step), model.fkine(q - step)
            linear = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
            w_hat = (plus[:3, :3] - minus[:3, :3]) / (2 * h) @ pose[:3, :3].T
            numeric = np.concatenate([linear, [w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]]])
            np.testing.assert_allclose(jacobian[:, i], numeric, atol=1e-8)


def test_task_jacobian_determinant_is_the_stated_singularity(model: Palletizer) -> None:
    # det of the (x, y, z, yaw) rows = -r a2 a3 sin(theta3): what `singular` thresholds.
    theta = model.dh_angles(random_axes(model, 100))
    jacobian = model.jacob0_dh(theta)[:, [0, 1, 2, 5], :]
    g = model.geometry
    pose = model.fkine_dh(theta)
    r = np.hypot(pose[:, 0, 3], pose[:, 1, 3]) * np.sign(model._radius(theta))
    np.testing.assert_allclose(np.linalg.det(jacobian), -r * g.a2 * g.a3 * np.sin(theta[:, 2]), atol=1e-12)


def test_every_candidate_reaches_the_target(model: Palletizer) -> None:
    q = random_axes(model, 2000)
    pose = model.fkine(q)
    solutions = model.solve_ik(pose, mode="dh")
    assert solutions.q.shape == (2000, 8, 4)
    exists = np.all(np.isfinite(solutions.q), axis=-1)
    assert exists[:, :2].all()  # the front arm reaches every pose it came from
    reached = model.fkine_dh(np.where(exists[..., None], solutions.q, 0.0))
    error = np.abs(reached - pose[:, None])[exists]
    assert error.max() < 1e-9
    # The generating configuration is among the candidates.
    theta = model.dh_angles(q)
    difference = np.abs(wrap_angle(solutions.q - theta[:, None, :]))
    assert np.all(np.nanmin(np.max(difference, axis=-1), axis=-1) < 1e-9)


@pytest.mark.parametrize("variant", ["single", "double"])
@pytest.mark.parametrize("compiled", [True, False])
def test_dh_answers_convert_to_the_axis_angles_checked_on_the_limits(variant: str, compiled: bool) -> None:
    # Issue 29 defect 7: mode dh gave atan2's D-H angles while the limits were checked on the
    # wrapped axis angles, so 255 of 1,993 candidates converted outside the limits (A3 -4.67 for
    # 1.61) and 12 SUCCESS answers were 2 pi off. Random targets in and beyond the reach, one by
    # one and in a batch: every dh candidate is axis_from_dh-exactly the axis candidate, its status
    # is the limit rule on that conversion, and it reaches the target (FK, independent of the IK).
    model = Palletizer.default(variant)
    if compiled:
        assert compiled_kernel(model, wait=True) is not None or not enabled()
    n = 3000
    lower, upper = model.limits.lower, model.limits.upper
    span = upper - lower
    axes = RNG.uniform(lower - 0.3 * span, upper + 0.3 * span, size=(n, 4))  # a third beyond a limit
    targets = model.fkine_dh(dh_from_axis(axes, variant))
    dh = model.solve_ik(targets, mode="dh", compiled=compiled)
    axis = model.solve_ik(targets, mode="axis", compiled=compiled)
    np.testing.assert_array_equal(dh.status, axis.status)
    exists = np.all(np.isfinite(dh.q), axis=-1)
    converted = axis_from_dh(dh.q[exists], variant)
    np.testing.assert_allclose(converted, axis.q[exists], rtol=0, atol=1e-12)
    inside = np.all((converted >= lower - 1e-10) & (converted <= upper + 1e-10), axis=-1)
    np.testing.assert_array_equal(inside, dh.status[exists] != IKStatus.JOINT_LIMITS)
    assert (~inside).sum() > 100 and inside.sum() > 1000  # both kinds are tested
    reached = model.fkine_dh(np.where(exists[..., None], dh.q, 0.0))
    assert np.abs(reached - targets[:, None])[exists].max() < 1e-9
    for i in range(0, n, 50):  # one target at a time: the single call's path
        one = model.solve_ik(targets[i], mode="dh", compiled=compiled)
        np.testing.assert_allclose(one.q, dh.q[i], rtol=0, atol=1e-12)


def test_round_trip_selects_the_generating_axis_angles(model: Palletizer) -> None:
    # Inside the limits the home elbow branch is selected; with the seed there, its flange turn too.
    q = random_axes(model, 2000)
    elbow_up = np.sin(model.dh_angles(q)[:, 2]) > model.singular_elbow
    q = q[elbow_up]
    solutions = model.solve_ik(model.fkine(q), seed=q)
    assert solutions.ok.all()
    np.testing.assert_allclose(solutions.solution, q, atol=1e-9)
    assert np.all(np.isin(solutions.selected, [0, 1]))


def test_eq8_matches_the_shared_planar_solver(model: Palletizer) -> None:
    # Independent: the planar 2R law-of-cosines solution for the wrist point in the arm's plane.
    g = model.geometry
    theta = model.dh_angles(random_axes(model, 500))
    p = model.fkine_dh(theta)[:, :3, 3]
    candidates = model.ik_dh(p, np.zeros(500))[0]
    x = np.hypot(p[:, 0], p[:, 1]) - g.a1 - g.a4
    z = p[:, 2] + g.d6 - g.d1
    planar = two_link_ik(x, z, g.a2, g.a3)
    # planar angles measured counter-clockwise in (rho, z): theta2 = -t1, theta3 = -t2.
    np.testing.assert_allclose(candidates[:, 0, 1], wrap_angle(-planar.theta1[:, 1]), atol=1e-9)
    np.testing.assert_allclose(candidates[:, 0, 2], -planar.theta2[:, 1], atol=1e-9)
    np.testing.assert_allclose(candidates[:, 2, 1], wrap_angle(-planar.theta1[:, 0]), atol=1e-9)
    np.testing.assert_allclose(candidates[:, 2, 2], -planar.theta2[:, 0], atol=1e-9)


def test_axis_angles_have_their_geometric_meaning(model: Palletizer) -> None:
    theta = model.dh_angles(random_axes(model, 300))
    frames = model.chain.fkine(theta, all_frames=True)
    axis2, elbow, wrist = frames[:, 2, :3, 3], frames[:, 3, :3, 3], frames[:, 4, :3, 3]
    heading = np.stack([np.cos(theta[:, 0]), np.sin(theta[:, 0])], axis=-1)
    lower, upper = elbow - axis2, wrist - elbow
    forward = lambda v: np.sum(v[:, :2] * heading, axis=-1)  # noqa: E731
    tilt = np.arctan2(forward(lower), lower[:, 2])  # lower arm from vertical, forward positive
    below = np.arctan2(-upper[:, 2], forward(upper))  # upper arm below horizontal
    single, double = axis_from_dh(theta, "single"), axis_from_dh(theta, "double")
    np.testing.assert_allclose(single[:, 1], tilt, atol=1e-12)
    np.testing.assert_allclose(double[:, 1], tilt, atol=1e-12)
    # Double: A3 = the upper arm against the base (its angle below horizontal).
    np.testing.assert_allclose(wrap_angle(double[:, 2] - below), 0.0, atol=1e-12)
    # Single: A3 = the upper arm against the lower arm: its clockwise turn (seen with forward to the
    # right, z up) from the lower arm's direction, 0 when perpendicular (home), down positive.
    cross = forward(lower) * upper[:, 2] - lower[:, 2] * forward(upper)
    clockwise = -np.arctan2(cross, forward(lower) * forward(upper) + lower[:, 2] * upper[:, 2])
    np.testing.assert_allclose(wrap_angle(single[:, 2] - (clockwise - math.pi / 2)), 0.0, atol=1e-12)
    np.testing.assert_allclose(wrap_angle(double[:, 2] - (single[:, 1] + single[:, 2])), 0.0, atol=1e-12)
    # A1 = slew, A6 = flange: yaw = A1 - A6 in both.
    yaw = np.arctan2(model.fkine_dh(theta)[:, 1, 0], model.fkine_dh(theta)[:, 0, 0])
    for axis in (single, double):
        np.testing.assert_allclose(wrap_angle(axis[:, 0] - axis[:, 3] - yaw), 0.0, atol=1e-12)


@pytest.mark.parametrize("variant", ["single", "double"])
def test_axis_dh_round_trip_both_directions(variant: str) -> None:
    axis = RNG.uniform(-3, 3, size=(7, 11, 4))
    np.testing.assert_allclose(axis_from_dh(dh_from_axis(axis, variant), variant), axis, atol=1e-14)
    theta = RNG.uniform(-3, 3, size=(50, 4))
    np.testing.assert_allclose(dh_from_axis(axis_from_dh(theta, variant), variant), theta, atol=1e-14)
    model = Palletizer.default(variant)
    np.testing.assert_allclose(model.dh_angles(model.axis_angles(theta)), theta, atol=1e-14)
    with pytest.raises(ValueError, match="unknown variant"):
        axis_from_dh(theta, "triple")


def test_both_variants_reach_the_same_pose(model: Palletizer) -> None:
    single, double = model.with_variant("single"), model.with_variant("double")
    theta = model.dh_angles(random_axes(model, 50))
    np.testing.assert_allclose(
        single.fkine(single.axis_angles(theta)), double.fkine(double.axis_angles(theta)), atol=1e-14
    )


def mixed_targets(model: Palletizer, n: int) -> np.ndarray:
    """Reachable poses, poses out of reach or out of the limits, tilted, not finite, not rigid."""
    targets = model.fkine(RNG.uniform(model.limits.lower - 0.3, model.limits.upper + 0.3, size=(n, 4)))
    kind = np.arange(n) % 10
    targets[kind == 1, :3, 3] *= 3.0  # out of reach
    targets[kind == 2, :3, 3] *= 0.05  # inside the folded arm or on axis 1
    targets[kind == 3, :3, :3] = targets[kind == 3, :3, :3] @ quaternion_matrix([0.0, 0.05, 0.0, 1.0])
    targets[kind == 4, 1, 3] = np.nan
    targets[kind == 5, 0, :3] *= 2.0  # not a rotation
    targets[kind == 6, :2, 3] = 0.0  # TCP on axis 1
    return targets


@pytest.mark.parametrize("variant", ["single", "double"])
def test_batch_equals_one_by_one(variant: str) -> None:
    # One target and a batch both run the compiled kernel once it is loaded (numpy until then):
    # the same results to the last bits (1e-12) either way.
    model = Palletizer.default(variant)
    targets = mixed_targets(model, 300).reshape(3, 100, 4, 4)
    seeds = RNG.uniform(model.limits.lower, model.limits.upper, size=(3, 100, 4))
    for options in (
        {},
        {"seed": seeds},
        {"seed": seeds[0, 0]},
        {"mode": "dh", "seed": model.dh_angles(seeds)},
        {"use_orientation": False, "seed": seeds},
        {"use_orientation": False},
        {"branch": "front_elbow_down"},
        {"branch": "back_elbow_up_outer", "seed": seeds},
    ):
        batch = model.solve_ik(targets, **options)
        assert batch.q.shape == (3, 100, 8, 4) and batch.selected.shape == (3, 100)
        assert len(set(batch.status.ravel().tolist())) == 5  # every status occurs
        seed = options.get("seed")
        for index in np.ndindex(3, 100):
            if seed is not None and seed.ndim > 1:
                options["seed"] = seed[index]
            one = model.solve_ik(targets[index], **options)
            np.testing.assert_allclose(one.q, batch.q[index], rtol=0, atol=1e-12)
            np.testing.assert_array_equal(one.status, batch.status[index])
            assert (int(one.selected), bool(one.tie)) == (int(batch.selected[index]), bool(batch.tie[index]))
            assert one.note() == batch.note(index)


@pytest.mark.skipif(not enabled(), reason="MK_COMPILED=0: the kernel is off")
@pytest.mark.parametrize("variant", ["single", "double"])
def test_compiled_kernel_equals_the_numpy_path(variant: str) -> None:
    # The kernel (one target per call, and its loop over a batch) against the numpy code (the
    # reference) on one batch: 6 x 2000
    # targets per variant, every status among them (singular: arm near stretched), seeded or not,
    # a requested branch, both modes.
    model = Palletizer.default(variant)
    assert compiled_kernel(model, wait=True) is not None
    n = 2000
    targets = mixed_targets(model, n)
    stretched = model.dh_angles(random_axes(model, n // 10))
    stretched[:, 2] = RNG.uniform(-0.02, 0.02, n // 10)
    targets[7::10] = model.fkine_dh(stretched)
    targets[8::10][::2, 2, 3] = np.inf
    seeds = RNG.uniform(model.limits.lower, model.limits.upper, size=(n, 4))
    for options in (
        {},
        {"seed": seeds},
        {"mode": "dh", "seed": model.dh_angles(seeds)},
        {"use_orientation": False, "seed": seeds},
        {"branch": "back_elbow_up"},
        {"branch": "front_elbow_down_outer", "seed": seeds, "mode": "dh"},
    ):
        numpy = model.solve_ik(targets, compiled=False, **options)
        assert set(numpy.status.ravel().tolist()) == set(range(5))  # every status occurs
        batch = model.solve_ik(targets, **options)
        np.testing.assert_allclose(batch.q, numpy.q, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(batch.status, numpy.status)
        np.testing.assert_array_equal(batch.selected, numpy.selected)
        np.testing.assert_array_equal(batch.tie, numpy.tie)
        seed = options.get("seed")
        for i in range(n):
            if seed is not None:
                options["seed"] = seed[i]
            one = model.solve_ik(targets[i], **options)
            np.testing.assert_allclose(one.q, numpy.q[i], rtol=0, atol=1e-12)
            np.testing.assert_array_equal(one.status, numpy.status[i])
            assert (int(one.selected), bool(one.tie)) == (int(numpy.selected[i]), bool(numpy.tie[i]))
            assert one.status.dtype == numpy.status.dtype and one.selected.shape == ()
        assert one.note() == numpy.note(n - 1)


def test_selection_is_the_shared_rule(model: Palletizer) -> None:
    # Independent: model.select (numpy) over the home elbow branch, then over every candidate.
    targets = mixed_targets(model, 2000)
    seeds = RNG.uniform(model.limits.lower, model.limits.upper, size=(2000, 4))
    home = np.array([b.startswith("front_elbow_up") for b in BRANCHES])
    for seed in (None, seeds):
        solutions = model.solve_ik(targets, seed=seed)
        status = solutions.status
        first, first_tie = select(solutions.q, np.where(home, status, IKStatus.UNREACHABLE), seed=seed)
        other, other_tie = select(solutions.q, solutions.status, seed=seed)
        np.testing.assert_array_equal(solutions.selected, np.where(first >= 0, first, other))
        np.testing.assert_array_equal(solutions.tie, np.where(first >= 0, first_tie, other_tie))
    # Two candidates exactly as far from the seed: a tie, reported.
    target = model.fkine(np.radians([10.0, 20.0, 30.0, 100.0]))
    between = np.radians([10.0, 20.0, 30.0, -80.0])  # 180 deg from A6 = 100 and -260
    assert model.solve_ik(target, seed=between).tie


def test_selection_prefers_home_elbow_then_seed_for_the_flange_turn(model: Palletizer) -> None:
    target = model.fkine(np.radians([10.0, 20.0, 30.0, 100.0]))
    free = model.solve_ik(target)
    # A6 = 100 and -260 deg are both inside +-300: the inner turn without a seed, else the seed's turn.
    assert free.valid[:2].all() and BRANCHES[int(free.selected)] == "front_elbow_up"
    np.testing.assert_allclose(free.solution[3], 100 * DEG, atol=1e-12)
    seeded = model.solve_ik(target, seed=np.radians([10.0, 20.0, 30.0, -250.0]))
    assert BRANCHES[int(seeded.selected)] == "front_elbow_up_outer"
    np.testing.assert_allclose(seeded.solution[3], -260 * DEG, atol=1e-12)
    assert seeded.ordered()[0] == 1 and "closest to the seed" in seeded.note()
    # A requested branch restricts the choice; an unknown one is a RequestError.
    outer = model.solve_ik(target, branch="front_elbow_up_outer")
    assert BRANCHES[int(outer.selected)] == "front_elbow_up_outer"
    assert BRANCHES[int(model.solve_ik(target, branch="front_elbow_up").selected)] == "front_elbow_up"
    with pytest.raises(RequestError, match="unknown branch"):
        model.solve_ik(target, branch="elbow_sideways")
    with pytest.raises(RequestError, match="unknown IK mode"):
        model.solve_ik(target, mode="cartesian")


def test_position_only_keeps_the_seed_yaw_or_home_yaw(model: Palletizer) -> None:
    q = np.radians([30.0, 10.0, 20.0, -15.0])
    target = model.fkine(q)
    tilted = target.copy()
    tilted[:3, :3] = np.eye(3)  # any orientation: ignored without use_orientation
    seeded = model.solve_ik(tilted, use_orientation=False, seed=q + 0.01 * np.array([1, 1, 1, 1]))
    np.testing.assert_allclose(seeded.solution, q, atol=1e-12)
    home = model.solve_ik(tilted, use_orientation=False)
    np.testing.assert_allclose(home.solution[3], home.solution[0], atol=1e-12)  # yaw 0: A6 = A1
    np.testing.assert_allclose(model.fkine(home.solution)[:3, 3], target[:3, 3], atol=1e-12)


def test_failures_have_status_and_reason_never_nan(model: Palletizer) -> None:
    mirrored = level_target([1.5, 0.0, 1.0], 0.0) @ np.diag([1.0, -1.0, 1.0, 1.0])  # det R = -1
    cases = {
        "far": (level_target([5.0, 0.0, 1.0], 0.0), IKStatus.UNREACHABLE, "beyond the stretched arm"),
        "limits": (level_target([-1.5, 0.0, 1.0], 0.0), IKStatus.JOINT_LIMITS, "axis_"),
        "nan": (level_target([np.nan, 0.0, 1.0], 0.0), IKStatus.INVALID, "not finite"),
        "tilted": (pose_matrix([1.5, 0.0, 1.0], [0.0, 0.1, 0.0, 1.0]), IKStatus.UNREACHABLE, "tilted"),
        "not a rotation": (np.diag([2.0, 1.0, 1.0, 1.0]), IKStatus.INVALID, "not a rotation"),
        "a reflection": (mirrored, IKStatus.INVALID, "not a rotation"),
    }
    for name, (target, status, text) in cases.items():
        solutions = model.solve_ik(target)
        assert not solutions.ok, name
        assert IKStatus(int(solutions.outcome)) is status, name
        assert text in solutions.note(), (name, solutions.note())
        assert np.all(np.isnan(solutions.solution)), name
    # Stretched arm: exactly reachable, singular. Double-variant A2 = 80 deg keeps the upper arm in line.
    stretched = np.radians([0.0, 80.0, -10.0, 0.0])
    assert abs(math.sin(model.dh_angles(stretched)[2])) < 1e-12
    singular = model.solve_ik(model.fkine(stretched))
    assert IKStatus(int(singular.outcome)) is IKStatus.SINGULAR and "singular" in singular.note()


def test_singular_status_is_the_singular_predicate(model: Palletizer) -> None:
    # The IK flags singular candidates from |sin theta3| and r of the target; `singular` computes
    # them from the candidate's angles. Targets spread over both thresholds.
    theta = model.dh_angles(random_axes(model, 3000))
    theta[:1000, 2] = RNG.uniform(-0.02, 0.02, 1000)  # arm near stretched
    targets = model.fkine_dh(theta)
    near_axis = targets[1000:2000, :2, 3]
    near_axis *= RNG.uniform(0.0, 0.02, (1000, 1)) / np.hypot(near_axis[:, 0], near_axis[:, 1])[:, None]
    solutions = model.solve_ik(targets, mode="dh")
    kept = (solutions.status == IKStatus.SUCCESS) | (solutions.status == IKStatus.SINGULAR)
    flagged = solutions.status[kept] == IKStatus.SINGULAR
    np.testing.assert_array_equal(flagged, model.singular(solutions.q[kept]))
    assert 100 < flagged.sum() < flagged.size - 100


def test_config_validation_names_the_key() -> None:
    section = load_parameters(config_path("irb460.yaml"))["palletizer"]
    for change, key in (
        ({"variant": "triple"}, "palletizer.variant"),
        ({"a2": -1.0}, "palletizer.a2"),
        ({"joint_min": [0.0, 0.0, 0.0, 0.0], "joint_max": [0.0, 1.0, 1.0, 1.0]}, "palletizer.joint_min[0]"),
        ({"joint_max": [4.0, 1.0, 1.0, 1.0]}, "palletizer.joint_max[0]"),
        ({"masses": {**section["masses"], "payload": -5.0}}, "palletizer.masses.payload"),
    ):
        with pytest.raises(ConfigError, match=key.replace("[", r"\[").replace("]", r"\]")):
            Palletizer.from_parameters({**section, **change})
    missing = dict(section)
    del missing["d6"]
    with pytest.raises(ConfigError, match=r"palletizer\.d6: missing"):
        Palletizer.from_parameters(missing)
    with pytest.raises(ConfigError, match="did you mean 'variant'"):
        Palletizer.from_parameters({**section, "varient": "single"})


def test_registered_as_a_serial_model() -> None:
    entry = machine("palletizer")
    model = entry.model()
    assert isinstance(model, SerialModel)
    assert model.joint_names == ("axis_1", "axis_2", "axis_3", "axis_6") and model.variant == "double"
    assert model.joint_names_for("dh") == ("theta1", "theta2", "theta3", "theta5")
    np.testing.assert_allclose(np.degrees(model.limits.lower), [-165, -40, -20, -300])
    np.testing.assert_allclose(np.degrees(model.limits.upper), [165, 85, 120, 300])
    assert set(entry.topics) == {"joint_states", "tool_pose", "tool_twist"}
    assert entry.forward_node == "palletizer_forward" and entry.analyse is not None


def test_yaw_quaternion_targets_round_trip(model: Palletizer) -> None:
    # The service path: a position and a quaternion of a level flange (x6 at yaw, z6 down = Rz(yaw) Rx(pi)).
    yaw = 25 * DEG
    quaternion = np.array([np.cos(yaw / 2), np.sin(yaw / 2), 0.0, 0.0])  # Rz(yaw) Rx(pi)
    target = pose_matrix([1.6, 0.4, 0.9], quaternion)
    np.testing.assert_allclose(target[:3, :3], level_target([0, 0, 0], yaw)[:3, :3], atol=1e-15)
    solution = model.solve_ik(target).solution
    np.testing.assert_allclose(model.fkine(solution), target, atol=1e-12)
