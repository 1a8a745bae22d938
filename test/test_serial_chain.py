"""Serial D-H chain: stated poses, hand cases, standard vs modified D-H, Jacobian vs finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manipulator_kinematics.planar import two_link_fk
from manipulator_kinematics.serial_chain import (
    DHRow,
    JointLimits,
    SerialChain,
    compiled_kernel,
    prismatic,
    revolute,
    transl,
    trotx,
    troty,
    trotz,
)

PI = math.pi
# TBM tool changer, the reconstruction of tool_changer.md (standard D-H, m): k1..k7.
K1, K2, K3, K4, K5, K6, K7 = 0.200, 0.140, 0.880, 0.560, 0.175, 0.040, 0.552
TOOL_CHANGER = [
    revolute(d=K1, a=K2, alpha=PI / 2),
    revolute(a=K3),
    revolute(a=K4),
    revolute(a=K6, alpha=PI / 2),
    revolute(d=K5, alpha=-PI / 2),
    revolute(d=K7),
]


def tool_changer_modified() -> SerialChain:
    """The same arm in modified D-H: row i carries a_{i-1}, alpha_{i-1}; the last a, alpha go to the tool."""
    previous = [(0.0, 0.0)] + [(r.a, r.alpha) for r in TOOL_CHANGER[:-1]]
    rows = [revolute(a=a, alpha=alpha, d=r.d) for (a, alpha), r in zip(previous, TOOL_CHANGER, strict=True)]
    last = TOOL_CHANGER[-1]
    return SerialChain(rows, modified=True, tool=transl(last.a, 0, 0) @ trotx(last.alpha))


def numeric_jacobian(chain: SerialChain, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of position, and of R for the angular rows (w^ = dR/dq R^T)."""
    columns = []
    rotation = chain.fkine(q)[:3, :3]
    for i in range(chain.n):
        step = np.zeros(chain.n)
        step[i] = h
        plus, minus = chain.fkine(q + step), chain.fkine(q - step)
        dp = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
        w_hat = (plus[:3, :3] - minus[:3, :3]) / (2 * h) @ rotation.T
        columns.append(np.concatenate([dp, [w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]]]))
    return np.stack(columns, axis=1)


def random_chain(rng: np.random.Generator, modified: bool) -> SerialChain:
    rows = []
    for _ in range(rng.integers(2, 7)):
        a, alpha, offset = rng.uniform(-0.5, 0.5), rng.uniform(-PI, PI), rng.uniform(-1, 1)
        if rng.random() < 0.35:
            rows.append(prismatic(a=a, alpha=alpha, theta=rng.uniform(-PI, PI), offset=offset))
        else:
            rows.append(revolute(a=a, alpha=alpha, d=rng.uniform(-0.5, 0.5), offset=offset))
    base = transl(*rng.uniform(-1, 1, 3)) @ trotz(rng.uniform(-PI, PI)) @ troty(rng.uniform(-PI, PI))
    tool = transl(*rng.uniform(-0.3, 0.3, 3)) @ trotx(rng.uniform(-PI, PI))
    return SerialChain(rows, modified=modified, base=base, tool=tool)


def test_tool_changer_verification_pose_matches_the_paper() -> None:
    chain = SerialChain(TOOL_CHANGER)
    T = chain.fkine([PI / 2, PI / 6, -PI / 3, PI / 3, PI / 2, 0.0])
    np.testing.assert_allclose(T[:3, :3], [[1, 0, 0], [0, -0.5, -0.866], [0, 0.866, -0.5]], atol=5e-4)
    np.testing.assert_allclose(T[:3, 3], [0.0, 1.0312, -0.0476], atol=5e-5)
    np.testing.assert_allclose(T[3], [0, 0, 0, 1])


def test_tool_changer_home_pose_by_hand() -> None:
    # q = 0: arm stretched along x0 (k2 + k3 + k4 + k6); after the twists d5 points down (-z0), d6 along -y0.
    T = SerialChain(TOOL_CHANGER).fkine(np.zeros(6))
    np.testing.assert_allclose(T[:3, 3], [K2 + K3 + K4 + K6, -K7, K1 - K5], atol=1e-12)


