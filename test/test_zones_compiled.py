"""The avoidance zones' compiled paths against their numpy references, to 1e-12 of each quantity's
scale: the hydraulic family kernel's monitored points (``kernel.monitored``) for every shipped
family machine and one with a tool outline (with and without width) and a tail; the excavator's
monitored points (the family's of its machine file, under its names) against its own model's
pins and the tip's closed form (eq. 8); and the zone kernel's one-call check against the numpy
path with zones in the base and the site frame, TINs in both, and with and without a site pose."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.tri import Triangulation
from numpy_paths import numpy_only

from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.machine import MACHINE
from manipulator_kinematics.hydraulic import HydraulicModel, StrokeError
from manipulator_kinematics.hydraulic import model as core
from manipulator_kinematics.hydraulic.description import parse
from manipulator_kinematics.landxml import Tin
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.zones import KERNEL, Monitor, Zone


def _with_options(width: float) -> HydraulicModel:
    raw = load_parameters(config_path("knuckle_crane_kc100.yaml"))["hydraulic_machine"]
    raw["tool"].update(width=width, outline=[0.3, 0.2, -0.2, 0.4])
    raw["swing"].update(tail_radius=1.4, tail_heights=[0.3, 1.1])
    return HydraulicModel(parse(raw))


MODELS = {
    "CET200": HydraulicModel.from_file(config_path("excavator_cet200.yaml")),
    "WL20": HydraulicModel.from_file(config_path("wheel_loader_wl20.yaml")),
    "KC100": HydraulicModel.from_file(config_path("knuckle_crane_kc100.yaml")),
    "KC100 with outline and tail": _with_options(0.6),
    "KC100 with outline, no width": _with_options(0.0),
}


@pytest.fixture(scope="module", autouse=True)
def kernels() -> None:
    assert core.compiled_kernel(wait=True) is not None and KERNEL.get(wait=True) is not None


def _close(got: np.ndarray, expected: np.ndarray) -> None:
    """Within 1e-12 of the quantity's scale (its largest entry, at least 1)."""
    scale = max(1.0, float(np.max(np.abs(expected))))
    np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12 * scale)


