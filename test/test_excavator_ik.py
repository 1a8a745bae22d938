"""Excavator pose IK (excavator_kinematics.core.inverse) against independent checks: FK(IK) round trips
over 10^4 random states (the generating state among the solutions), eq. 3 of every open-chain
candidate, a multi-start bounded least-squares solve giving the same solution set, the stroke-box
boundary (a wider machine's states just outside), and one target = a batch of one (same bits)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from excavator_kinematics.core.inverse import (
    BRANCHES,
    compiled_kernel,
    open_chain_candidates,
    solve_pose,
    solve_position,
    stroke_margins,
)
from excavator_kinematics.core.kinematics import Excavator
from manipulator_kinematics.model import IKStatus, RequestError, matrix_quaternion, quaternion_matrix
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.planar import wrap_angle

EXC = Excavator.default()
LOWER, UPPER = EXC.joint_limits.lower, EXC.joint_limits.upper
SUCCESS, LIMITS, UNREACHABLE = IKStatus.SUCCESS, IKStatus.JOINT_LIMITS, IKStatus.UNREACHABLE


def random_states(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(LOWER, UPPER, (n, 4))


def pose_error(D: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """max |position error| (m) and |alpha error| (rad, wrapped) of pose(D) against Q."""
    got = EXC.pose(D)
    position = np.abs(got[..., :3] - Q[..., :3]).max(axis=-1)
    return np.maximum(position, np.abs(wrap_angle(got[..., 3] - Q[..., 3])))


def test_the_reference_state_is_the_selected_solution() -> None:
    D = EXC.limits.reference
    result = EXC.ik(EXC.pose(D))
    assert result.branches == BRANCHES
    np.testing.assert_allclose(result.solution, D, atol=1e-12)
    assert result.status.tolist() == [SUCCESS, UNREACHABLE, UNREACHABLE, UNREACHABLE]
    assert result.note() == "branch front_elbow_up (first valid in branch order)"


def test_round_trip_over_ten_thousand_random_states() -> None:
    D = random_states(10_000, 18)
    Q = EXC.pose(D)
    result = EXC.ik(Q)
    distance = np.abs(result.q - D[:, None, :]).max(axis=-1)
    generating = np.nanmin(np.where(result.valid, distance, np.inf), axis=-1)
    assert generating.max() < 1e-9, generating.max()  # the generating state is a valid candidate
    valid = result.q[result.valid]
    assert pose_error(valid, np.repeat(Q, result.valid.sum(axis=-1), axis=0)).max() < 1e-9
    # The rule without a seed picks the first valid branch; with the generating state as seed, it.
    assert np.all(result.selected == np.argmax(result.valid, axis=-1))
    seeded = EXC.ik(Q, seed=D)
    assert np.abs(seeded.solution - D).max() < 1e-9
    # Every status: the rest is either outside a stroke or has no geometric solution.
    assert set(np.unique(result.status)) <= {SUCCESS, LIMITS, UNREACHABLE}
    assert np.all(np.isnan(result.q[result.status == UNREACHABLE]).any(axis=-1))
    assert not np.any(EXC.joint_limits.within(result.q[result.status == LIMITS], 1e-10))


def test_every_open_chain_candidate_meets_eq_3_behind_the_swing_axis_too() -> None:
    Q = EXC.pose(random_states(2000, 3))
    theta, reach = open_chain_candidates(EXC, Q)
    found = reach == 0
    assert found[:, 2:].any()  # some targets have candidates with the tip behind (swing + pi)
    got = EXC.open_chain_pose(theta[found])
    expected = np.repeat(Q[:, None, :], 4, axis=1)[found]
    np.testing.assert_allclose(got[:, :3], expected[:, :3], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(got[:, 3] - expected[:, 3]), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.abs(wrap_angle(theta[:, 2:, 0] - theta[:, :2, 0])), math.pi, atol=1e-12)


def test_one_target_is_a_batch_of_one() -> None:
    """The numpy path (the reference; one target and a batch run the compiled kernel unless
    compiled=False)."""
    Q = EXC.pose(random_states(50, 5))
    batch = solve_pose(EXC, Q, compiled=False)
    for i in range(len(Q)):
        one = solve_pose(EXC, Q[i], compiled=False)
        assert np.array_equal(one.q, batch.q[i], equal_nan=True)
        assert np.array_equal(one.status, batch.status[i]) and int(one.selected) == batch.selected[i]
    free = EXC.position_ik(Q[:5, :3])
    for i in range(5):
        assert np.array_equal(solve_position(EXC, Q[i, :3], compiled=False).q, free.q[i], equal_nan=True)


def mixed_targets(n: int, seed: int) -> np.ndarray:
    """Reachable targets, random ones (mostly out of reach or outside a stroke), NaN ones and
    targets on the swing axis: every status."""
    rng = np.random.default_rng(seed)
    Q = np.concatenate(
        (
            EXC.pose(random_states(n // 2, seed)),
            np.column_stack(
                (
                    rng.uniform(-9, 9, (n - n // 2, 2)),
                    rng.uniform(-5, 7, n - n // 2),
                    rng.uniform(-np.pi, np.pi, n - n // 2),
                )
            ),
        )
    )
    Q[::997] = np.nan
    Q[5::1999, :2] = 0.0
    return Q


@pytest.mark.parametrize("n", [1_000, pytest.param(10_000, marks=pytest.mark.slow)])
def test_the_compiled_kernel_is_the_numpy_path_for_one_target(n: int) -> None:
    """ik_kernel (one target) against the vectorised numpy path over n targets (10^3; 10^4 in the
    slow tier), seeded and not and with a branch asked for: the same statuses and selections, D
    within 1e-12 (the kernel takes cos and sin from libm, the numpy path by the half-angle
    tangent)."""
    assert compiled_kernel(EXC, wait=True) is not None
    Q = mixed_targets(n, 31)
    seeds = random_states(len(Q), 32)
    for seed, branch in ((None, None), (seeds, None), (seeds, "front_elbow_down")):
        batch = EXC.ik(Q, seed=seed, branch=branch)
        assert {SUCCESS, LIMITS, UNREACHABLE, IKStatus.INVALID} <= set(np.unique(batch.status))
        for i in range(len(Q)):
            one = EXC.ik(Q[i], seed=None if seed is None else seed[i], branch=branch)
            np.testing.assert_allclose(one.q, batch.q[i], rtol=0.0, atol=1e-12)  # NaN where NaN
            assert np.array_equal(one.status, batch.status[i]), (i, one.status, batch.status[i])
            assert int(one.selected) == batch.selected[i] and bool(one.tie) == batch.tie[i], i
            if i % 50 == 0:  # the texts too (every status among them)
                assert one.note() == batch.note(i), (i, one.note(), batch.note(i))


def test_the_compiled_position_search_is_the_numpy_one() -> None:
    """Position only, one position through the kernel against the numpy search: the same statuses,
    the widest margins equal within 1e-9 and D within 1e-6 (the search resolves alpha to 2e-8 rad;
    near-equal margins may stop a refinement step apart)."""
    assert compiled_kernel(EXC, wait=True) is not None
    P = mixed_targets(300, 33)[:, :3]
    batch = EXC.position_ik(P)
    for i in range(len(P)):
        one = EXC.position_ik(P[i])
        assert np.array_equal(one.status, batch.status[i]), (i, one.status, batch.status[i])
        assert int(one.selected) == batch.selected[i]
        np.testing.assert_allclose(one.q, batch.q[i], rtol=0.0, atol=1e-6)
        np.testing.assert_allclose(stroke_margins(EXC, one.q), stroke_margins(EXC, batch.q[i]), atol=1e-9)


def numerical_solutions(Q: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Distinct D inside the limits with pose(D) = Q, by bounded least squares from every start."""

    def residual(D: np.ndarray) -> np.ndarray:
        error = EXC.pose(D) - Q
        error[3] = wrap_angle(error[3])
        return error

    found: list[np.ndarray] = []
    for start in starts:
        fit = least_squares(residual, start, bounds=(LOWER, UPPER), xtol=1e-15, ftol=1e-15, gtol=1e-15)
        if np.abs(fit.fun).max() < 1e-9 and not any(np.abs(fit.x - f).max() < 1e-6 for f in found):
            found.append(fit.x)
    return np.array(found).reshape(-1, 4)


