"""The shared selection rule: the compiled one-target rule (select_kernel.select_one) against select
(numpy), with and without a seed, over allowed subsets and exact ties; the
one failure rule (IKSolutions.failure) on every machine and the error codes MoveIt shares."""

from __future__ import annotations

import numpy as np
import pytest

from manipulator_kinematics.model import TIE_TOLERANCE, IKSolutions, IKStatus, pose_matrix, select
from manipulator_kinematics.registry import machine
from manipulator_kinematics.select_kernel import select_one

RNG = np.random.default_rng(8)


def candidates(count: int, m: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q = RNG.uniform(-3.0, 3.0, size=(count, m, n))
    status = RNG.integers(0, 5, size=(count, m)).astype(np.int8)
    q[status >= IKStatus.UNREACHABLE] = np.nan
    seed = RNG.uniform(-3.0, 3.0, size=(count, n))
    # Exact ties, the nearest candidates mirrored about the seed: 0 and 1 in every tenth target,
    # 1 and 2 in the next. Multiples of 1/8 and 1/1024: every sum exact, in any order.
    for first in (0, 1):
        tied = np.arange(count) % 10 == first
        seed[tied] = RNG.integers(-24, 24, size=(tied.sum(), n)) / 8
        step = RNG.integers(-8, 8, size=(tied.sum(), n)) / 1024
        q[tied, first], q[tied, first + 1] = seed[tied] + step, seed[tied] - step
        status[tied, first : first + 2] = IKStatus.SUCCESS
    return q, status, seed


@pytest.mark.parametrize("allowed", [None, (True, True), (False, True, True, False, True, True)])
@pytest.mark.parametrize("seeded", [False, True])
def test_the_compiled_rule_is_select(allowed: tuple[bool, ...] | None, seeded: bool) -> None:
    m, n = 6, 4
    q, status, seed = candidates(500, m, n)
    mask = np.zeros(m, dtype=bool)
    mask[: m if allowed is None else len(allowed)] = True if allowed is None else allowed
    expected, expected_tie = select(
        q, np.where(mask, status, IKStatus.UNREACHABLE), seed=seed if seeded else None
    )
    assert (expected >= 0).any() and (expected < 0).any()
    assert not seeded or expected_tie.any()
    for k in range(500):
        one = select_one(q[k], status[k], seed[k], seeded, mask, np.ones(n), TIE_TOLERANCE)
        assert one == (int(expected[k]), bool(expected_tie[k])), k


def test_error_codes_are_moveits_where_the_names_are_shared() -> None:
    """moveit_msgs/MoveItErrorCodes (MoveIt 2, Jazzy): the values of the names both define."""
    from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes as Codes

    moveit = {
        "SUCCESS": 1,
        "FAILURE": 99999,
        "INVALID_GOAL_CONSTRAINTS": -16,
        "INVALID_ROBOT_STATE": -17,
        "FRAME_TRANSFORM_FAILURE": -21,
        "NO_IK_SOLUTION": -31,
    }
    assert {name: getattr(Codes, name) for name in moveit} == moveit
    # Our own codes lie outside the values MoveIt uses (1, 99999, -1 ... -33).
    ours = {name: getattr(Codes, name) for name in ("SINGULAR", "JOINT_LIMITS_VIOLATED", "INVALID_MODE")}
    assert ours == {"SINGULAR": -40, "JOINT_LIMITS_VIOLATED": -41, "INVALID_MODE": -42}


def _solutions(status: list[int], branches: tuple[str, ...]) -> IKSolutions:
    m = len(status)
    return IKSolutions(
        q=np.zeros((m, 2)),
        status=np.array(status, dtype=np.int8),
        branches=branches,
        selected=np.array(-1),
        tie=np.array(False),
    )


def test_failure_is_the_best_status_or_the_asked_branchs() -> None:
    U, J, S, N = IKStatus.UNREACHABLE, IKStatus.JOINT_LIMITS, IKStatus.SINGULAR, IKStatus.INVALID
    branches = ("a", "b", "c")
    assert _solutions([U, J, U], branches).failure() is J  # a solution exists, it breaks a limit
    assert _solutions([U, U, U], branches).failure() is U
    assert _solutions([U, S, J], branches).failure() is S
    # With a branch asked for, the other branches are no answer: no geometric solution in it.
    assert _solutions([U, J, U], branches).failure(branch="a") is U
    assert _solutions([U, J, U], branches).failure(branch="b") is J
    assert _solutions([N, N, N], branches).failure(branch="c") is N
    assert _solutions([IKStatus.SUCCESS] * 3, branches).failure() is N  # nothing failed, nothing selected


@pytest.mark.parametrize(
    "name, target, branch, expected",
    [
        (
            "scara",
            (2.0, 0.0, 0.0),
            None,
            IKStatus.JOINT_LIMITS,
        ),  # the arm reaches it from x_l = 1.63 m > 0.4 m
        ("scara", (0.0, 2.0, 0.0), None, IKStatus.UNREACHABLE),  # |y| > l2 + l3: no rail length helps
        ("tool_changer", (1.5, 0.0, 1.0), None, IKStatus.JOINT_LIMITS),
        ("tool_changer", (1.5, 0.0, 1.0), "front_up_noflip", IKStatus.UNREACHABLE),  # J3 out of reach there
        ("tool_changer", (1.5, 0.0, 1.0), "front_up_flip", IKStatus.JOINT_LIMITS),
        ("tool_changer", (4.0, 0.0, 1.0), None, IKStatus.UNREACHABLE),
        ("palletizer", (0.0, 0.0, 0.0), None, IKStatus.JOINT_LIMITS),
        ("palletizer", (100.0, 0.0, 0.0), None, IKStatus.UNREACHABLE),
        ("pump_boom", (100.0, 0.0, 0.0), None, IKStatus.UNREACHABLE),
    ],
)
def test_one_failure_rule_on_every_machine(
    name: str, target: tuple[float, float, float], branch: str | None, expected: IKStatus
) -> None:
    model = machine(name).model()
    result = model.solve_ik(pose_matrix(np.array(target)), use_orientation=False, branch=branch)
    assert not result.ok and result.failure(branch=branch) is expected, result.note()
    geometric = result.status[[result.branches.index(branch)]] if branch else result.status
    assert (expected is IKStatus.UNREACHABLE) == bool(np.all(geometric >= IKStatus.UNREACHABLE))


def test_a_seed_at_infinity_selects_a_valid_candidate() -> None:
    """Every distance to an infinite seed is inf: the rule still picks a valid candidate."""
    q = np.array([[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]])
    status = np.array([[int(IKStatus.JOINT_LIMITS), int(IKStatus.SUCCESS), int(IKStatus.SUCCESS)]])
    for seed in ([np.inf, 0.0], [-np.inf, np.inf], [np.nan, 0.0]):
        selected, _ = select(q, status, seed=np.array(seed))
        assert selected[0] in (1, 2), seed
    selected, _ = select(q[0], status[0], seed=np.array([np.inf, np.inf]))
    assert int(selected) == 1
