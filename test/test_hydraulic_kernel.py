"""The hydraulic family's compiled kernel (manipulator_kinematics.hydraulic.kernel) against the numpy
core, the reference, for every shipped family machine (CET200, WL20, KC100): random states inside
the stroke box and on and next to its faces, with rates and accelerations, one call and batches,
to 1e-12 of each quantity's scale; refusals still raised by the numpy path with the actuator
named; the program layout's stale-cache refusal."""

from __future__ import annotations

import types

import numpy as np
import pytest
from numpy_paths import numpy_only

from manipulator_kinematics.hydraulic import HydraulicModel, StrokeError, layout
from manipulator_kinematics.hydraulic import model as core
from manipulator_kinematics.param_files import config_path

FILES = {
    "CET200": "excavator_cet200.yaml",
    "WL20": "wheel_loader_wl20.yaml",
    "KC100": "knuckle_crane_kc100.yaml",
}
MODELS = {name: HydraulicModel.from_file(config_path(f)) for name, f in FILES.items()}
FIELDS = ("theta", "theta_dot", "theta_ddot", "Q", "Q_dot", "Q_ddot", "jc0", "k")


@pytest.fixture(scope="module")
def kernel() -> types.ModuleType:
    loaded = core.compiled_kernel(wait=True)
    assert loaded is not None
    return loaded


