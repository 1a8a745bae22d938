"""Tool changer (paper 003): FK against the note's pose, FK(IK) round trips, a numerical solver's
solution set, Jacobian vs central differences, selection rule, singular and failing targets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manipulator_kinematics.model import IKStatus, RequestError, SerialModel, quaternion_matrix
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.planar import wrap_angle
from manipulator_kinematics.schema import ConfigError
from tool_changer_kinematics.kinematics import BRANCHES, SECTION, ToolChanger

PI = math.pi
PAPER_Q = np.array([PI / 2, PI / 6, -PI / 3, PI / 3, PI / 2, 0.0])
# The note's pair of in-limit joint vectors that reach one pose (deg).
PAIR = np.radians(
    [[-11.06, 128.98, -82.79, 32.96, 82.48, -152.27], [168.94, 143.64, -80.26, 37.46, 97.52, 27.73]]
)


@pytest.fixture(scope="module")
def arm() -> ToolChanger:
    return ToolChanger.default()


def in_limits(arm: ToolChanger, n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(arm.limits.lower, arm.limits.upper, (n, 6))


def section() -> dict:
    return load_parameters(config_path("tool_changer.yaml"))[SECTION]


def numeric_jacobian(arm: ToolChanger, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of the tool position, and of R for the angular rows (w^ = dR/dq R^T)."""
    rotation = arm.fkine(q)[:3, :3]
    columns = []
    for i in range(6):
        step = np.zeros(6)
        step[i] = h
        plus, minus = arm.fkine(q + step), arm.fkine(q - step)
        w_hat = (plus[:3, :3] - minus[:3, :3]) / (2 * h) @ rotation.T
        angular = [w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]]
        columns.append(np.concatenate([(plus[:3, 3] - minus[:3, 3]) / (2 * h), angular]))
    return np.stack(columns, axis=1)


def test_the_note_verification_pose(arm: ToolChanger) -> None:
    T = arm.fkine(PAPER_Q)
    np.testing.assert_allclose(T[:3, :3], [[1, 0, 0], [0, -0.5, -0.866], [0, 0.866, -0.5]], atol=5e-4)
    np.testing.assert_allclose(T[:3, 3], [0.0, 1.0312, -0.0476], atol=5e-5)
    position, quaternion = arm.pose(PAPER_Q)
    np.testing.assert_allclose(quaternion_matrix(quaternion), T[:3, :3], atol=1e-12)
    np.testing.assert_allclose(position, T[:3, 3], atol=0)
    solutions = arm.solve_ik(T, seed=PAPER_Q)
    assert solutions.branches[int(solutions.selected)] == "front_up_noflip"
    np.testing.assert_allclose(solutions.solution, PAPER_Q, atol=1e-12)
    # theta4 = 60 deg is inside J4's [20, 65] deg stop: the only valid one of the 8 candidates.
    assert solutions.valid.sum() == 1 and not solutions.tie


def test_random_round_trips_recover_the_generating_vector(arm: ToolChanger) -> None:
    q = in_limits(arm, 10_000, 1)
    T = arm.fkine(q)
    solutions = arm.solve_ik(T)
    found = np.isfinite(solutions.q).all(axis=-1)
    assert found.sum(axis=-1).min() >= 2  # the generating vector and its shoulder twin at least
    reached = arm.fkine(np.where(found[..., None], solutions.q, 0.0))
    error = np.abs(reached - T[:, None]).max(axis=(-2, -1))
    assert np.where(found, error, 0.0).max() < 1e-9
    distance = np.abs(wrap_angle(solutions.q - q[:, None, :])).max(axis=-1)
    best = np.nanargmin(np.where(found, distance, np.inf), axis=-1)
    assert np.take_along_axis(distance, best[:, None], axis=-1).max() < 1e-7
    own_status = np.take_along_axis(solutions.status, best[:, None], axis=-1)[:, 0]
    assert set(np.unique(own_status)) <= {IKStatus.SUCCESS, IKStatus.SINGULAR}
    # Every candidate inside the limits is flagged so; every other has a failure status.
    inside = arm.limits.within(solutions.q, 1e-10)
    np.testing.assert_array_equal(solutions.status == IKStatus.JOINT_LIMITS, found & ~inside)
    np.testing.assert_array_equal(solutions.status == IKStatus.UNREACHABLE, ~found)