def test_single_rows_by_hand() -> None:
    q = 0.7
    standard = SerialChain([revolute(a=0.4, alpha=0.3, d=0.2, offset=0.1)]).fkine([q])
    expected = trotz(q + 0.1) @ transl(0, 0, 0.2) @ transl(0.4, 0, 0) @ trotx(0.3)
    np.testing.assert_allclose(standard, expected, atol=1e-15)
    slide = SerialChain([prismatic(a=0.4, alpha=0.3, theta=0.5, offset=0.1)]).fkine([q])
    expected = trotz(0.5) @ transl(0, 0, q + 0.1) @ transl(0.4, 0, 0) @ trotx(0.3)
    np.testing.assert_allclose(slide, expected, atol=1e-15)
    craig = SerialChain([revolute(a=0.4, alpha=0.3, d=0.2, offset=0.1)], modified=True).fkine([q])
    expected = trotx(0.3) @ transl(0.4, 0, 0) @ trotz(q + 0.1) @ transl(0, 0, 0.2)
    np.testing.assert_allclose(craig, expected, atol=1e-15)


def test_planar_two_link_chain_equals_the_planar_helper() -> None:
    rng = np.random.default_rng(4)
    q = rng.uniform(-PI, PI, (500, 2))
    chain = SerialChain([revolute(a=0.7), revolute(a=0.4)])
    np.testing.assert_allclose(chain.fkine(q)[:, :2, 3], two_link_fk(q[:, 0], q[:, 1], 0.7, 0.4), atol=1e-14)
    craig = SerialChain([revolute(), revolute(a=0.7)], modified=True, tool=transl(0.4, 0, 0))
    np.testing.assert_allclose(craig.fkine(q), chain.fkine(q), atol=1e-14)


def test_modified_dh_describes_the_same_arm() -> None:
    rng = np.random.default_rng(5)
    q = rng.uniform(-PI, PI, (300, 6))
    standard, modified = SerialChain(TOOL_CHANGER), tool_changer_modified()
    np.testing.assert_allclose(modified.fkine(q), standard.fkine(q), atol=1e-12)
    np.testing.assert_allclose(modified.jacob0(q), standard.jacob0(q), atol=1e-12)


@pytest.mark.parametrize("modified", [False, True])
def test_jacobian_matches_central_differences(modified: bool) -> None:
    rng = np.random.default_rng(6 + modified)
    for _ in range(25):
        chain = random_chain(rng, modified)
        q = rng.uniform(-PI, PI, chain.n)
        np.testing.assert_allclose(chain.jacob0(q), numeric_jacobian(chain, q), atol=1e-8)


def test_prismatic_column_is_its_axis_and_has_no_angular_part() -> None:
    chain = SerialChain([revolute(a=0.3), prismatic(alpha=PI / 2, offset=0.2), revolute(a=0.1)])
    q = np.array([0.4, 0.25, -0.3])
    J = chain.jacob0(q)
    frames = chain.fkine(q, all_frames=True)
    np.testing.assert_allclose(J[:3, 1], frames[1, :3, 2], atol=1e-15)
    np.testing.assert_allclose(J[3:, 1], 0.0, atol=1e-15)
    np.testing.assert_allclose(J[3:, 0], [0, 0, 1], atol=1e-15)


def test_batches_equal_single_configurations() -> None:
    rng = np.random.default_rng(8)
    chain = random_chain(rng, modified=False)
    q = rng.uniform(-PI, PI, (4, 5, chain.n))
    T, J, frames = chain.fkine(q), chain.jacob0(q), chain.fkine(q, all_frames=True)
    assert T.shape == (4, 5, 4, 4) and J.shape == (4, 5, 6, chain.n)
    assert frames.shape == (4, 5, chain.n + 1, 4, 4)
    for index in [(0, 0), (3, 4), (2, 1)]:
        np.testing.assert_allclose(T[index], chain.fkine(q[index]), atol=1e-14)
        np.testing.assert_allclose(J[index], chain.jacob0(q[index]), atol=1e-14)
    np.testing.assert_allclose(frames[..., 0, :, :], np.broadcast_to(chain.base, (4, 5, 4, 4)))
    np.testing.assert_allclose(frames[..., -1, :, :] @ chain.tool, T, atol=1e-14)