@pytest.mark.slow
def test_a_numerical_solve_finds_the_same_solution_set() -> None:
    rng = np.random.default_rng(22)
    targets = np.concatenate(
        (
            EXC.pose(random_states(24, 7)),  # reachable, and random targets
            np.column_stack(
                (rng.uniform(-9, 9, (8, 2)), rng.uniform(-5, 7, 8), rng.uniform(-np.pi, np.pi, 8))
            ),
        )
    )
    lengths = random_states(4, 8)
    matched = closed_total = numeric_total = 0
    for Q in targets:
        closed = EXC.ik(Q)
        mine = closed.q[closed.valid]
        # Starts: random lengths at both headings of the tip (eq. 3 puts it in the boom plane).
        starts = np.concatenate([lengths.copy() for _ in range(2)])
        heading = math.atan2(Q[1], Q[0])
        starts[:, 0] = np.repeat([heading, wrap_angle(heading + math.pi)], len(lengths))
        theirs = numerical_solutions(Q, starts)
        closed_total += len(mine)
        numeric_total += len(theirs)
        for solution in theirs:
            assert np.abs(mine - solution).max(axis=-1).min(initial=np.inf) < 1e-6, (Q, solution, mine)
            matched += 1
        assert len(theirs) == len(mine), (Q, theirs, mine)
    print(
        f"\nsolution sets of {len(targets)} targets: closed form {closed_total}, least squares "
        f"{numeric_total}, matched {matched}"
    )
    assert matched == closed_total == numeric_total and closed_total >= 24


