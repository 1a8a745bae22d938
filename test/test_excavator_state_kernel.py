"""The excavator's compiled single call (excavator_kinematics.core.state_kernel) against the numpy path,
the reference: 10^4 random states in and out of the limits, with rates and accelerations; and
one state through the numpy path = that row of a batch, bit for bit (the same code)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from excavator_kinematics.core import kinematics
from excavator_kinematics.core.kinematics import BucketState, Excavator, StrokeError, compiled_kernel

EXC = Excavator.default()
LIM = EXC.limits
N = 10_000


def _states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States over the limits widened by a fifth of each range (about half outside one), a few
    not finite; rates and accelerations up to twice the speed limits."""
    lo, hi = LIM.d_min, LIM.d_max
    span = hi - lo
    D = rng.uniform(lo - 0.2 * span, hi + 0.2 * span, size=(n, 4))
    D[rng.choice(n, 20, replace=False), rng.integers(0, 4, 20)] = np.nan
    rates = rng.uniform(-2.0, 2.0, size=(n, 4)) * LIM.max_rates
    rates[rng.choice(n, 10, replace=False), rng.integers(0, 4, 10)] = np.inf
    return D, rates, rng.uniform(-2.0, 2.0, size=(n, 4)) * LIM.max_rates


def _close(kernel: np.ndarray, reference: np.ndarray) -> bool:
    """Within 1e-12 relative to the largest entry of the quantity."""
    scale = max(float(np.max(np.abs(reference))), 1.0)
    return bool(np.all(np.abs(kernel - reference) <= 1e-12 * scale))


def test_kernel_equals_numpy_over_random_states_in_and_out_of_the_limits(monkeypatch: pytest.MonkeyPatch):
    """Each state through the kernel's single call; the numpy path (the family core, about 1.6 ms
    a call) refuses every state the kernel refuses, one by one (it refuses before any work), and
    takes the others as one batch (a refusal there fails the test), whose rows are its single
    calls' bits (test_one_state_on_the_numpy_path_is_that_row_of_a_batch_bit_for_bit)."""
    kernel = compiled_kernel(EXC, wait=True)
    monkeypatch.setattr(kinematics.KERNEL, "ready", None)  # numpy below
    D, rates, accelerations = _states(np.random.default_rng(20261202), N)
    tables, poses, jc0s = np.empty((N, 10, 4)), np.empty((N, 4)), np.empty((N, 4, 4))
    state_ok, pose_ok = np.zeros(N, dtype=bool), np.zeros(N, dtype=bool)
    for i in range(N):
        state_ok[i] = kernel.state(EXC.packed, D[i], rates[i], accelerations[i], tables[i])
        pose_ok[i] = kernel.pose(EXC.packed, D[i], poses[i])
        assert kernel.jc0(EXC.packed, D[i], jc0s[i]) == pose_ok[i]
        if not state_ok[i]:  # the numpy path on a batch of one
            with pytest.raises(StrokeError):
                EXC.state(D[i : i + 1], rates[i : i + 1], accelerations[i : i + 1])
        if not pose_ok[i]:
            with pytest.raises(StrokeError):
                EXC.pose(D[i : i + 1])
    reference = EXC.state(D[state_ok], rates[state_ok], accelerations[state_ok])
    pose, jc0 = EXC.pose(D[pose_ok]), EXC.jc0(D[pose_ok])
    for j, i in enumerate(np.flatnonzero(pose_ok)):
        assert _close(poses[i], pose[j]) and _close(jc0s[i], jc0[j]), D[i]
    for j, i in enumerate(np.flatnonzero(state_ok)):
        for row, field in enumerate(BucketState._fields[:6]):
            assert _close(tables[i, row], getattr(reference, field)[j]), (field, D[i])
        assert _close(tables[i, 6:], reference.jc0[j]), D[i]
    refused = N - int(np.count_nonzero(state_ok))
    assert 0.3 * N < refused < 0.8 * N  # both kinds well represented


