"""Every batch API through its compiled batch path (issue #32: a batch of any size through the
kernels) against the same targets as single calls and against the numpy path, the reference:
numbers within 1e-12 (never bitwise), statuses, selections, ties and texts equal, for N in
{1, 2, 5, 30}; targets include unreachable, out-of-limit and non-finite ones. The machines of the
hydraulic family (HydraulicModel's state, pose and jc0) for each shipped machine file."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np
import pytest
from numpy_paths import numpy_only

from excavator_kinematics.core import inverse
from excavator_kinematics.core import kinematics as excavator
from excavator_kinematics.core.kinematics import Excavator, StrokeError
from manipulator_kinematics import serial_chain
from manipulator_kinematics.hydraulic import HydraulicModel, HydraulicState
from manipulator_kinematics.hydraulic import StrokeError as FamilyStrokeError
from manipulator_kinematics.hydraulic import model as family
from manipulator_kinematics.param_files import config_path
from palletizer_kinematics import kinematics as palletizer
from palletizer_kinematics.kinematics import Palletizer
from pump_boom_kinematics import kinematics as pump_boom
from pump_boom_kinematics.kinematics import PumpBoom
from scara_kinematics import kinematics as scara_module
from scara_kinematics.kinematics import Scara
from tool_changer_kinematics.kinematics import ToolChanger

SIZES = (1, 2, 5, 30)
EXC = Excavator.default()
ARM = ToolChanger.default()
PAL = Palletizer.default()
SCARA = Scara.default()
BOOM = PumpBoom.default()
FAMILY = {
    name: HydraulicModel.from_file(config_path(file))
    for name, file in (
        ("cet200", "excavator_cet200.yaml"),
        ("wheel_loader", "wheel_loader_wl20.yaml"),
        ("knuckle_crane", "knuckle_crane_kc100.yaml"),
    )
}


@pytest.fixture(scope="module", autouse=True)
def kernels() -> None:
    serial_chain.compiled_kernel(wait=True)
    ARM.compiled_kernel(wait=True)
    palletizer.compiled_kernel(PAL, wait=True)
    scara_module.compiled_kernel(SCARA, wait=True)
    excavator.compiled_kernel(EXC, wait=True)
    inverse.compiled_kernel(EXC, wait=True)
    pump_boom.compiled_kernel(BOOM, wait=True)
    family.compiled_kernel(wait=True)


@contextlib.contextmanager
def kernel_only(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The numpy paths of the batch APIs made to fail: a batch inside ran the kernels' batch path."""

    def refused(*args: object, **kwargs: object) -> None:
        raise AssertionError("the numpy path ran")

    with monkeypatch.context() as patch:
        for owner, name in (
            (serial_chain.SerialChain, "_numpy"),
            (ToolChanger, "_solve"),
            (Palletizer, "_solve_block"),
            (Scara, "ik"),
            (Excavator, "validate"),
            (inverse, "candidates"),
            (PumpBoom, "region_ik"),
            (HydraulicModel, "_solve"),
        ):
            patch.setattr(owner, name, refused)
        yield


def close(got: np.ndarray, expected: np.ndarray) -> None:
    """Within 1e-12 of the quantity's scale, NaN where the reference has NaN, the same shape."""
    got, expected = np.asarray(got), np.asarray(expected)
    assert got.shape == expected.shape
    scale = max(float(np.nanmax(np.abs(expected), initial=0.0)), 1.0)
    np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12 * scale)


def same_solutions(batch, singles: list, reference) -> None:
    """IKSolutions of a batch = the single calls' and the numpy path's, texts included."""
    for i, one in enumerate(singles):
        close(batch.q[i], one.q)
        assert np.array_equal(batch.status[i], one.status)
        assert int(batch.selected[i]) == int(one.selected) and bool(batch.tie[i]) == bool(one.tie)
        assert batch.note(i) == one.note() == reference.note(i)
    close(batch.q, reference.q)
    assert np.array_equal(batch.status, reference.status)
    assert np.array_equal(batch.selected, reference.selected) and np.array_equal(batch.tie, reference.tie)
    assert batch.selected.dtype == reference.selected.dtype and batch.status.dtype == reference.status.dtype