def test_a_bucket_length_maps_back_to_its_angle_over_the_whole_turn() -> None:
    """The inverse linkage keeps the forward model's assembly (side triangle and bucket four-bar):
    a length it gives for any theta4 inside the stroke gives that theta4 forward (it once gave
    lengths of the other assembly for angles beyond the stroke's range)."""
    theta4 = np.linspace(-np.pi, np.pi, 7201)
    angles = np.column_stack((np.full_like(theta4, 0.5), np.full_like(theta4, -1.5), theta4))
    lengths = EXC.linkage_lengths(angles)
    inside = (lengths[:, 2] >= LOWER[3]) & (lengths[:, 2] <= UPPER[3])
    assert 0.3 < inside.mean() < 0.8
    back = EXC.joint_angles(lengths[inside])
    np.testing.assert_allclose(wrap_angle(back[:, 2] - theta4[inside]), 0.0, atol=1e-9)


def test_the_stroke_box_boundary() -> None:
    sections = copy.deepcopy(load_parameters(config_path("excavator_cet200.yaml")))
    machine = sections["hydraulic_machine"]
    for name in ("boom_cylinder", "arm_cylinder", "bucket_cylinder"):
        machine["cylinders"][name]["min_length"] -= 0.05
        machine["cylinders"][name]["max_length"] += 0.05
    for joint in machine["chain"].values():  # the wider strokes turn the joints further
        joint["limits"] = [-np.pi, np.pi]
    wide = Excavator.from_parameters(sections)
    for i, name in enumerate(("boom_cylinder", "arm_cylinder", "bucket_cylinder"), start=1):
        for end, outward in ((UPPER[i], 1.0), (LOWER[i], -1.0)):
            D = EXC.limits.reference.copy()
            D[i] = end
            at_end = EXC.ik(wide.pose(D))
            assert at_end.ok and np.abs(at_end.solution - D).max() < 1e-9, (name, at_end.note())
            D[i] = end + outward * 1e-6
            outside = EXC.ik(wide.pose(D))
            assert not outside.ok and outside.status[0] == LIMITS, (name, outside.note())
            assert np.abs(outside.q[0] - D).max() < 1e-9
            side = "above" if outward > 0 else "below"
            assert f"{name} = " in outside.note() and f"{side} its limit" in outside.note(), outside.note()


def test_statuses_and_notes_of_targets_it_cannot_take() -> None:
    far = EXC.ik([15.0, 0.0, 1.0, 0.0])
    assert far.outcome == UNREACHABLE and "out of the boom and arm's reach" in far.note()
    # An arm bent the other way (theta3 > 0) exists for the open chain but not for the arm cylinder.
    Q = EXC.open_chain_pose([0.0, math.radians(10.0), math.radians(30.0), math.radians(-60.0)])
    bent = EXC.ik(Q)
    assert bent.status[1] == UNREACHABLE and "arm cylinder cannot close" in bent.note(), bent.note()
    nan = EXC.ik([math.nan, 0.0, 1.0, 0.0])
    assert (nan.status == IKStatus.INVALID).all() and not nan.ok
    with pytest.raises(RequestError, match="unknown branch 'up'"):
        EXC.ik([5.0, 0.0, 0.0, 0.0], branch="up")
    on_axis = EXC.ik([0.0, 0.0, 1.0, 0.0])
    assert on_axis.outcome >= IKStatus.SINGULAR