def test_a_batch_through_the_kernel_equals_the_numpy_batch(monkeypatch: pytest.MonkeyPatch):
    """Batches of valid states run the kernel's loop (states), rates and accelerations per state
    or one row for all: the numpy batch's values to 1e-12, and the same refusals."""
    assert compiled_kernel(EXC, wait=True) is not None
    rng = np.random.default_rng(7)
    n = 3000
    D = rng.uniform(LIM.d_min, LIM.d_max, size=(n, 4))
    rates = rng.uniform(-1.0, 1.0, size=(n, 4)) * LIM.max_rates
    accelerations = rng.uniform(-1.0, 1.0, size=(n, 4)) * LIM.max_rates
    compiled = [EXC.state(D, rates, accelerations), EXC.state(D, rates), EXC.state(D[:100], rates[0])]
    with monkeypatch.context() as numpy_only:
        numpy_only.setattr(kinematics.KERNEL, "ready", None)
        reference = [EXC.state(D, rates, accelerations), EXC.state(D, rates), EXC.state(D[:100], rates[0])]
    for got, expected in zip(compiled, reference, strict=True):
        for a, b in zip(got, expected, strict=True):
            assert a.shape == b.shape and _close(a, b)
    outside = D.copy()
    outside[5, 2] = LIM.d_max[2] + 0.1
    with pytest.raises(StrokeError):
        EXC.state(outside, rates)