def mixed_targets(poses: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Poses of random configurations, one in five moved 20 m away (unreachable), one NaN."""
    poses = poses.copy()
    far = rng.random(len(poses)) < 0.2
    poses[far, 0, 3] += 20.0
    if len(poses) > 3:
        poses[3, 1, 3] = np.nan
    return poses


# ---- the shared chain -------------------------------------------------------------------------------
@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize(
    "chain",
    [ARM.chain, PAL.chain, SCARA.chain, BOOM.chain],
    ids=["tool_changer", "palletizer", "scara", "pump_boom"],
)
def test_chain_batches_equal_single_calls_and_numpy(
    monkeypatch: pytest.MonkeyPatch, chain: serial_chain.SerialChain, n: int
) -> None:
    q = np.random.default_rng(n).uniform(-3.0, 3.0, (n, chain.n))
    with kernel_only(monkeypatch):
        pose, jacobian = chain.fkine_jacob0(q)
        poses = chain.fkine(q)
    reference = chain.fkine_jacob0(q, compiled=False)
    close(pose, reference[0])
    close(jacobian, reference[1])
    close(poses, chain.fkine(q, compiled=False))
    for i in range(n):
        one = chain.fkine_jacob0(q[i])
        close(pose[i], one[0])
        close(jacobian[i], one[1])
        close(poses[i], chain.fkine(q[i]))


def test_a_chain_batch_of_the_wrong_width_or_layout_takes_the_general_path() -> None:
    chain = ARM.chain
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 6\)"):
        chain.fkine_jacob0(np.zeros((3, 5)))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 6\)"):
        chain.fkine(np.zeros((3, 7)))
    q = np.random.default_rng(1).uniform(-1.0, 1.0, (6, 12))[:, ::2]  # strided: converted first
    close(chain.fkine_jacob0(q)[1], chain.fkine_jacob0(np.ascontiguousarray(q), compiled=False)[1])
    single = q.astype(np.float32)  # another dtype: converted first
    close(chain.fkine(single), chain.fkine(single.astype(float), compiled=False))


# ---- IK of the tool changer and the palletizer -------------------------------------------------------
@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("seeding", ["none", "one", "each"])
def test_tool_changer_ik_batches(monkeypatch: pytest.MonkeyPatch, n: int, seeding: str) -> None:
    rng = np.random.default_rng(100 + n)
    limits = ARM.limits
    targets = mixed_targets(ARM.fkine(rng.uniform(limits.lower, limits.upper, (n, 6))), rng)
    seeds = rng.uniform(limits.lower, limits.upper, (n, 6))
    seed = {"none": None, "one": seeds[0], "each": seeds}[seeding]
    with kernel_only(monkeypatch):
        batch = ARM.solve_ik(targets, seed=seed)
        branched = ARM.solve_ik(targets, seed=seed, branch=ARM.ik_branches[n % 8])
    singles = [
        ARM.solve_ik(targets[i], seed=None if seed is None else np.array(np.broadcast_to(seed, (n, 6))[i]))
        for i in range(n)
    ]
    same_solutions(batch, singles, ARM.solve_ik(targets, seed=seed, compiled=False))
    branch = ARM.ik_branches[n % 8]
    same_solutions(
        branched,
        [
            ARM.solve_ik(
                t, seed=None if seed is None else np.array(np.broadcast_to(seed, (n, 6))[i]), branch=branch
            )
            for i, t in enumerate(targets)
        ],
        ARM.solve_ik(targets, seed=seed, branch=branch, compiled=False),
    )


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("seeding", ["none", "one", "each"])
def test_palletizer_ik_batches(monkeypatch: pytest.MonkeyPatch, n: int, seeding: str) -> None:
    rng = np.random.default_rng(200 + n)
    limits = PAL.limits
    targets = mixed_targets(PAL.fkine(rng.uniform(limits.lower, limits.upper, (n, 4))), rng)
    seeds = rng.uniform(limits.lower, limits.upper, (n, 4))
    seed = {"none": None, "one": seeds[0], "each": seeds}[seeding]
    with kernel_only(monkeypatch):
        batch = PAL.solve_ik(targets, seed=seed)
        position = PAL.solve_ik(targets, seed=seed, use_orientation=False, mode="dh")
    each = [None if seed is None else np.array(np.broadcast_to(seed, (n, 4))[i]) for i in range(n)]
    singles = [PAL.solve_ik(targets[i], seed=each[i]) for i in range(n)]
    same_solutions(batch, singles, PAL.solve_ik(targets, seed=seed, compiled=False))
    same_solutions(
        position,
        [PAL.solve_ik(targets[i], seed=each[i], use_orientation=False, mode="dh") for i in range(n)],
        PAL.solve_ik(targets, seed=seed, use_orientation=False, mode="dh", compiled=False),
    )


# ---- the SCARA ---------------------------------------------------------------------------------------
def numpy_scara(*args, **kwargs):
    """Scara.solve_ik on the numpy path (the kernel set aside for the call)."""
    with numpy_only(scara_module.KERNEL):
        return SCARA.solve_ik(*args, **kwargs)


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize(
    "mode, oriented, seeding, branch",
    [
        ("phi", True, "none", None),
        ("phi", True, "each", "elbow_b"),
        ("position", False, "none", None),
        ("position", False, "one", None),
        ("position", False, "each", "elbow_a"),
        ("fixed_phi", False, "one", None),
    ],
)
def test_scara_ik_batches(
    monkeypatch: pytest.MonkeyPatch, n: int, mode: str, oriented: bool, seeding: str, branch: str | None
) -> None:
    rng = np.random.default_rng(300 + n)
    limits = SCARA.limits
    targets = mixed_targets(SCARA.fkine(rng.uniform(limits.lower, limits.upper, (n, 3))), rng)
    if n > 4:
        targets[4, 2, 3] = 0.5  # off the plane
        targets[1, :3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]  # tilted
    seeds = rng.uniform(limits.lower, limits.upper, (n, 3))
    seed = {"none": None, "one": seeds[0], "each": seeds}[seeding]
    options = {"mode": mode, "use_orientation": oriented, "seed": seed, "branch": branch}
    with kernel_only(monkeypatch):
        batch = SCARA.solve_ik(targets, **options)
    singles = []
    for i in range(n):
        single = {**options, "seed": None if seed is None else np.array(np.broadcast_to(seed, (n, 3))[i])}
        singles.append(SCARA.solve_ik(targets[i], **single))
    same_solutions(batch, singles, numpy_scara(targets, **options))


def test_scara_fixed_phi_batch_refuses_another_heading() -> None:
    targets = SCARA.fkine(np.array([[0.1, 0.3, 1.2], [0.2, 0.4, 0.3]]))
    with pytest.raises(scara_module.RequestError) as batch:
        SCARA.solve_ik(targets, mode="fixed_phi")
    with pytest.raises(scara_module.RequestError) as reference:
        numpy_scara(targets, mode="fixed_phi")
    assert str(batch.value) == str(reference.value) and "target heading is" in str(batch.value)


# ---- the excavator -----------------------------------------------------------------------------------
def numpy_excavator(method: str, *args):
    with numpy_only(excavator.KERNEL):
        return getattr(EXC, method)(*args)


def _states(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(400 + n)
    lo, hi = EXC.limits.d_min, EXC.limits.d_max
    D = rng.uniform(lo, hi, (n, 4))
    rates = rng.uniform(-1.0, 1.0, (n, 4)) * EXC.limits.max_rates
    return D, rates, rng.uniform(-1.0, 1.0, (n, 4)) * EXC.limits.max_rates


@pytest.mark.parametrize("n", SIZES)
def test_excavator_state_and_pose_batches(monkeypatch: pytest.MonkeyPatch, n: int) -> None:
    D, rates, accelerations = _states(n)
    for args in ((D, rates, accelerations), (D, rates), (D, rates[0], accelerations[0])):
        with kernel_only(monkeypatch):
            batch = EXC.state(*args)
        reference = numpy_excavator("state", *args)
        for field, got in batch._asdict().items():
            close(got, getattr(reference, field))
            for i in range(n):
                one = EXC.state(*(a[i] if a.ndim == 2 else a for a in args))
                close(got[i], getattr(one, field))
    with kernel_only(monkeypatch):
        Q = EXC.pose(D)
    close(Q, numpy_excavator("pose", D))
    for i in range(n):
        close(Q[i], EXC.pose(D[i]))


def test_an_excavator_batch_with_a_state_refused_raises_as_the_numpy_path() -> None:
    D, rates, _ = _states(5)
    D[3, 2] = EXC.limits.stroke_max[1] + 0.5  # the arm cylinder beyond its stroke
    with pytest.raises(StrokeError, match="arm_cylinder length"):
        EXC.state(D, rates)
    with pytest.raises(StrokeError, match="arm_cylinder length"):
        EXC.pose(D)
    with pytest.raises(ValueError, match="D_dot"):
        EXC.state(_states(5)[0], rates[:3])


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("seeding, branch", [("none", None), ("one", None), ("each", "front_elbow_down")])
def test_excavator_ik_batches(
    monkeypatch: pytest.MonkeyPatch, n: int, seeding: str, branch: str | None
) -> None:
    D, _, _ = _states(n)
    Q = EXC.pose(D)
    Q[np.random.default_rng(n).random(n) < 0.2, 0] += 20.0  # out of reach
    if n > 3:
        Q[3, 2] = np.nan
        Q[2, :2] = 0.0  # on the swing axis
    seeds = _states(n + 7)[0][:n]
    seed = {"none": None, "one": seeds[0], "each": seeds}[seeding]
    with kernel_only(monkeypatch):
        batch = EXC.ik(Q, seed=seed, branch=branch)
    singles = [
        EXC.ik(Q[i], seed=None if seed is None else np.array(np.broadcast_to(seed, (n, 4))[i]), branch=branch)
        for i in range(n)
    ]
    same_solutions(batch, singles, inverse.solve_pose(EXC, Q, seed=seed, branch=branch, compiled=False))


# ---- the pump boom -----------------------------------------------------------------------------------
@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("seeding", ["none", "one", "each"])
def test_pump_boom_ik_batches(monkeypatch: pytest.MonkeyPatch, n: int, seeding: str) -> None:
    rng = np.random.default_rng(500 + n)
    limits = BOOM.limits
    targets = mixed_targets(BOOM.fkine(rng.uniform(limits.lower, limits.upper, (n, 6))), rng)
    seeds = rng.uniform(limits.lower, limits.upper, (n, 6))
    seed = {"none": None, "one": seeds[0], "each": seeds}[seeding]
    with kernel_only(monkeypatch):
        batch = BOOM.solve_ik(targets, use_orientation=False, seed=seed)
    singles = [
        BOOM.solve_ik(
            targets[i],
            use_orientation=False,
            seed=None if seed is None else np.array(np.broadcast_to(seed, (n, 6))[i]),
        )
        for i in range(n)
    ]
    with numpy_only(pump_boom.KERNEL):
        reference = BOOM.solve_ik(targets, use_orientation=False, seed=seed)
    same_solutions(batch, singles, reference)
    assert len(set(batch.status.ravel().tolist())) >= (2 if n >= 5 else 1)


# ---- the hydraulic family ---------------------------------------------------------------------------
def numpy_family(model: HydraulicModel, method: str, *args):
    with numpy_only(family.KERNEL):
        return getattr(model, method)(*args)


def _family_states(model: HydraulicModel, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(600 + n)
    D = rng.uniform(model.lower, model.upper, (n, model.m))
    rates = rng.uniform(-1.0, 1.0, (n, model.m)) * model.max_speed
    return D, rates, rng.uniform(-1.0, 1.0, (n, model.m)) * model.max_speed


@contextlib.contextmanager
def rows_as_given() -> Iterator[None]:
    """The family's general batch path (``_batch``: conversions, broadcasting) made to fail too."""

    def refused(*args: object, **kwargs: object) -> None:
        raise AssertionError("_batch ran")

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(HydraulicModel, "_batch", refused)
        yield


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("name", FAMILY)
def test_family_batches_equal_single_calls_and_numpy(
    monkeypatch: pytest.MonkeyPatch, name: str, n: int
) -> None:
    """state, pose and jc0 of a batch (N, m): the kernels' loops on the arrays as given (rates
    (N, m) or one row (1, m) for all); rates of one state (m,) through ``_batch``."""
    model = FAMILY[name]
    D, rates, accelerations = _family_states(model, n)
    for args in ((D, rates, accelerations), (D, rates), (D, rates[:1], accelerations[:1]), (D, rates[0])):
        with kernel_only(monkeypatch), rows_as_given() if args[1].ndim == 2 else contextlib.nullcontext():
            batch = model.state(*args)
        reference = numpy_family(model, "state", *args)
        for field in HydraulicState._fields:
            got = getattr(batch, field)
            close(got, getattr(reference, field))
            for i in range(n):
                one = model.state(*(a[i if len(a) == n else 0] if a.ndim == 2 else a for a in args))
                close(got[i], getattr(one, field))
    with kernel_only(monkeypatch), rows_as_given():
        Q, J = model.pose(D), model.jc0(D)
    close(Q, numpy_family(model, "pose", D))
    close(J, numpy_family(model, "jc0", D))
    for i in range(n):
        close(Q[i], model.pose(D[i]))
        close(J[i], model.jc0(D[i]))


def test_a_family_batch_with_a_state_refused_raises_as_the_numpy_path() -> None:
    model = FAMILY["wheel_loader"]
    D, rates, _ = _family_states(model, 5)
    D[3, 1] = model.upper[1] + 0.5  # the second actuator beyond its stroke
    name = model.actuator_names[1]
    for call in (lambda: model.state(D, rates), lambda: model.pose(D), lambda: model.jc0(D)):
        with pytest.raises(FamilyStrokeError, match=name):
            call()
    with pytest.raises(FamilyStrokeError, match="D_dot"):
        model.state(_family_states(model, 5)[0], rates[:3])
    assert model.pose(np.empty((0, model.m))).shape == (0, len(model.task_names))


def test_a_batch_of_one_is_checked_as_any_batch(monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernels' straight line for a batch of one (issue #32) refuses what their loops refuse:
    rates of another row count, a row of another width, a state beyond its stroke; the error is
    the numpy path's. Rates as lists or of one state (4,) go the kernel's way once converted."""
    D, rates, accelerations = _states(2)
    with pytest.raises(ValueError, match="D_dot"):
        EXC.state(D[:1], rates)
    with pytest.raises(ValueError, match="D_ddot"):
        EXC.state(D[:1], rates[:1], accelerations)
    with pytest.raises(ValueError, match="shape"):
        EXC.state(D[:1, :3], rates[:1, :3])
    beyond = D[:1].copy()
    beyond[0, 2] = EXC.limits.stroke_max[1] + 0.5
    with pytest.raises(StrokeError, match="arm_cylinder length"):
        EXC.state(beyond, rates[:1])
    with kernel_only(monkeypatch):
        listed = EXC.state(D[:1], [list(rates[0])], accelerations[0].tolist())
        one = EXC.state(D[0], list(rates[0]), accelerations[0].tolist())
    close(listed.Q_ddot[0], one.Q_ddot)
    close(one.Q_ddot, EXC.state(D[0], rates[0], accelerations[0]).Q_ddot)
    model = FAMILY["knuckle_crane"]
    D, rates, _ = _family_states(model, 2)
    with pytest.raises(FamilyStrokeError, match="D_dot"):
        model.state(D[:1], rates)
    with pytest.raises(ValueError, match="shape"):
        model.pose(D[:1, :-1])
    beyond = D[:1].copy()
    beyond[0, 1] = model.upper[1] + 0.5
    name = model.actuator_names[1]
    for call in (
        lambda: model.state(beyond, rates[:1]),
        lambda: model.pose(beyond),
        lambda: model.jc0(beyond),
    ):
        with pytest.raises(FamilyStrokeError, match=name):
            call()
    q = np.zeros((1, ARM.chain.n + 1))
    with pytest.raises(ValueError, match="shape"):
        ARM.chain.fkine(q)
    with pytest.raises(ValueError, match="shape"):
        ARM.chain.fkine_jacob0(q)


def test_a_read_only_batch_takes_the_numpy_path_without_compiling() -> None:
    """Arguments of types a batch loop was not warmed with (a read-only view) raise TypeError in
    the loop (no compile inside the call) and the call answers from the numpy path."""
    D, _, _ = _states(5)
    Q = np.broadcast_to(EXC.pose(D), (5, 4))  # read-only
    close(EXC.ik(Q).q, inverse.solve_pose(EXC, Q, compiled=False).q)
    targets = np.broadcast_to(SCARA.fkine(np.array([[0.1, 0.3, 1.2], [0.2, 0.4, 0.3]])), (2, 4, 4))
    close(SCARA.solve_ik(targets).q, numpy_scara(targets).q)
    points = np.broadcast_to(
        BOOM.fkine(np.zeros((3, 6)) + BOOM.limits.lower * 0.5 + BOOM.limits.upper * 0.5), (3, 4, 4)
    )
    assert BOOM.solve_ik(points, use_orientation=False).q.shape == (3, 1, 6)
    for kernel in (
        inverse.KERNEL.ready.solve_batch,
        scara_module.KERNEL.ready.solve_ik_batch,
        pump_boom.KERNEL.ready.region_ik_batch,
    ):
        assert len(kernel.signatures) == 1
