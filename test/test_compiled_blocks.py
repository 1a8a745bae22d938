"""The shared block helper and kernel loader (manipulator_kinematics.row_blocks / .compiled)."""

from __future__ import annotations

import numpy as np
import pytest

from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.row_blocks import in_blocks


def _work(a: np.ndarray, b: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    return np.cumsum(a, axis=-1), (a[:, 0] > 0) if b is None else b.astype(np.int8)


@pytest.mark.parametrize("n", [1, 7, 64, 65, 1000])
def test_in_blocks_is_one_call(n: int) -> None:
    a = np.random.default_rng(n).normal(size=(n, 3))
    whole = _work(a, None)
    blocked = in_blocks(_work, a, None, block=8)
    for expected, got in zip(whole, blocked, strict=True):
        assert got.dtype == expected.dtype and got.shape == expected.shape
        np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(in_blocks(np.sin, a, block=5), np.sin(a))


def test_a_kernel_that_fails_to_load_leaves_the_numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    kernel = Kernel("manipulator_kinematics.no_such_kernel", lambda module: None)
    with pytest.raises(RuntimeError, match="no_such_kernel"):
        kernel.get(wait=True)
    assert kernel.get() is None and isinstance(kernel.error, ImportError)
    monkeypatch.setenv("MK_COMPILED", "0")
    assert Kernel("math", lambda module: None).get(wait=True) is None


def test_a_kernel_warms_with_the_first_sample() -> None:
    seen = []
    kernel = Kernel("math", lambda module, x: seen.append(module.sqrt(x)))
    assert kernel.get(4.0, wait=True).sqrt(9.0) == 3.0
    assert seen == [2.0]


def test_the_compiled_selection_is_the_numpy_rule() -> None:
    """select_kernel.select_one against model.select over random candidate sets, with ties,
    requested branches, weights and seeds that are NaN or infinite."""
    from manipulator_kinematics.model import TIE_TOLERANCE, IKStatus, select
    from manipulator_kinematics.select_kernel import select_one

    rng = np.random.default_rng(22)
    for trial in range(4000):
        m, n = int(rng.integers(1, 9)), int(rng.integers(1, 7))
        q = rng.integers(-2, 3, size=(m, n)).astype(float)  # small integers: exact ties happen
        status = rng.choice(
            [int(IKStatus.SUCCESS), int(IKStatus.JOINT_LIMITS), int(IKStatus.SINGULAR)],
            size=m,
            p=[0.6, 0.3, 0.1],
        ).astype(np.int8)
        seed = rng.integers(-2, 3, size=n).astype(float)
        if trial % 10 == 0:
            seed[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        weights = rng.choice([1.0, 0.5, 2.0], size=n)
        seeded = trial % 7 != 0
        branch = int(rng.integers(m)) if trial % 5 == 0 else None
        expected, expected_tie = select(
            q, status, seed=seed if seeded else None, branch=branch, weights=weights
        )
        allowed = np.full(m, branch is None)
        if branch is not None:
            allowed[branch] = True
        got, tie = select_one(q, status, seed, seeded, allowed, weights, TIE_TOLERANCE)
        assert (got, tie) == (int(expected), bool(expected_tie)), (trial, q, status, seed, branch)


@pytest.mark.parametrize("n", [1, 7, 8, 9, 100])
def test_in_blocks_rows_is_the_table_of_entries(n: int) -> None:
    a = np.random.default_rng(n).normal(size=(n, 2))

    def entries(x: np.ndarray) -> tuple:
        return x[:, 0] * 2.0, 1.5, np.hypot(x[:, 0], x[:, 1])

    table = in_blocks(entries, a, block=8, rows=True)
    assert table.shape == (3, n)
    np.testing.assert_array_equal(table, [a[:, 0] * 2.0, np.full(n, 1.5), np.hypot(a[:, 0], a[:, 1])])