def test_a_batch_of_poses_through_the_kernel_equals_the_numpy_batch(monkeypatch: pytest.MonkeyPatch):
    """Batches of poses of every size run the kernel's loop (poses, issue #32): the numpy batch's
    values to 1e-12 over 2 x 10^4 states in batches of sizes 1 to 10^4, and the same refusal."""
    assert compiled_kernel(EXC, wait=True) is not None
    rng = np.random.default_rng(32)
    D = rng.uniform(LIM.d_min, LIM.d_max, size=(20_000, 4))
    sizes = [1, 2, 7, 100, 1000, 2049, 10_000]
    batches = np.split(D, np.cumsum(sizes * (len(D) // sum(sizes)))[:-1])
    calls = 0
    real = kinematics.KERNEL.ready.poses

    def counted(*arguments):
        nonlocal calls
        calls += 1
        return real(*arguments)

    with monkeypatch.context() as spy:
        spy.setattr(kinematics.KERNEL.ready, "poses", counted)
        compiled = [EXC.pose(batch) for batch in batches]
    assert calls == len(batches) == len(sizes)
    with monkeypatch.context() as numpy_only:
        numpy_only.setattr(kinematics.KERNEL, "ready", None)
        reference = [EXC.pose(batch) for batch in batches]
    for got, expected in zip(compiled, reference, strict=True):
        assert got.shape == expected.shape and _close(got, expected)
    outside = D[:10].copy()
    outside[5, 2] = LIM.d_max[2] + 0.1
    with pytest.raises(StrokeError):
        EXC.pose(outside)


def test_the_single_call_returns_the_kernel_result_and_refuses_as_the_numpy_path():
    kernel = compiled_kernel(EXC, wait=True)
    D, V, A = LIM.reference, np.array([0.2, 0.05, -0.08, 0.1]), np.array([0.1, 0.02, 0.01, -0.03])
    table = np.empty((10, 4))
    assert kernel.state(EXC.packed, D, V, A, table)
    one = EXC.state(D, V, A)
    np.testing.assert_array_equal(np.concatenate(one[:6]), table[:6].ravel())
    np.testing.assert_array_equal(one.jc0, table[6:])
    np.testing.assert_array_equal(EXC.state(D, V).Q_ddot, EXC.state(D, V, np.zeros(4)).Q_ddot)
    np.testing.assert_array_equal(EXC.state(list(D), list(V)).Q, one.Q)  # lists are fine
    bad = D.copy()
    bad[2] = LIM.stroke_max[1] + 0.5
    for call in (lambda: EXC.state(bad, V), lambda: EXC.pose(bad), lambda: EXC.jc0(bad)):
        with pytest.raises(StrokeError, match="arm_cylinder length"):
            call()
    with pytest.raises(StrokeError, match="D_ddot"):
        EXC.state(D, V, [0.0, np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="shape"):
        EXC.state(D, V, np.zeros(3))
    # A view that is not contiguous takes the numpy path (numba compiles nothing new in a call).
    strided = np.tile(D, (2, 1)).T.copy().T[0]
    assert not strided.flags.c_contiguous
    np.testing.assert_allclose(EXC.pose(strided), EXC.pose(D), rtol=1e-12)
    np.testing.assert_allclose(
        EXC.state(D, np.tile(V, (2, 1)).T.copy().T[0]).Q_dot, EXC.state(D, V).Q_dot, rtol=1e-12
    )
    assert [len(f.signatures) for f in (kernel.state, kernel.pose, kernel.jc0)] == [1, 1, 1]


@pytest.mark.parametrize("path", ["kernel", "numpy"])
def test_the_record_reads_like_a_named_tuple_from_a_new_table_per_call(
    monkeypatch: pytest.MonkeyPatch, path: str
):
    """BucketState of one state, a batch in the kernel's loop and one on numpy: by name = by
    position = unpacked, the shapes, JC0's axes (Qdot = JC0 Ddot, eq. 8), Q = the pose, theta =
    the joint angles, and a call leaves the fields of the one before alone (a table of its own)."""
    if path == "kernel":
        assert compiled_kernel(EXC, wait=True) is not None
    else:
        monkeypatch.setattr(kinematics.KERNEL, "ready", None)
    rng = np.random.default_rng(5)
    for shape in ((4,), (3, 4), (kinematics._BLOCK + 1, 4)):
        D = rng.uniform(LIM.d_min, LIM.d_max, size=shape)
        V, A = rng.uniform(-1.0, 1.0, size=(2, *shape)) * LIM.max_rates
        state = EXC.state(D, V, A)
        kept = [field.copy() for field in state]
        assert len(state) == 7 and tuple(state._asdict()) == BucketState._fields
        theta, *_, Q, Q_dot, _, jc0 = state
        for i, (name, value) in enumerate(state._asdict().items()):
            assert value.shape == shape[:-1] + ((4, 4) if name == "jc0" else (4,)), name
            for same in (getattr(state, name), state[i], state[i - 7], state[i:][0]):
                np.testing.assert_array_equal(same, value, err_msg=name)
        np.testing.assert_allclose(np.einsum("...ij,...j->...i", jc0, V), Q_dot, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Q, EXC.pose(D), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(theta[..., 1:], EXC.joint_angles(D[..., 1:]), rtol=1e-12, atol=1e-12)
        EXC.state(D[::-1].copy(), -V, A)
        for before, field in zip(kept, state, strict=True):
            np.testing.assert_array_equal(field, before)
        np.testing.assert_array_equal(pickle.loads(pickle.dumps(state)).jc0, jc0)
        assert repr(state).startswith("BucketState(theta=array(")


def test_one_state_on_the_numpy_path_is_that_row_of_a_batch_bit_for_bit(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(kinematics.KERNEL, "ready", None)
    rng = np.random.default_rng(7)
    lo, hi = LIM.d_min, LIM.d_max
    D = rng.uniform(lo, hi, size=(300, 4))
    V, A = rng.uniform(-1, 1, size=(2, 300, 4)) * LIM.max_rates
    batch, poses, jc0s = EXC.state(D, V, A), EXC.pose(D), EXC.jc0(D)
    for i in range(0, 300, 7):
        one = EXC.state(D[i], V[i], A[i])
        for field in BucketState._fields:
            np.testing.assert_array_equal(getattr(one, field), getattr(batch, field)[i], err_msg=field)
        np.testing.assert_array_equal(EXC.pose(D[i]), poses[i])
        np.testing.assert_array_equal(EXC.jc0(D[i]), jc0s[i])


def test_bucket_orientation_and_rates_of_one_state_compiled_equal_the_numpy_path():
    compiled_kernel(EXC, wait=True)
    rng = np.random.default_rng(11)
    values = rng.uniform(-7.0, 7.0, size=(N // 10, 5))
    quaternions = kinematics.bucket_quaternion(values[:, 0], values[:, 1])
    omegas = kinematics.bucket_angular_velocity(*values[:, :3].T)
    alphas = kinematics.bucket_angular_acceleration(*values.T)
    for i, row in enumerate(values.tolist()):  # Python floats: the kernel
        assert _close(kinematics.bucket_quaternion(row[0], row[1]), quaternions[i])
        assert _close(kinematics.bucket_angular_velocity(*row[:3]), omegas[i])
        assert _close(kinematics.bucket_angular_acceleration(*row), alphas[i])
    assert kinematics.bucket_angular_velocity(0.5, 1, 0.25).shape == (3,)  # an int: the numpy path
