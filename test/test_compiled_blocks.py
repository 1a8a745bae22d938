"""The shared block helper and kernel loader (manipulator_kinematics.blocks / .compiled)."""

from __future__ import annotations

import numpy as np
import pytest

from manipulator_kinematics.blocks import in_blocks
from manipulator_kinematics.compiled import Kernel


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