@pytest.mark.parametrize("name", MODELS)
def test_the_compiled_monitored_points_are_the_numpy_ones(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    model = MODELS[name]
    rng = np.random.default_rng(34)
    span = model.upper - model.lower
    for trial in range(100):
        D = rng.uniform(model.lower, model.upper)
        if trial % 4 == 0:  # on a face of the stroke box
            j = rng.integers(model.m)
            D[j] = rng.choice([model.lower[j], model.upper[j], model.lower[j] + 1e-9 * span[j]])
        D_dot = rng.uniform(-2.0, 2.0, model.m) * model.max_speed
        with monkeypatch.context() as compiled_only:
            compiled_only.setattr(model, "_solve", lambda *_a, **_k: pytest.fail("numpy path taken"))
            names, p, v, a = model.monitored_motion(D, D_dot)
        with numpy_only(core.KERNEL):
            expected = model.monitored_motion(D, D_dot)
        assert names == expected[0]
        for got, want in zip((p, v, a), expected[1:], strict=True):
            _close(got, want)


def test_a_state_the_kernel_refuses_is_refused_by_the_numpy_path_naming_the_actuator() -> None:
    model = MODELS["WL20"]
    D = model.reference.copy()
    D[1] = model.upper[1] + 1e-6
    with pytest.raises(StrokeError, match=model.actuator_names[1]):
        model.monitored_motion(D, np.zeros(model.m))
    with pytest.raises(StrokeError, match="D_dot"):
        model.monitored_motion(model.reference, np.full(model.m, np.nan))


def test_the_excavators_points_are_its_own_models_pins_and_tip_velocity() -> None:
    """MonitoredPoints (the family's points of the machine file) against Excavator.pins (the
    excavator's own model), the corners a bucket width across, and the tip's velocity and
    acceleration against eq. 8 and its derivative along the command (central differences)."""
    exc = MACHINE.model()
    points = MonitoredPoints(exc)
    rng = np.random.default_rng(8)
    D = rng.uniform(exc.limits.d_min, exc.limits.d_max, (200, 4))
    D[::7, 2] = exc.limits.d_max[2]  # at a stroke end
    pins = exc.pins(D)
    p = points.positions(D)
    for i, name in enumerate(pins):
        _close(p[:, i], pins[name])
    tip = points.names.index("bucket_tip")
    for k in range(20):
        D_dot = rng.uniform(-1.0, 1.0, 4) * exc.limits.max_rates
        q, v, a = points.motion(D[k], D_dot)
        _close(q, p[k])
        _close(v[tip], exc.jc0(D[k])[:3] @ D_dot)
        h = 1e-5
        ends = D[k] + np.multiply.outer([-h, h], D_dot)
        if np.all((ends >= exc.limits.d_min) & (ends <= exc.limits.d_max)):
            along = (exc.jc0(D[k] + h * D_dot)[:3] - exc.jc0(D[k] - h * D_dot)[:3]) @ D_dot / (2 * h)
            np.testing.assert_allclose(a[tip], along, atol=1e-6)
    # A state a round-off beyond a stroke end (the excavator takes it) is taken at the end.
    beyond = exc.limits.reference.copy()
    beyond[1] = exc.limits.d_max[1] + 5e-10
    at_end = beyond.copy()
    at_end[1] = exc.limits.d_max[1]
    _close(points.motion(beyond, np.ones(4))[0], points.motion(at_end, np.ones(4))[0])


def test_the_one_call_check_is_the_numpy_check_in_both_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    """zone_kernel.check against the numpy path for zones of every kind in the base frame and
    (but sectors) in the site frame, a TIN in each, at random site poses and without one."""
    rng = np.random.default_rng(6)
    xy = rng.uniform(-6.0, 6.0, (80, 2))
    ground = Tin(np.column_stack([xy, 0.2 * xy[:, 0] - 0.1 * xy[:, 1]]), Triangulation(*xy.T).triangles)
    names = [f"p{i}" for i in range(25)]
    for trial in range(30):
        frames = ("base", "site") if trial % 3 else ("base", "base")
        zones = [
            Zone("ceiling", "ceiling", frames[1], 0.3, {"height": rng.uniform(2, 6)}),
            Zone("floor", "floor", frames[0], 0.1, {"height": rng.uniform(-3, 0)}),
            Zone(
                "wall",
                "wall",
                frames[1],
                0.2,
                {"point": rng.uniform(-4, 4, 2).tolist(), "normal": [1.0, 0.4]},
            ),
            Zone("box", "box", frames[1], 0.2, {"min": [-1.0, -1.0, -1.0], "max": [1.0, 2.0, 3.0]}),
            Zone("sector", "sector", "base", 0.1, {"from": rng.uniform(-3, 3), "to": rng.uniform(-3, 3)}),
            Zone("under", "surface", frames[1], 0.2, {"side": "below"}, ground),
            Zone("over", "surface", frames[0], 0.1, {"side": "above"}, ground),
        ]
        p = rng.uniform(-5.0, 5.0, (25, 3))
        v, a = rng.normal(size=(25, 3)), rng.normal(size=(25, 3))
        angle = rng.uniform(-np.pi, np.pi)
        R = np.array(
            [[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]]
        )
        site = None if trial % 5 == 4 else (R, rng.uniform(-2.0, 2.0, 3))
        flight = rng.normal(0.0, 0.5, (25, len(zones)))
        monitor = Monitor(zones, names)
        args = (p, v, rng.uniform(0.0, 0.5), rng.uniform(0.005, 0.1), site)
        curved = {"accelerations": a, "in_flight": flight, "delay": 0.03}
        numpy_path = monitor.check(*args, compiled=False, **curved)
        with monkeypatch.context() as compiled_only:
            compiled_only.setattr(monitor, "_numpy", lambda *_a: pytest.fail("numpy path taken"))
            compiled = monitor.check(*args, **curved)
        assert compiled.scale == pytest.approx(numpy_path.scale, abs=1e-12)
        assert (compiled.zone, compiled.point) == (numpy_path.zone, numpy_path.point)
        np.testing.assert_allclose(compiled.approach, numpy_path.approach, atol=1e-12)
        for name, (c, point) in numpy_path.clearance.items():
            assert compiled.clearance[name][0] == pytest.approx(c, abs=1e-12), name
            assert compiled.clearance[name][1] == point, name
