"""SCARA core: the reference check values, FK vs the D-H chain, IK round trips in every mode,
branches, the position-mode rule against brute force, Jacobian and singularity, limits, config."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.planar import wrap_angle
from scara_kinematics.kinematics import BRANCHES, MODES, PAPER_PHI, IKStatus, Scara, compiled_kernel

DEG = math.pi / 180
N = 10_000


@pytest.fixture(scope="module")
def scara() -> Scara:
    return Scara.default()


def random_states(scara: Scara, rng: np.random.Generator, n: int) -> np.ndarray:
    """Joint states inside the limits and away from the singularity."""
    q = rng.uniform(scara.limits.lower, scara.limits.upper, (3 * n, 3))
    return q[~scara.singular(q)][:n]


def test_default_machine_is_the_reference(scara: Scara) -> None:
    assert (scara.l1, scara.l2, scara.l3) == (0.20, 0.30, 0.25)
    assert scara.joint_names == ("rail_joint", "shoulder_joint", "elbow_joint")
    np.testing.assert_allclose(scara.limits.lower, [0.0, -150 * DEG, -150 * DEG], atol=1e-15)
    np.testing.assert_allclose(scara.limits.upper, [0.40, 150 * DEG, 150 * DEG], atol=1e-15)
    assert scara.singularity_threshold == 0.01


def test_reference_check_values(scara: Scara) -> None:
    x = scara.fk([0.1, 30 * DEG, 60 * DEG])
    np.testing.assert_allclose(x, [0.559808, 0.40, 90 * DEG], atol=5e-7)
    assert x[0] == pytest.approx(0.2 + 0.1 + 0.3 * math.cos(30 * DEG), abs=1e-15)
    for mode in MODES:
        result = scara.ik(x[:2], mode=mode, phi=x[2] if mode == "phi" else None)
        assert result.status == IKStatus.SUCCESS, result.reason()
        np.testing.assert_allclose(result.q, [0.1, 30 * DEG, 60 * DEG], atol=1e-12)


def test_fixed_phi_is_the_papers_equation_12(scara: Scara) -> None:
    rng = np.random.default_rng(12)
    p = np.column_stack([rng.uniform(0.2, 0.7, 500), rng.uniform(0.0, 0.5, 500)])
    result = scara.ik(p, mode="fixed_phi")
    theta1 = np.arcsin((p[:, 1] - scara.l3) / scara.l2)
    expected = np.column_stack([p[:, 0] - scara.l1 - scara.l2 * np.cos(theta1), theta1, PAPER_PHI - theta1])
    np.testing.assert_allclose(result.candidates[:, 0], expected, atol=1e-12)


def test_fk_equals_the_dh_chain(scara: Scara) -> None:
    q = np.random.default_rng(2).uniform([-1, -math.pi, -math.pi], [1, math.pi, math.pi], (2000, 3))
    T = scara.chain.fkine(q)
    x = scara.fk(q)
    np.testing.assert_allclose(T[:, :2, 3], x[:, :2], atol=1e-14)
    np.testing.assert_allclose(T[:, 2, 3], 0.0, atol=1e-14)
    np.testing.assert_allclose(T[:, 2, 2], 1.0, atol=1e-14)  # tool z stays up (REP 103)
    np.testing.assert_allclose(np.arctan2(T[:, 1, 0], T[:, 0, 0]), x[:, 2], atol=1e-12)


def test_protocol_fk_frames_and_jacobian_are_the_shared_chains(scara: Scara) -> None:
    """The SerialModel protocol's closed forms (fkine, jacob0) equal the D-H chain's generic ones."""
    q = np.random.default_rng(4).uniform([-1, -math.pi, -math.pi], [1, math.pi, math.pi], (2000, 3))
    np.testing.assert_allclose(scara.fkine(q), scara.chain.fkine(q), atol=1e-14)
    np.testing.assert_allclose(scara.jacob0(q), scara.chain.jacob0(q), atol=1e-14)
    frames = scara.frames(q)
    assert frames.shape == (2000, 5, 4, 4)
    np.testing.assert_allclose(frames[:, -1], scara.fkine(q), atol=0)
    np.testing.assert_allclose(frames[:, :4], scara.chain.fkine(q, all_frames=True), atol=0)


def test_protocol_solve_ik_returns_the_generating_state_among_its_solutions(scara: Scara) -> None:
    rng = np.random.default_rng(5)
    q = rng.uniform(scara.limits.lower, scara.limits.upper, (3000, 3))
    q = q[~scara.singular(q)]
    solutions = scara.solve_ik(scara.fkine(q))
    assert solutions.q.shape == (len(q), 2, 3) and solutions.branches == ("elbow_a", "elbow_b")
    error = np.abs(solutions.q - q[:, None, :]).max(axis=-1)
    found = np.min(np.where(solutions.valid, error, np.inf), axis=-1)
    assert np.all(found < 1e-9)
    np.testing.assert_allclose(scara.fkine(solutions.solution), scara.fkine(q), atol=1e-12)
    seeded = scara.solve_ik(scara.fkine(q), seed=q)
    np.testing.assert_allclose(seeded.solution, q, atol=1e-9)  # the seed picks the generating branch
    off_plane = scara.fkine(q[0]) @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.1], [0, 0, 0, 1.0]])
    refused = scara.solve_ik(off_plane)
    assert not refused.ok and "z = 0.1 m" in refused.note()


def test_jacobian_against_chain_and_finite_differences(scara: Scara) -> None:
    rng = np.random.default_rng(3)
    q = rng.uniform([-1, -math.pi, -math.pi], [1, math.pi, math.pi], (500, 3))
    J = scara.jacobian(q)
    np.testing.assert_allclose(J, scara.chain.jacob0(q)[:, [0, 1, 5], :], atol=1e-14)
    h = 1e-6
    for i in range(3):
        step = np.zeros(3)
        step[i] = h
        difference = scara.fk(q + step) - scara.fk(q - step)
        difference[:, 2] = wrap_angle(difference[:, 2])
        np.testing.assert_allclose(difference / (2 * h), J[:, :, i], atol=1e-8)
    np.testing.assert_allclose(np.linalg.det(J), scara.l2 * np.cos(q[:, 1]), atol=1e-14)
    np.testing.assert_allclose(scara.manipulability(q), np.linalg.det(J), atol=1e-14)


def test_velocity_ik_inverts_velocity_fk(scara: Scara) -> None:
    rng = np.random.default_rng(4)
    q = random_states(scara, rng, 5000)
    xd = rng.normal(size=(len(q), 3))
    solution = scara.velocity_ik(q, xd)
    assert not solution.singular.any()
    np.testing.assert_allclose(scara.velocity_fk(q, solution.qd), xd, atol=1e-8)
    direct = np.linalg.solve(scara.jacobian(q), xd[..., None])[..., 0]
    np.testing.assert_allclose(solution.qd, direct, atol=1e-8)


def test_singularity_detection(scara: Scara) -> None:
    # |cos theta1| < 0.01 <=> theta1 within 0.573 deg of +-90 deg: 89.5 deg is singular, 89.4 deg is not.
    q = np.array([[0.1, 90 * DEG, 0.0], [0.1, -89.5 * DEG, 0.3], [0.1, 89.4 * DEG, 0.0], [0.1, 0.0, 0.0]])
    np.testing.assert_array_equal(scara.singular(q), [True, True, False, False])
    solution = scara.velocity_ik(q, np.ones((4, 3)))
    np.testing.assert_array_equal(solution.singular, [True, True, False, False])
    assert np.isnan(solution.qd[:2]).all() and np.isfinite(solution.qd[2:]).all()


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seeded", [False, True])
def test_ik_round_trip_over_random_reachable_targets(scara: Scara, mode: str, seeded: bool) -> None:
    rng = np.random.default_rng(2 * MODES.index(mode) + seeded)
    q = random_states(scara, rng, 3 * N)
    if mode == "fixed_phi":  # targets the paper's arm can reach with theta1 + theta2 = 90 deg
        q[:, 2] = PAPER_PHI - q[:, 1]
        q = q[scara.within_limits(q) & ~scara.singular(q)]
    q = q[:N]
    assert len(q) == N
    x = scara.fk(q)
    seed = rng.uniform(scara.limits.lower, scara.limits.upper, (N, 3)) if seeded else None
    result = scara.ik(x[:, :2], mode=mode, phi=x[:, 2] if mode == "phi" else None, seed=seed)
    assert result.ok.all(), result.reason(int(np.argmin(result.ok)))
    np.testing.assert_allclose(scara.fk(result.q)[:, :2], x[:, :2], atol=1e-9, rtol=0)
    assert scara.within_limits(result.q).all() and not scara.singular(result.q).any()
    if mode != "position":
        np.testing.assert_allclose(wrap_angle(scara.fk(result.q)[:, 2] - x[:, 2]), 0.0, atol=1e-12)
    # Every branch flagged valid is a solution too, and the sampled state is among them.
    valid = result.valid
    both = valid.all(axis=1)
    assert both.sum() > N // 20
    for b in range(2):
        reached = scara.fk(result.candidates[valid[:, b], b])[:, :2]
        np.testing.assert_allclose(reached, x[valid[:, b], :2], atol=1e-9, rtol=0)
    if mode != "position":
        found = np.abs(result.candidates - q[:, None, :]).max(axis=-1) < 1e-9
        assert np.all(found.any(axis=1))


# Every kind of target occurs in 10^3 (the fast tier); 10^4 finds the rare ties and bands.
@pytest.mark.parametrize("n", [1_000, pytest.param(N, marks=pytest.mark.slow)])
def test_the_compiled_kernel_is_the_numpy_path_for_one_target(scara: Scara, n: int) -> None:
    """ik_kernel (one target, every mode) against the vectorised numpy path over 10^4 targets,
    seeded and not and with a branch asked for: the same statuses, selections and ties, headings
    and candidates within 1e-12, the same texts; reachable, singular, off-limits, unreachable and
    non-finite targets among them, targets from states with a joint at a limit, around the band
    |py| = l2 + l3 (singular in mode position, or out of reach), and seeds halfway between two
    solutions (ties; in mode position their heading is the preferred one)."""
    assert compiled_kernel(scara, wait=True) is not None
    rng = np.random.default_rng(22)
    x = scara.fk(random_states(scara, rng, n // 2))
    wide = np.column_stack(
        [
            rng.uniform(-0.6, 1.4, n - n // 2),
            rng.uniform(-0.9, 0.9, n - n // 2),
            rng.uniform(-math.pi, math.pi, n - n // 2),
        ]
    )
    x = np.concatenate([x, wide])
    near_vertical = scara.l2 * rng.uniform(0.99995, 1.0, len(x[3::50]))  # sin theta1 ~ 1: singular
    x[3::50, 1] = scara.l3 * np.sin(x[3::50, 2]) + near_vertical
    x[4::50, 1] = scara.l3 + near_vertical  # singular at phi = 90 deg (mode fixed_phi) and in mode position
    x[5::50, 1] = -scara.l3 - scara.l2 * rng.uniform(0.9999, 1.00001, len(x[5::50]))  # band edges, position
    at_limit = random_states(scara, rng, len(x[6::50]))
    joint = rng.integers(0, 3, len(at_limit))
    at_limit[np.arange(len(at_limit)), joint] = np.where(
        rng.random(len(at_limit)) < 0.5, scara.limits.lower[joint], scara.limits.upper[joint]
    )
    x[6::50] = scara.fk(at_limit)
    x[::997, 0] = np.nan
    x[500::997, 1] = np.inf
    seeds = rng.uniform(scara.limits.lower, scara.limits.upper, (n, 3))
    both = scara.ik(x[:, :2], mode="phi", phi=x[:, 2])
    ties = np.flatnonzero(both.valid.all(axis=1))[::10]  # seeded halfway between two solutions
    seeds[ties] = both.candidates[ties].mean(axis=1)
    seeds[4::100, 2] = PAPER_PHI - seeds[4::100, 1]  # mode position in the singular band: stays singular
    for mode, seed, branch in (
        ("phi", None, None),
        ("phi", seeds, None),
        ("phi", seeds, "elbow_b"),
        ("fixed_phi", seeds, None),
        ("position", None, None),
        ("position", None, "elbow_b"),
        ("position", seeds, None),
        ("position", seeds, "elbow_a"),
    ):
        phi = x[:, 2] if mode == "phi" else None
        batch = scara.ik(x[:, :2], mode=mode, phi=phi, seed=seed, branch=branch)
        seen = set(np.unique(batch.branch_status).tolist()) | set(np.unique(batch.status).tolist())
        assert seen == set(range(5)), seen
        for i in range(n):
            one = scara.ik(
                x[i, :2],
                mode=mode,
                phi=None if phi is None else phi[i],
                seed=None if seed is None else seed[i],
                branch=branch,
            )
            np.testing.assert_allclose(one.candidates, batch.candidates[i], rtol=0.0, atol=1e-12)
            np.testing.assert_allclose(
                [one.phi, one.preferred_phi], [batch.phi[i], batch.preferred_phi[i]], rtol=0.0, atol=1e-12
            )
            assert np.array_equal(one.branch_status, batch.branch_status[i]), i
            assert one.status == batch.status[i] and one.solutions.tie == batch.solutions.tie[i], i
            # A tie is decided by the last bits of two equal distances: either tied branch is right.
            assert one.branch == batch.branch[i] or (one.solutions.tie and one.valid.all()), i
            if i % 50 == 0:
                assert one.reason() == batch.reason(i), (i, one.reason(), batch.reason(i))
        assert batch.solutions.tie.any() == (mode != "fixed_phi" and seed is not None and branch is None)
        if mode == "position":  # the rule moved the heading for some targets and kept it for others
            moved = np.abs(wrap_angle(batch.phi - batch.preferred_phi)) > 1e-6
            assert 0 < np.sum(moved & batch.ok) < np.sum(batch.ok)


def test_both_branches_when_both_are_valid(scara: Scara) -> None:
    q_a = np.array([0.05, 70 * DEG, 20 * DEG])
    x = scara.fk(q_a)
    result = scara.ik(x[:2], mode="fixed_phi")
    assert result.valid.tolist() == [True, True]
    q_b = [0.05 + 2 * scara.l2 * math.cos(70 * DEG), 110 * DEG, -20 * DEG]
    np.testing.assert_allclose(result.candidates, [q_a, q_b], atol=1e-12)
    assert math.cos(result.candidates[0, 1]) > 0 > math.cos(result.candidates[1, 1])
    assert BRANCHES[int(result.branch)] == "elbow_a"  # no seed: the paper's branch
    near_b = scara.ik(x[:2], mode="fixed_phi", seed=[0.3, 100 * DEG, -10 * DEG])
    assert int(near_b.branch) == 1
    np.testing.assert_allclose(near_b.q, q_b, atol=1e-12)
    forced = scara.ik(x[:2], mode="fixed_phi", branch="elbow_b", seed=q_a)
    np.testing.assert_allclose(forced.q, q_b, atol=1e-12)


def test_requested_branch_that_fails_reports_its_own_reason(scara: Scara) -> None:
    x = scara.fk([0.1, 30 * DEG, 60 * DEG])  # elbow_b would need the rail at 0.62 m
    result = scara.ik(x[:2], mode="fixed_phi", branch="elbow_b")
    assert result.status == IKStatus.JOINT_LIMITS and np.isnan(result.q).all() and result.branch == -1
    assert "elbow_b: rail_joint = 0.619615 m above its limit 0.4 m" in result.reason()
    assert "elbow_a" not in result.reason()


def test_position_mode_keeps_the_seed_heading_when_admissible(scara: Scara) -> None:
    seed = np.array([0.2, 20 * DEG, 50 * DEG])
    target = scara.fk([0.15, 40 * DEG, 30 * DEG])[:2]
    result = scara.ik(target, mode="position", seed=seed)
    assert result.ok and result.phi == pytest.approx(70 * DEG, abs=1e-12)
    np.testing.assert_allclose(result.q, [0.15, 40 * DEG, 30 * DEG], atol=1e-12)
    assert "kept the seed's heading" in result.reason()
    unseeded = scara.ik(target, mode="position")
    assert unseeded.ok and unseeded.phi == pytest.approx(PAPER_PHI, abs=1e-12)


def test_position_mode_moves_the_heading_as_little_as_possible(scara: Scara) -> None:
    rng = np.random.default_rng(9)
    q = random_states(scara, rng, 300)
    targets = scara.fk(q)[:, :2]
    seeds = rng.uniform(scara.limits.lower, scara.limits.upper, (300, 3))
    result = scara.ik(targets, mode="position", seed=seeds)
    assert result.ok.all()
    preferred = wrap_angle(seeds[:, 1] + seeds[:, 2])
    moved = np.abs(wrap_angle(result.phi - preferred))
    assert (moved > 1e-6).sum() > 50  # the rule had to move the heading for many of them
    # Brute force: admissible headings on a fine grid are never closer to the preferred one.
    grid = np.linspace(-math.pi, math.pi, 7201)
    for i in range(len(targets)):
        scan = scara.ik(np.broadcast_to(targets[i], (grid.size, 2)), mode="phi", phi=grid)
        best = np.min(np.abs(wrap_angle(grid[scan.ok] - preferred[i])))
        assert moved[i] <= best + 1e-9
        assert moved[i] >= best - 2 * math.pi / 7200  # and the grid finds one about as close
    # A moved heading sits on a constraint: a joint at a limit or |cos theta1| at the threshold.
    on_edge = moved > 1e-6
    q_moved = result.q[on_edge]
    at_limit = np.isclose(q_moved, scara.limits.lower, atol=1e-9) | np.isclose(
        q_moved, scara.limits.upper, atol=1e-9
    )
    at_singular = np.isclose(np.abs(np.cos(q_moved[:, 1])), scara.singularity_threshold, atol=1e-9)
    assert np.all(at_limit.any(axis=1) | at_singular)


def test_position_mode_takes_the_first_of_two_equally_near_headings(scara: Scara) -> None:
    """Mirror images: with symmetric shoulder and elbow limits, an unseeded target whose 90 deg heading
    needs the elbow beyond a limit can have two admissible headings equally near 90 deg, 90 deg -+ d
    (elbow at +150 deg on branch a, at -150 deg on branch b); which one is nearer is then up to the last
    bits of arctan2. Both paths take the first candidate (HEADING_TIE): the elbow at its upper limit."""
    assert compiled_kernel(scara, wait=True) is not None
    target = np.array([0.4361529, -0.05390288])
    for compiled in (True, False):
        result = scara.ik(target, mode="position", compiled=compiled)
        assert result.ok and int(result.branch) == 0 and result.phi < PAPER_PHI, result.reason()
        assert result.q[2] == pytest.approx(scara.limits.upper[2], abs=1e-12)
        mirror = scara.ik(target, mode="phi", phi=math.pi - result.phi)  # the other one, as near
        assert mirror.ok and int(mirror.branch) == 1, mirror.reason()
        assert mirror.q[2] == pytest.approx(scara.limits.lower[2], abs=1e-12)


def test_failures_say_why(scara: Scara) -> None:
    cases = {
        "unreachable": ([0.3, 0.9], "fixed_phi", IKStatus.UNREACHABLE, "out of the upper arm's reach"),
        "limits": (
            [1.3, 0.4],
            "fixed_phi",
            IKStatus.JOINT_LIMITS,
            "rail_joint = 0.840192 m above its limit 0.4 m",
        ),
        "singular": ([0.5, 0.55], "fixed_phi", IKStatus.SINGULAR, "|cos theta1|"),
        "nan": ([np.nan, 0.2], "fixed_phi", IKStatus.INVALID, "not finite"),
        "position far": ([0.3, 0.6], "position", IKStatus.UNREACHABLE, "farther than l2 + l3 = 0.55 m"),
        "position rail": ([1.5, 0.1], "position", IKStatus.JOINT_LIMITS, "rail_joint"),
        "position singular": ([0.5, 0.54999], "position", IKStatus.SINGULAR, "|cos theta1|"),
    }
    targets = np.array([c[0] for c in cases.values()])
    for mode in ("fixed_phi", "position"):
        batch = scara.ik(targets, mode=mode)
        for i, (target, case_mode, status, text) in enumerate(cases.values()):
            if case_mode == mode:
                assert batch.status[i] == status, (target, batch.reason(i))
                assert text in batch.reason(i)
                assert np.isnan(batch.q[i]).all()


def test_phi_mode_with_a_heading_outside_the_limits(scara: Scara) -> None:
    # Heading 180 deg at a point straight ahead needs theta2 beyond 150 deg on both branches.
    x = scara.fk([0.2, 0.0, 0.0])
    result = scara.ik(x[:2], mode="phi", phi=math.pi)
    assert result.status == IKStatus.JOINT_LIMITS
    assert "elbow_joint" in result.reason()


def test_invalid_arguments(scara: Scara) -> None:
    with pytest.raises(ValueError, match="unknown IK mode"):
        scara.ik([0.5, 0.2], mode="nope")
    with pytest.raises(ValueError, match="unknown branch"):
        scara.ik([0.5, 0.2], mode="position", branch="up")
    with pytest.raises(ValueError, match="phi"):
        scara.ik([0.5, 0.2], mode="phi")
    with pytest.raises(ValueError, match="phi"):
        scara.ik([0.5, 0.2], mode="position", phi=0.3)
    with pytest.raises(ValueError, match="seed"):
        scara.ik([0.5, 0.2], mode="position", seed=[0.1, np.nan, 0.0])


def test_limit_checks(scara: Scara) -> None:
    q = np.array(
        [[0.41, 0.0, 0.0], [-0.01, 0.0, 0.0], [0.2, -151 * DEG, 0.0], [0.2, 0.0, 150 * DEG], [0.4, 0.0, 0.0]]
    )
    np.testing.assert_array_equal(
        scara.limit_violation(q), [[1, 0, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 0], [0, 0, 0]]
    )
    np.testing.assert_array_equal(scara.within_limits(q), [False, False, False, True, True])


# ---- configuration ------------------------------------------------------------------------------
def reference_parameters() -> dict:
    return load_parameters(config_path("scara.yaml"))["scara"]


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (lambda p: p.pop("l2"), "scara.l2: missing"),
        (lambda p: p.update(l3=-0.25), "scara.l3 = -0.25 is outside (0, 100] (m)"),
        (lambda p: p.update(l1=-0.1), "scara.l1 = -0.1 is outside [0, 100] (m)"),
        (lambda p: p.update(l2="0.3"), "scara.l2: expected a number (m), got '0.3'"),
        (lambda p: p.update(l2=True), "scara.l2: expected a number (m), got True"),
        (lambda p: p.update(l2=1e300), "scara.l2 = 1e+300 is outside (0, 100] (m)"),
        (lambda p: p.update(l22=0.3), "scara.l22: unknown key (did you mean 'l2'?)"),
        (
            lambda p: p.update(joint_min=[0.5, -2.0, -2.0]),
            "scara.joint_min[0]: 0.5 must be below scara.joint_max[0] = 0.4",
        ),
        (lambda p: p.update(joint_max=[0.4, 200.0, 2.0]), "scara.joint_max[1]: 200.0 rad"),
        (lambda p: p.update(joint_max=[0.4, 2.0]), "scara.joint_max: expected 3 numbers"),
        (
            lambda p: p.update(joint_min=[0.0, float("nan"), -2.0]),
            "scara.joint_min[1]: expected a finite number",
        ),
        (lambda p: p.update(joint_names=["a", "a", "b"]), "scara.joint_names"),
        (lambda p: p.pop("singularity_threshold"), "scara.singularity_threshold: missing"),
        (
            lambda p: p.update(singularity_threshold=1.5),
            "scara.singularity_threshold = 1.5 is outside [0, 1]",
        ),
        (lambda p: p.update(singularity_threshold=1.0), "scara.singularity_threshold: 1.0 must be below 1"),
    ],
)
def test_config_errors_name_the_key(change, key: str) -> None:
    params = reference_parameters()
    change(params)
    with pytest.raises(ConfigError) as error:
        Scara.from_parameters(params)
    assert key in str(error.value)


def test_a_users_params_file_is_loaded(tmp_path: Path) -> None:
    document = {
        "/**": {"ros__parameters": {"scara": {**reference_parameters(), "l2": 0.35}}},
        "scara_ik_server": {"ros__parameters": {"scara": {"l3": 0.2}}},
    }
    path = tmp_path / "my_scara.yaml"
    path.write_text(yaml.safe_dump(document))
    machine = Scara.from_parameters(load_parameters(path, "scara_ik_server")["scara"])
    assert (machine.l1, machine.l2, machine.l3) == (0.20, 0.35, 0.2)
    np.testing.assert_allclose(machine.fk([0.0, 0.0, 0.0]), [0.75, 0.0, 0.0])


def test_solve_ik_of_one_target_is_the_batch_path(scara: Scara) -> None:
    """solve_ik of one pose (Python floats around the compiled kernel, issue #32) against the same
    pose in a batch (numpy): the same candidates (1e-12), statuses, selections, ties and texts,
    over 2000 poses with off-plane, tilted and non-finite ones among them, in every mode, seeded
    and not, with a branch asked for."""
    assert compiled_kernel(scara, wait=True) is not None
    rng = np.random.default_rng(32)
    n = 2000
    m = n - n // 2
    x = np.concatenate(
        [
            scara.fk(random_states(scara, rng, n // 2)),
            np.column_stack(
                [rng.uniform(-0.6, 1.4, m), rng.uniform(-0.9, 0.9, m), rng.uniform(-math.pi, math.pi, m)]
            ),
        ]
    )
    poses = scara.fkine(np.zeros((n, 3)))
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    poses[:, 0, 3], poses[:, 1, 3] = x[:, 0], x[:, 1]
    poses[7::40, 2, 3] = rng.uniform(-0.1, 0.1, len(poses[7::40]))  # off the plane
    tilted = poses[9::40]
    tilted[:, :3, :3] = tilted[:, :3, :3] @ np.array([[1.0, 0.0, 0.0], [0.0, 0.6, -0.8], [0.0, 0.8, 0.6]])
    poses[9::40] = tilted
    poses[11::97, 1, 0] = np.nan
    poses[13::97, 2, 3] = np.inf
    fixed = poses.copy()  # heading 90 deg: what mode fixed_phi with an orientation accepts
    fixed[:, :2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    seeds = rng.uniform(scara.limits.lower, scara.limits.upper, (n, 3))
    for targets, orientation, mode, seed, branch in (
        (poses, True, None, None, None),
        (poses, True, "phi", seeds, "elbow_b"),
        (poses, False, None, seeds, None),
        (poses, False, "position", None, "elbow_a"),
        (fixed, True, "fixed_phi", seeds, None),
        (poses, False, "fixed_phi", None, None),
    ):
        batch = scara.solve_ik(targets, use_orientation=orientation, mode=mode, seed=seed, branch=branch)
        assert len(set(batch.status.ravel().tolist())) >= 3
        for i in range(n):
            one = scara.solve_ik(
                targets[i],
                use_orientation=orientation,
                mode=mode,
                seed=None if seed is None else seed[i],
                branch=branch,
            )
            np.testing.assert_allclose(one.q, batch.q[i], rtol=0.0, atol=1e-12)
            assert np.array_equal(one.status, batch.status[i]), i
            assert one.selected.shape == () and one.tie.shape == ()
            assert one.tie == batch.tie[i], i
            assert one.selected == batch.selected[i] or (one.tie and one.valid.all()), i
            assert one.note() == batch.note(i), (i, one.note(), batch.note(i))
