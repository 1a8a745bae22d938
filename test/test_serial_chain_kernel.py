"""The compiled serial chain (manipulator_kinematics.chain_kernel) against the numpy path, the
reference: every machine's chain and random chains, 10^4 random configurations each."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manipulator_kinematics.serial_chain import (
    SerialChain,
    compiled_kernel,
    prismatic,
    revolute,
    transl,
    trotx,
    troty,
)
from palletizer_kinematics.kinematics import Palletizer
from pump_boom_kinematics.kinematics import PumpBoom
from scara_kinematics.kinematics import Scara
from tool_changer_kinematics.kinematics import ToolChanger

COUNT = 10_000
TOL = 1e-12


def random_chain(seed: int) -> SerialChain:
    """Standard or modified D-H, revolute and prismatic rows, a base, a tool and a coupling."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(rng.integers(1, 7)):
        a, alpha, offset = rng.uniform(-1, 1), rng.uniform(-math.pi, math.pi), rng.uniform(-1, 1)
        if rng.random() < 0.3:
            rows.append(prismatic(a=a, alpha=alpha, theta=rng.uniform(-math.pi, math.pi), offset=offset))
        else:
            rows.append(revolute(a=a, alpha=alpha, d=rng.uniform(-1, 1), offset=offset))
    base = transl(*rng.uniform(-1, 1, 3)) @ troty(rng.uniform(-math.pi, math.pi)) if seed % 2 else None
    tool = transl(*rng.uniform(-1, 1, 3)) @ trotx(rng.uniform(-math.pi, math.pi)) if seed % 3 else None
    coupling = rng.uniform(-1, 1, (len(rows), max(1, len(rows) - 1))) if seed % 4 == 0 else None
    return SerialChain(rows, modified=bool(seed % 5 % 2), base=base, tool=tool, coupling=coupling)


CHAINS = {
    "tool_changer": lambda: ToolChanger.default().chain,  # standard D-H, tool transform
    "palletizer": lambda: Palletizer.default().chain,  # modified D-H, coupled passive joint
    "scara": lambda: Scara.default().chain,  # a prismatic row, base transform
    "pump_boom": lambda: PumpBoom.default().chain,  # offsets of -180 deg
    **{f"random_{seed}": (lambda seed=seed: random_chain(seed)) for seed in range(8)},
}


@pytest.fixture(scope="module")
def kernel():
    module = compiled_kernel(wait=True)
    assert module is not None
    return module


@pytest.mark.parametrize("name", list(CHAINS))
def test_the_kernel_is_the_numpy_path(name: str, kernel) -> None:
    chain = CHAINS[name]()
    rng = np.random.default_rng(len(name))
    q = rng.uniform(-4.0, 4.0, (COUNT, chain.n))
    pose, jacobian = chain.fkine_jacob0(q)
    reference_pose, reference_jacobian = chain.fkine_jacob0(q, compiled=False)
    np.testing.assert_allclose(pose, reference_pose, rtol=0, atol=TOL)
    np.testing.assert_allclose(jacobian, reference_jacobian, rtol=0, atol=TOL)
    np.testing.assert_allclose(chain.fkine(q), reference_pose, rtol=0, atol=TOL)
    np.testing.assert_allclose(chain.jacob0(q), reference_jacobian, rtol=0, atol=TOL)
    frames = chain.fkine(q, all_frames=True)
    np.testing.assert_allclose(frames, chain.fkine(q, all_frames=True, compiled=False), rtol=0, atol=TOL)
    for k in range(0, COUNT, 97):  # one configuration per call: the batch's steps, the same bits
        one_pose, one_jacobian = chain.fkine_jacob0(q[k])
        np.testing.assert_array_equal(one_pose, pose[k])
        np.testing.assert_array_equal(one_jacobian, jacobian[k])
        np.testing.assert_array_equal(chain.fkine(q[k]), pose[k])
        np.testing.assert_array_equal(chain.fkine(q[k], all_frames=True), frames[k])


def test_non_finite_joint_values_give_non_finite_poses_on_both_paths(kernel) -> None:
    chain = CHAINS["palletizer"]()
    q = np.random.default_rng(3).uniform(-3.0, 3.0, (50, chain.n))
    q[::3, 1], q[1::5, 2], q[2::7, 0] = np.nan, np.inf, -np.inf
    for compiled in (True, False):
        with np.errstate(invalid="ignore"):  # numpy's cos(inf) says so
            pose, jacobian = chain.fkine_jacob0(q, compiled=compiled)
        broken = ~np.isfinite(q).all(axis=-1)
        np.testing.assert_array_equal(~np.isfinite(pose).all(axis=(-2, -1)), broken)
        np.testing.assert_array_equal(np.isfinite(pose[~broken]).all(), True)
        assert np.isfinite(jacobian[~broken]).all()


def test_any_layout_of_joint_values_is_accepted(kernel) -> None:
    chain = CHAINS["tool_changer"]()
    q = np.random.default_rng(4).uniform(-3.0, 3.0, (6, 2 * chain.n))
    columns = q[:, ::2]  # not contiguous
    frozen = np.array(q[:, : chain.n])
    frozen.flags.writeable = False
    for values in (columns, frozen, columns[1], frozen[2], columns.astype(np.float32), columns.tolist()):
        expected = chain.fkine_jacob0(np.array(values, dtype=float), compiled=False)
        for got, reference in zip(chain.fkine_jacob0(values), expected, strict=True):
            np.testing.assert_allclose(got, reference, rtol=0, atol=TOL)
    assert chain.fkine(np.zeros((0, chain.n))).shape == (0, 4, 4)
    assert chain.fkine_jacob0(np.zeros((2, 0, chain.n)))[1].shape == (2, 0, 6, chain.n)


def test_the_single_call_hot_path_refuses_or_converts_what_its_kernel_cannot_take(kernel) -> None:
    """One configuration goes to the kernel as given (issue #32): a wrong length is refused with
    the shape named, integer or float32 values are converted, as the general path does."""
    chain = CHAINS["tool_changer"]()
    for wrong in (np.zeros(chain.n - 1), np.zeros(chain.n + 1), np.zeros(0)):
        for call in (chain.fkine, chain.fkine_jacob0):
            with pytest.raises(ValueError, match=rf"shape \(\.\.\., {chain.n}\)"):
                call(wrong)
    for values in (np.arange(chain.n), np.linspace(-2.0, 2.0, chain.n, dtype=np.float32)):
        expected = chain.fkine_jacob0(values.astype(float), compiled=False)
        for got, reference in zip(chain.fkine_jacob0(values), expected, strict=True):
            np.testing.assert_allclose(got, reference, rtol=0, atol=TOL)
        np.testing.assert_allclose(chain.fkine(values), expected[0], rtol=0, atol=TOL)