def test_position_only_takes_the_seed_angle_else_the_widest_stroke_margin() -> None:
    D = random_states(200, 9)
    Q = EXC.pose(D)
    seeded = EXC.position_ik(Q[:, :3], seed=D)
    assert np.abs(seeded.solution - D).max() < 1e-9
    free = EXC.position_ik(Q[:20, :3])
    assert free.ok.all()
    np.testing.assert_allclose(EXC.pose(free.solution)[:, :3], Q[:20, :3], atol=1e-9)

    def margin(D: np.ndarray) -> np.ndarray:
        lengths = D[..., 1:]
        return (np.minimum(lengths - LOWER[1:], UPPER[1:] - lengths) / (UPPER[1:] - LOWER[1:])).min(axis=-1)

    # No bucket angle on a fine grid gives the selected branch a wider margin (to 1e-5 of a stroke).
    for k in range(5):
        chosen = free.solution[k]
        alphas = np.linspace(-np.pi, np.pi, 20001)
        grid = EXC.ik(np.column_stack((np.tile(Q[k, :3], (len(alphas), 1)), alphas)))
        candidate = grid.q[:, int(free.selected[k])]
        best = np.nanmax(np.where(grid.valid[:, int(free.selected[k])], margin(candidate), np.nan))
        assert margin(chosen) >= best - 1e-5, (k, margin(chosen), best)


def test_fkine_jacob0_and_the_six_d_pose_solve() -> None:
    D = random_states(500, 11)
    D_dot = np.random.default_rng(12).normal(size=(500, 4)) * 0.1
    pose = EXC.fkine(D)
    state = EXC.state(D, D_dot)
    np.testing.assert_allclose(pose[:, :3, 3], state.Q[:, :3], atol=1e-12)
    from excavator_kinematics.core.kinematics import bucket_angular_velocity, bucket_quaternion

    np.testing.assert_allclose(
        pose[:, :3, :3], quaternion_matrix(bucket_quaternion(D[:, 0], state.Q[:, 3])), atol=1e-12
    )
    twist = np.einsum("nij,nj->ni", EXC.jacob0(D), D_dot)
    np.testing.assert_allclose(twist[:, :3], state.Q_dot[:, :3], atol=1e-12)
    np.testing.assert_allclose(
        twist[:, 3:], bucket_angular_velocity(D[:, 0], D_dot[:, 0], state.Q_dot[:, 3]), atol=1e-12
    )
    result = EXC.solve_ik(pose)
    assert result.ok.all() and np.abs(result.solution - D).max() < 1e-9
    assert np.all(result.status[:, 2:] == UNREACHABLE)  # the other heading is another orientation
    # Position mode of the protocol = position_ik; the modes refuse a contradicting orientation flag.
    np.testing.assert_array_equal(
        EXC.solve_ik(pose[:5], use_orientation=False, seed=D[:5]).solution,
        EXC.position_ik(pose[:5, :3, 3], seed=D[:5]).solution,
    )
    with pytest.raises(RequestError, match="use_orientation"):
        EXC.solve_ik(pose[0], use_orientation=False, mode="pose")
    with pytest.raises(RequestError, match="unknown mode"):
        EXC.solve_ik(pose[0], mode="sideways")
    # A rolled bucket frame or a position off the orientation's boom plane is refused, with why.
    rolled = pose[0].copy()
    rolled[:3, :3] = quaternion_matrix(matrix_quaternion(pose[0, :3, :3]) + [0.05, 0.0, 0.0, 0.0])
    assert "rolls the bucket" in EXC.solve_ik(rolled).note()
    shifted = pose[0].copy()
    shifted[:3, 3] += 0.01 * shifted[:3, 1]
    assert "off the boom plane" in EXC.solve_ik(shifted).note()