def _states(model: HydraulicModel, rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """n states in the stroke box, every fourth with one actuator on a face or 1e-9 inside it;
    rates and accelerations up to twice the speed limits."""
    D = rng.uniform(model.lower, model.upper, size=(n, model.m))
    span = model.upper - model.lower
    for i in range(0, n, 4):
        j = rng.integers(model.m)
        D[i, j] = rng.choice(
            [model.lower[j], model.upper[j], model.lower[j] + 1e-9 * span[j], model.upper[j] - 1e-9 * span[j]]
        )
    rates = rng.uniform(-2.0, 2.0, size=D.shape) * model.max_speed
    return D, rates, rng.uniform(-2.0, 2.0, size=D.shape) * model.max_speed


def _close(got: np.ndarray, expected: np.ndarray) -> None:
    """Within 1e-12 of the quantity's scale (its largest entry, at least 1)."""
    assert got.shape == expected.shape
    scale = max(float(np.max(np.abs(expected))), 1.0)
    assert np.all(np.abs(got - expected) <= 1e-12 * scale), np.max(np.abs(got - expected)) / scale


@pytest.mark.parametrize("name", FILES)
def test_one_call_equals_the_numpy_core(
    name: str, kernel: types.ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    model = MODELS[name]
    D, rates, accelerations = _states(model, np.random.default_rng(31), 400)
    with numpy_only(core.KERNEL):
        reference = model.state(D, rates, accelerations)
        free = model.state(D, rates)
    # The single calls must not touch the numpy core.
    monkeypatch.setattr(model, "_solve", lambda *_a, **_k: pytest.fail("numpy path taken"))
    for i in range(len(D)):
        one = model.state(D[i], rates[i], accelerations[i])
        for field in FIELDS:
            _close(getattr(one, field), getattr(reference, field)[i])
        _close(model.state(D[i], rates[i]).Q_ddot, free.Q_ddot[i])
        _close(model.pose(D[i]), reference.Q[i])
        _close(model.jc0(D[i]), reference.jc0[i])


@pytest.mark.parametrize("name", FILES)
def test_batches_equal_the_numpy_core(
    name: str, kernel: types.ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    model = MODELS[name]
    D, rates, accelerations = _states(model, np.random.default_rng(32), 300)
    grid = D.reshape(20, 15, model.m)
    read_only = rates.copy()
    read_only.flags.writeable = False
    calls = [
        lambda: model.state(D, rates, accelerations),
        lambda: model.state(grid, rates.reshape(grid.shape)),
        lambda: model.state(D[:1], rates[0]),  # a batch of one, the rates broadcast
        lambda: model.state(np.asfortranarray(D), read_only, accelerations.tolist()),  # copied
    ]
    with monkeypatch.context() as kernel_only:  # batches must not touch the numpy core either
        kernel_only.setattr(model, "_solve", lambda *_a, **_k: pytest.fail("numpy path taken"))
        compiled = [call() for call in calls]
        poses = [model.pose(D), model.pose(grid), model.pose(D[:1])]
    with numpy_only(core.KERNEL):
        reference = [call() for call in calls]
        reference_poses = [model.pose(D), model.pose(grid), model.pose(D[:1])]
    for got, expected in zip(compiled, reference, strict=True):
        for field in FIELDS:
            _close(getattr(got, field), getattr(expected, field))
    for got, expected in zip(poses, reference_poses, strict=True):
        _close(got, expected)


@pytest.mark.parametrize("name", FILES)
def test_the_kernel_refuses_and_the_numpy_path_names_the_actuator(
    name: str, kernel: types.ModuleType
) -> None:
    model = MODELS[name]
    D, rates = model.reference.copy(), 0.1 * model.max_speed
    table, Q, J = np.empty(model._table_shape), np.empty(model._nq), np.empty((model._nq, model.m))
    span = model.upper - model.lower
    for i, actuator in enumerate(model.actuator_names):
        for value in (model.lower[i] - 1e-6 * span[i], model.upper[i] + 1e-6 * span[i], np.nan, np.inf):
            bad = D.copy()
            bad[i] = value
            assert not kernel.state(model._code, model._constants, bad, rates, rates, table)
            assert not kernel.pose(model._code, model._constants, bad, Q)
            assert not kernel.jc0(model._code, model._constants, bad, J)
            for call in (
                lambda bad=bad: model.state(bad, rates),
                lambda bad=bad: model.pose(bad),
                lambda bad=bad: model.jc0(bad),
                lambda bad=bad: model.cylinder_rates(bad, np.zeros(model._nq)),
                lambda bad=bad: model.state(np.stack((D, bad)), rates),
                lambda bad=bad: model.pose(np.stack((D, bad))),
            ):
                with pytest.raises(StrokeError, match=rf"D\[{i}\] = .* \({actuator}\)"):
                    call()
    with pytest.raises(StrokeError, match="D_ddot"):
        model.state(D, rates, np.full(model.m, np.nan))
    with pytest.raises(StrokeError, match="D_dot"):
        model.state(D, np.full(model.m, np.inf))
    with pytest.raises(StrokeError, match="D_dot: expected shape"):
        model.state(D, np.zeros(model.m + 1))
    with pytest.raises(StrokeError, match="expected"):
        model.state(np.append(D, 0.0), np.zeros(model.m + 1))


def test_arguments_the_kernel_does_not_take_go_the_numpy_way(kernel: types.ModuleType) -> None:
    """Lists, integers and strided views: numba compiles nothing new in a call (disable_compile),
    the numpy path answers the same."""
    model = MODELS["KC100"]
    D, rates = model.reference.copy(), 0.1 * model.max_speed
    one = model.state(D, rates)
    strided = np.stack((D, D), axis=1)[:, 0]
    assert not strided.flags.c_contiguous
    for got in (model.state(list(D), list(rates)), model.state(strided, rates)):
        _close(got.Q, one.Q)
        _close(got.jc0, one.jc0)
    _close(model.pose(strided), one.Q)


def test_a_kernel_compiled_for_another_layout_is_refused(kernel: types.ModuleType) -> None:
    assert kernel.layout_signature() == layout.SIGNATURE
    stale = types.SimpleNamespace(__name__="stale", layout_signature=lambda: layout.SIGNATURE + 1)
    with pytest.raises(RuntimeError, match="another program layout"):
        layout.check_compiled(stale)  # type: ignore[arg-type]


def test_mk_compiled_0_keeps_the_numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(core.KERNEL, "ready", None)
    monkeypatch.setenv("MK_COMPILED", "0")
    assert core.compiled_kernel() is None
    model = MODELS["WL20"]
    calls = 0
    real = model._solve

    def counted(*arguments, **keywords):  # type: ignore[no-untyped-def]
        nonlocal calls
        calls += 1
        return real(*arguments, **keywords)

    monkeypatch.setattr(model, "_solve", counted)
    model.state(model.reference, np.zeros(model.m))
    model.pose(model.reference)
    assert calls == 2
