"""The shared selection rule: select_parts (scalar parts: floats for one target, arrays for a
batch) against select (numpy), with and without a seed, over allowed subsets and exact ties."""

from __future__ import annotations

import numpy as np
import pytest

from manipulator_kinematics.model import IKStatus, select, select_parts
from manipulator_kinematics.serial_chain import parts_rows

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
def test_select_parts_is_select(allowed: tuple[bool, ...] | None, seeded: bool) -> None:
    m, n = 6, 4
    q, status, seed = candidates(500, m, n)
    seed = seed if seeded else None
    mask = np.zeros(m, dtype=bool)
    mask[: m if allowed is None else len(allowed)] = True if allowed is None else allowed
    expected, expected_tie = select(q, np.where(mask, status, IKStatus.UNREACHABLE), seed=seed)
    assert (expected >= 0).any() and (expected < 0).any()
    assert not seeded or expected_tie.any()
    rows = parts_rows(q.reshape(-1, m * n)), parts_rows(status.astype(float))
    chosen, tie = select_parts(*rows, seed=None if seed is None else parts_rows(seed), allowed=allowed)
    np.testing.assert_array_equal(chosen, expected)
    np.testing.assert_array_equal(np.broadcast_to(tie, expected.shape), expected_tie)
    for k in range(0, 500, 7):  # one target: floats
        one = select_parts(q[k].ravel().tolist(), status[k].tolist(),
                           seed=None if seed is None else seed[k].tolist(), allowed=allowed)
        assert one == (int(expected[k]), bool(expected_tie[k]))