def test_invalid_rows_and_inputs_are_refused() -> None:
    with pytest.raises(ValueError, match="offset"):
        DHRow(theta=0.3)
    with pytest.raises(ValueError, match="offset"):
        DHRow(d=0.3, prismatic=True)
    with pytest.raises(ValueError, match="rotation"):
        SerialChain([revolute(a=1.0)], base=np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        SerialChain([revolute(), revolute()]).fkine([0.1, 0.2, 0.3])


def test_joint_limits_report_the_side_of_a_violation() -> None:
    limits = JointLimits(("a", "b", "c"), np.array([0.0, -1.0, -1.0]), np.array([0.4, 1.0, 1.0]))
    q = np.array([[0.5, 0.0, -1.2], [0.4 + 1e-12, np.nan, 1.0], [-0.1, 0.2, 0.3]])
    np.testing.assert_array_equal(limits.violation(q, tol=1e-10), [[1, 0, -1], [0, 1, 0], [-1, 0, 0]])
    np.testing.assert_array_equal(limits.within(q, tol=1e-10), [False, False, False])
    assert limits.within([0.2, 0.9, -0.9])
    with pytest.raises(ValueError):
        JointLimits(("a",), np.array([1.0]), np.array([0.0]))


def product_of_links(chain: SerialChain, q: np.ndarray) -> np.ndarray:
    """base A_1 ... A_n tool from link_transforms: plain 4x4 products, apart from the chain's own."""
    links = chain.link_transforms(q)
    pose = np.broadcast_to(chain.base, links.shape[:-3] + (4, 4))
    for i in range(chain.n_rows):
        pose = pose @ links[..., i, :, :]
    return pose @ chain.tool


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("modified", [False, True])
def test_fkine_jacob0_equals_link_products_and_central_differences(modified: bool, compiled: bool) -> None:
    assert not compiled or compiled_kernel(wait=True) is not None
    rng = np.random.default_rng(11 + modified)
    for _ in range(20):
        chain = random_chain(rng, modified)
        q = rng.uniform(-PI, PI, (7, chain.n))
        pose, jacobian = chain.fkine_jacob0(q, compiled=compiled)
        assert pose.shape == (7, 4, 4) and jacobian.shape == (7, 6, chain.n)
        np.testing.assert_allclose(pose, product_of_links(chain, q), atol=1e-13)
        for k in (0, 6):
            np.testing.assert_allclose(jacobian[k], numeric_jacobian(chain, q[k]), atol=1e-8)
            one_pose, one_jacobian = chain.fkine_jacob0(q[k], compiled=compiled)
            np.testing.assert_array_equal(one_pose, pose[k])  # one state = a batch of one: the same steps
            np.testing.assert_array_equal(one_jacobian, jacobian[k])


def test_fkine_jacob0_of_a_coupled_chain_differentiates_the_independent_joints() -> None:
    # The palletizer's pattern: a passive row v4 = -(q2 + q3) keeps the flange level.
    coupling = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, -1, -1, 0], [0, 0, 0, 1]]
    rows = [
        revolute(d=0.4, alpha=PI / 2),
        revolute(a=0.7),
        revolute(a=0.6),
        revolute(a=0.1, alpha=-PI / 2),
        revolute(d=0.2),
    ]
    chain = SerialChain(rows, tool=transl(0.0, 0.0, 0.15), coupling=coupling)
    q = np.array([0.3, 0.9, -0.4, 1.1])
    pose, jacobian = chain.fkine_jacob0(q)
    assert jacobian.shape == (6, 4)
    np.testing.assert_allclose(jacobian, numeric_jacobian(chain, q), atol=1e-8)
    np.testing.assert_allclose(pose, product_of_links(chain, q), atol=1e-14)
    np.testing.assert_allclose(pose[2, :3], [0.0, 0.0, 1.0], atol=1e-14)  # level flange: z stays vertical