def test_joint4_stop_alone_does_not_make_the_solution_unique(arm: ToolChanger) -> None:
    """The note's check of the paper's claim: ~40 % of poses have two J4-admissible candidates."""
    q = in_limits(arm, 10_000, 2)
    solutions = arm.solve_ik(arm.fkine(q))
    j4 = solutions.q[..., 3]
    with np.errstate(invalid="ignore"):
        j4_ok = (j4 >= arm.limits.lower[3] - 1e-10) & (j4 <= arm.limits.upper[3] + 1e-10)
    fraction = float(np.mean(j4_ok.sum(axis=-1) >= 2))
    assert 0.3 < fraction < 0.5
    in_all = (solutions.status <= IKStatus.SINGULAR).sum(axis=-1)
    assert 0.95 < float(np.mean(in_all == 1)) < 1.0


@pytest.mark.slow
def test_solution_set_equals_a_numerical_solvers(arm: ToolChanger) -> None:
    """scipy least squares from 48 seeds per pose finds exactly the closed form's candidates (mod 2 pi)."""
    optimize = pytest.importorskip("scipy.optimize")
    rng = np.random.default_rng(3)
    for q in in_limits(arm, 4, 4):
        T = arm.fkine(q)

        def residual(x: np.ndarray, T: np.ndarray = T) -> np.ndarray:
            return (arm.fkine(x) - T)[:3].ravel()

        numeric = []
        for start in rng.uniform(-PI, PI, (48, 6)):
            fit = optimize.least_squares(residual, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
            if np.abs(fit.fun).max() < 1e-10:
                numeric.append(fit.x)
        numeric = np.array(numeric)
        candidates = arm.solve_ik(T).q
        candidates = candidates[np.isfinite(candidates).all(axis=-1)]
        near = np.abs(wrap_angle(numeric[:, None, :] - candidates[None])).max(axis=-1)  # (numeric, closed)
        assert near.min(axis=1).max() < 1e-6, "the numerical solver found a solution the closed form misses"
        assert near.min(axis=0).max() < 1e-6, "a closed-form candidate the numerical solver never reached"


def test_jacobian_matches_central_differences_with_a_tool(arm: ToolChanger) -> None:
    params = section()
    params["tool_xyz"], params["tool_rpy"] = [0.05, -0.02, 0.3], [0.3, -0.2, 1.1]
    tooled = ToolChanger.from_parameters(params)
    for model in (arm, tooled):
        for q in in_limits(model, 20, 5):
            np.testing.assert_allclose(model.jacob0(q), numeric_jacobian(model, q), atol=1e-8)
    q, qd = in_limits(tooled, 50, 6), np.random.default_rng(7).normal(size=(50, 6))
    twist = tooled.twist(q, qd)
    h = 1e-6
    dp = (tooled.fkine(q + h * qd)[:, :3, 3] - tooled.fkine(q - h * qd)[:, :3, 3]) / (2 * h)
    np.testing.assert_allclose(twist[:, :3], dp, atol=1e-8)


def test_tool_transform_round_trips(arm: ToolChanger) -> None:
    params = section()
    params["tool_xyz"], params["tool_rpy"] = [0.05, -0.02, 0.3], [0.3, -0.2, 1.1]
    tooled = ToolChanger.from_parameters(params)
    q = in_limits(tooled, 500, 8)
    solutions = tooled.solve_ik(tooled.fkine(q), seed=q)
    ok = solutions.ok
    assert ok.mean() > 0.9
    np.testing.assert_allclose(solutions.solution[ok], q[ok], atol=1e-7)
    frames = tooled.frames(q[0])
    assert frames.shape == (8, 4, 4)
    np.testing.assert_allclose(frames[-1], tooled.fkine(q[0]), atol=1e-15)
    np.testing.assert_allclose(frames[5, :3, 3], tooled.wrist_centre(q[0]), atol=1e-15)


def test_two_valid_solutions_are_both_returned_and_the_seed_decides(arm: ToolChanger) -> None:
    T = arm.fkine(PAIR[0])
    np.testing.assert_allclose(arm.fkine(PAIR[1]), T, atol=2e-4)  # the note's values are rounded to 0.01 deg
    for k in range(2):
        solutions = arm.solve_ik(T, seed=PAIR[k])
        valid = solutions.ordered()
        assert [BRANCHES[i] for i in valid][1:] == ["back_up_noflip" if k == 0 else "front_up_noflip"]
        assert len(valid) == 2 and not solutions.tie
        np.testing.assert_allclose(solutions.solution, PAIR[k], atol=2e-4)
    unseeded = arm.solve_ik(T)
    assert BRANCHES[int(unseeded.selected)] == "front_up_noflip" and "no seed" in unseeded.note()
    forced = arm.solve_ik(T, seed=PAIR[0], branch="back_up_noflip")
    np.testing.assert_allclose(forced.solution, PAIR[1], atol=2e-4)
    # A seed halfway between the two (in joint space) is a tie, and says so.
    tie = arm.solve_ik(arm.fkine(PAIR[0]), seed=arm.solve_ik(T).q[[0, 4]].mean(axis=0))
    assert tie.tie and "tie" in tie.note()


def test_wrist_singularity_keeps_the_seed_theta6(arm: ToolChanger) -> None:
    for q5 in (0.0, PI):
        q = np.array([0.4, 1.2, -1.0, 0.6, q5, 0.3])
        T = arm.fkine(q)
        for seed in (q, q + np.array([0.1, -0.1, 0.1, -0.1, 0.05, 0.1])):
            solutions = arm.solve_ik(T, seed=seed)
            found = np.isfinite(solutions.q).all(axis=-1)
            assert found.sum() >= 2
            reached = arm.fkine(solutions.q[found])
            np.testing.assert_allclose(reached, np.broadcast_to(T, (found.sum(), 4, 4)), atol=1e-9)
            np.testing.assert_allclose(wrap_angle(solutions.q[found, 5] - seed[5]), 0.0, atol=1e-9)
            assert not found[1::2].any()  # the flip branch is the same configuration: left empty
            assert int(solutions.selected) == -1 and solutions.status[0] == IKStatus.SINGULAR
            assert "wrist singularity" in solutions.note()
        np.testing.assert_allclose(arm.solve_ik(T, seed=q).q[0], q, atol=1e-9)


def test_wrist_centre_on_the_j1_axis_keeps_the_seed_theta1(arm: ToolChanger) -> None:
    # Boom angle that puts the wrist centre on the J1 axis (bisection on its horizontal distance).
    def horizontal(q2: float) -> float:
        w = arm.wrist_centre(np.array([0.0, q2, -1.0, 0.7, 1.2, 0.3]))
        return w[0]

    low, high = 0.0, 2.6
    for _ in range(80):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if horizontal(middle) > 0 else (low, middle)
    q = np.array([0.0, low, -1.0, 0.7, 1.2, 0.3])
    seed = np.array([0.8, low, -1.0, 0.7, 1.2, 0.3])
    T = arm.fkine(q)
    solutions = arm.solve_ik(T, seed=seed)
    found = np.isfinite(solutions.q).all(axis=-1)
    reached = arm.fkine(solutions.q[found])
    np.testing.assert_allclose(reached, np.broadcast_to(T, (found.sum(), 4, 4)), atol=1e-9)
    np.testing.assert_allclose(solutions.q[found[:4].nonzero()[0], 0], seed[0], atol=1e-12)
    assert int(solutions.selected) == -1 and "J1 axis" in solutions.note()


def test_failures_are_statuses_with_reasons(arm: ToolChanger) -> None:
    far = np.eye(4)
    far[:3, 3] = (5.0, 0.0, 0.0)
    solutions = arm.solve_ik(far)
    assert (solutions.status == IKStatus.UNREACHABLE).all() and int(solutions.selected) == -1
    assert "cannot reach" in solutions.note()
    assert np.isnan(solutions.solution).all()
    bad = np.stack([np.full((4, 4), np.nan), np.diag([1.0, 1.0, -1.0, 1.0]), 2 * np.eye(4)])
    invalid = arm.solve_ik(bad)
    assert (invalid.status == IKStatus.INVALID).all() and "rigid transform" in invalid.note(1)
    # J4 out of its stop on every candidate: JOINT_LIMITS, and the reason names the joint.
    q = np.array([0.3, 1.0, -1.2, 1.5, 1.0, 0.2])
    limited = arm.solve_ik(arm.fkine(q))
    assert int(limited.selected) == -1 and limited.outcome == IKStatus.JOINT_LIMITS
    assert "wrist_pitch_joint" in limited.note()
    with pytest.raises(RequestError, match="branch"):
        arm.solve_ik(far, branch="elbow_up")
    with pytest.raises(RequestError, match="mode"):
        arm.solve_ik(far, mode="numeric")


def test_batches_equal_single_targets_and_keep_their_shape(arm: ToolChanger) -> None:
    q = in_limits(arm, 12, 9).reshape(3, 4, 6)
    seeds = q + 0.05
    batch = arm.solve_ik(arm.fkine(q), seed=seeds, compiled=False)  # one state = a batch of one
    assert batch.q.shape == (3, 4, 8, 6) and batch.selected.shape == (3, 4)
    assert arm.solve_ik(arm.fkine(q), seed=seeds).q.shape == (3, 4, 8, 6)  # the kernel's loop
    for index in [(0, 0), (2, 3), (1, 2)]:
        single = arm.solve_ik(arm.fkine(q[index]), seed=seeds[index], compiled=False)  # the numpy path
        np.testing.assert_array_equal(single.q, batch.q[index])
        assert int(single.selected) == int(batch.selected[index])
    assert arm.twist(q, np.ones(6)).shape == (3, 4, 6) and arm.pose(q)[1].shape == (3, 4, 4)


def mixed_targets(arm: ToolChanger, n: int, seed: int) -> np.ndarray:
    """Tool poses with every status: reachable ones (in the limits and out of them), at the wrist
    singularity, with the wrist centre on the J1 axis, random ones (mostly out of reach), and ones
    that are not poses (NaN, inf, not rigid)."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(arm.limits.lower - 0.5, arm.limits.upper + 0.5, (n, 6))
    q[1::7, 4] = rng.choice([0.0, PI], len(q[1::7]))  # sin q5 = 0
    q[2::7, 4] = rng.normal(0.0, 0.01, len(q[2::7]))  # near it
    T = arm.fkine(q)
    random = slice(3, None, 7)
    T[random, :3, :3] = quaternion_matrix(rng.normal(size=(len(T[random]), 4)))
    T[random, :3, 3] = rng.uniform(-2.0, 2.0, (len(T[random]), 3))
    axis = slice(4, None, 7)  # the wrist centre on the J1 axis, exactly or nearly
    offset = rng.normal(0.0, 1e-3, (len(T[axis]), 2)) * rng.integers(0, 2, (len(T[axis]), 1))
    T[axis, :2, 3] = T[axis, :2, 2] * arm.d[5] + offset
    T[5::97, 0, 3] = np.nan
    T[6::97, 1, 1] = np.inf
    T[12::97, :3, :3] *= 1.01
    return T


@pytest.mark.parametrize(
    ("tooled", "n"), [(True, 2_000), (False, 2_000), pytest.param(False, 10_000, marks=pytest.mark.slow)]
)
def test_the_compiled_kernel_is_the_numpy_path_for_one_target(arm: ToolChanger, tooled: bool, n: int) -> None:
    """ik_kernel (one target, and its loop over a batch) against the vectorised numpy path over
    n targets (2,000; 10^4 in the slow tier), seeded and not and with a branch asked for: the same
    statuses, selections, ties and texts, q within 1e-12."""
    model = arm
    if tooled:
        params = section()
        params["tool_xyz"], params["tool_rpy"] = [0.05, -0.02, 0.3], [0.3, -0.2, 1.1]
        model = ToolChanger.from_parameters(params)
    assert model.compiled_kernel(wait=True) is not None
    T = mixed_targets(model, n, 41 + tooled)
    seeds = in_limits(model, len(T), 42)
    seen = set()
    for seed, branch in ((None, None), (seeds, None), (seeds, "back_down_flip")):
        batch = model.solve_ik(T, seed=seed, branch=branch, compiled=False)
        seen |= set(np.unique(batch.status).tolist())
        looped = model.solve_ik(T, seed=seed, branch=branch)
        np.testing.assert_allclose(looped.q, batch.q, rtol=0.0, atol=1e-12)
        for field in ("status", "selected", "tie"):
            np.testing.assert_array_equal(getattr(looped, field), getattr(batch, field))
        for i in range(len(T)):
            one = model.solve_ik(T[i], seed=None if seed is None else seed[i], branch=branch)
            np.testing.assert_allclose(one.q, batch.q[i], rtol=0.0, atol=1e-12)  # NaN where NaN
            assert np.array_equal(one.status, batch.status[i]), (i, one.status, batch.status[i])
            assert int(one.selected) == batch.selected[i] and bool(one.tie) == batch.tie[i], i
            if i % 20 == 0:  # the texts too (every status among them)
                assert one.note() == batch.note(i), (i, one.note(), batch.note(i))
    assert seen == {int(s) for s in IKStatus}
    # A seed halfway between two solutions: the tie, through the kernel too.
    tie = arm.solve_ik(arm.fkine(PAIR[0]), seed=arm.solve_ik(arm.fkine(PAIR[0])).q[[0, 4]].mean(axis=0))
    assert tie.tie and "tie" in tie.note()


def test_position_only_keeps_the_seed_orientation(arm: ToolChanger) -> None:
    q = in_limits(arm, 1, 10)[0]
    target = np.eye(4)
    target[:3, 3] = arm.fkine(q)[:3, 3] + (0.02, -0.03, 0.01)
    solutions = arm.solve_ik(target, use_orientation=False, seed=q)
    reached = arm.fkine(solutions.solution)
    np.testing.assert_allclose(reached[:3, 3], target[:3, 3], atol=1e-9)
    np.testing.assert_allclose(reached[:3, :3], arm.fkine(q)[:3, :3], atol=1e-9)


def test_config_is_validated_and_the_model_meets_the_protocol(arm: ToolChanger) -> None:
    assert isinstance(arm, SerialModel)
    assert arm.joint_names[0] == "slew_joint" and arm.limits.lower[3] == pytest.approx(math.radians(20))
    for key, value, match in (
        ("alpha", 0.5, r"tool_changer\.dh\.alpha\[1\]"),
        ("d", 0.1, r"tool_changer\.dh\.d\[2\]"),
        ("a", 0.1, r"tool_changer\.dh\.a\[4\]"),
    ):
        params = section()
        index = int(match[-3])
        params["dh"][key][index] = value
        with pytest.raises(ConfigError, match=match):
            ToolChanger.from_parameters(params)
    params = section()
    params["joint_min"][3] = 2.0
    with pytest.raises(ConfigError, match=r"joint_min\[3\]"):
        ToolChanger.from_parameters(params)
    params = section()
    params["dh"]["ofset"] = params["dh"].pop("offset")
    with pytest.raises(ConfigError, match="did you mean 'offset'"):
        ToolChanger.from_parameters(params)


def test_registered_machine_builds_the_model() -> None:
    from manipulator_kinematics.registry import machine

    entry = machine("tool_changer")
    model = entry.model()
    np.testing.assert_allclose(model.fkine(PAPER_Q), ToolChanger.default().fkine(PAPER_Q), atol=0)
    assert "tool_pose" in entry.topics
