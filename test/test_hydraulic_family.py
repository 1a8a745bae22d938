"""The hydraulic family core against independent references: the reference note's check values
(WL20 wheel loader, KC100 knuckle crane, CET200), central finite differences and the implicit
function theorem on the loop closures (complex-step derivatives of rigid-body closure equations
written here, not the dyad solver's), the open chain (J0 K = JC0), assembly over the stroke box
(every dyad closes and keeps its branch), the stroke box's faces, the CET200 against
``excavator_kinematics`` and the inverses (eqs. 9, 12-13, position IK)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from manipulator_kinematics.hydraulic import HydraulicModel, StrokeError
from manipulator_kinematics.param_files import config_path

LOADER = HydraulicModel.from_file(config_path("wheel_loader_wl20.yaml"))
CRANE = HydraulicModel.from_file(config_path("knuckle_crane_kc100.yaml"))
CET200 = HydraulicModel.from_file(config_path("excavator_cet200.yaml"))
MODELS = {"WL20": LOADER, "KC100": CRANE, "CET200": CET200}
RNG = np.random.default_rng(20261204)
DEG = np.pi / 180.0


def inside(model: HydraulicModel, n: int, margin: float = 0.02) -> np.ndarray:
    span = model.upper - model.lower
    return RNG.uniform(model.lower + margin * span, model.upper - margin * span, size=(n, model.m))


# ------------------------------------------------------------------ the note's check values
def test_loader_reference_state() -> None:
    D = [1.323, 1.624]
    np.testing.assert_allclose(LOADER.joints(D), [-0.583821245, 0.284534435], atol=1e-8)
    np.testing.assert_allclose(LOADER.pose(D), [3.249479, 0.0, -0.001644, -0.299286810], atol=1e-6)
    left, right = LOADER.corners(D)
    np.testing.assert_allclose(left, [3.249479, 1.5, -0.001644], atol=1e-6)
    np.testing.assert_allclose(right, [3.249479, -1.5, -0.001644], atol=1e-6)
    np.testing.assert_allclose(LOADER.pins(D)["bucket_hinge"], [1.949935, 0.0, 0.399337], atol=1e-6)
    jc0 = [[1.781698, 0.571081], [0, 0], [2.794596, 1.850825], [0.141041, 1.424211]]
    np.testing.assert_allclose(LOADER.jc0(D), jc0, atol=1e-6)
    np.testing.assert_allclose(LOADER.k_matrix(D), [[0.985423, 0], [-0.844382, 1.424211]], atol=1e-6)
    floor = LOADER.pose(D)[3] / DEG + 17.10
    assert abs(floor - -0.048) < 1e-3


@pytest.mark.parametrize(
    ("D", "hinge", "t2", "t3", "floor", "edge"),
    [
        ([1.300, 2.020], (1.9097, 0.3398), -34.747, 59.874, 42.23, (3.141, 0.917)),
        ([1.300, 1.395], (1.9097, 0.3398), -34.747, -2.268, -19.91, (2.996, -0.479)),
        ([2.300, 1.395], (1.8681, 4.0186), 36.040, -101.122, -47.98, (2.441, 2.785)),
        ([2.300, 2.020], (1.8681, 4.0186), 36.040, 0.146, 53.29, (2.966, 4.822)),
    ],
)
def test_loader_stroke_box_corners(D, hinge, t2, t3, floor, edge) -> None:
    pins = LOADER.pins(D)
    np.testing.assert_allclose(pins["bucket_hinge"][[0, 2]], hinge, atol=1e-4)
    np.testing.assert_allclose(LOADER.joints(D) / DEG, [t2, t3], atol=1e-3)
    Q = LOADER.pose(D)
    assert abs(Q[3] / DEG + 17.10 - floor) < 0.01
    np.testing.assert_allclose(Q[[0, 2]], edge, atol=1e-3)


def test_crane_reference_state() -> None:
    D = [0.0, 2.100, 2.200, 3.100]
    np.testing.assert_allclose(CRANE.joints(D), [0.0, 0.351654536, -1.136983004, 0.5], atol=1e-8)
    np.testing.assert_allclose(CRANE.pose(D), [7.092317, 0.0, 0.847761], atol=1e-6)
    jc0 = [[0, 2.406623, 9.705347, 0.707156], [7.092317, 0, 0, 0], [0, 11.338958, 9.706700, -0.707057]]
    np.testing.assert_allclose(CRANE.jc0(D), jc0, atol=1e-6)
    np.testing.assert_allclose(CRANE.k_matrix(D), np.diag([1, 1.657181, 3.347900, 1]), atol=1e-6)
    reference = {
        "knuckle_pin": (4.192977, 3.746697),
        "fold_cyl_rod": (4.150831, 3.332883),
        "coupler_pin": (4.488557, 3.618024),
        "tele_cyl_rod": (6.809455, 1.130584),
    }
    pins = CRANE.pins(D)
    for name, rz in reference.items():
        np.testing.assert_allclose(pins[name][[0, 2]], rz, atol=1e-6, err_msg=name)


@pytest.mark.parametrize(
    ("D", "t2", "t3", "d4", "tool"),
    [
        ([0, 1.650, 1.650, 2.600], -25.015, -164.884, 0.0, (0.5096, 1.1429)),
        ([0, 2.560, 2.550, 4.600], 72.256, 15.063, 2.0, (1.7919, 11.8941)),
        ([0, 1.650, 2.550, 4.600], -25.015, 15.063, 2.0, (9.5718, -0.4437)),
        ([0, 2.560, 1.650, 2.600], 72.256, -164.884, 0.0, (1.3649, 2.7040)),
    ],
)
def test_crane_stroke_box_corners(D, t2, t3, d4, tool) -> None:
    theta = CRANE.joints(D)
    np.testing.assert_allclose(theta[1:3] / DEG, [t2, t3], atol=1e-3)
    assert abs(theta[3] - d4) < 1e-12
    np.testing.assert_allclose(CRANE.pose(D)[[0, 2]], tool, atol=1e-4)


def test_crane_swing_turns_the_boom_plane() -> None:
    Q = CRANE.pose([np.pi / 2, 2.1, 2.2, 3.1])
    np.testing.assert_allclose(Q, [0.0, 7.092317, 0.847761], atol=1e-6)


def test_cet200_reference_state() -> None:
    D = CET200.reference
    np.testing.assert_allclose(CET200.joints(D)[1:] / DEG, [34.123830, -124.135605, -31.496482], atol=1e-6)
    np.testing.assert_allclose(CET200.pose(D), [4.209238, 0.0, 1.008412, -121.508257 * DEG], atol=1e-6)


# ------------------------------------------------------------------ independent derivatives
def _fd(f, D: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of f at D, columns per D entry: (..., m)."""
    cols = []
    for i in range(D.shape[-1]):
        step = np.zeros(D.shape[-1])
        step[i] = h
        cols.append((f(D + step) - f(D - step)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("name", MODELS)
def test_k_j0_jc0_against_finite_differences(name: str) -> None:
    model = MODELS[name]
    D = inside(model, 20, margin=0.01)
    np.testing.assert_allclose(model.k_matrix(D), _fd(model.joints, D), atol=2e-7)
    np.testing.assert_allclose(model.jc0(D), _fd(model.pose, D), atol=2e-7)
    theta = model.joints(D)
    np.testing.assert_allclose(model.j0(theta), _fd(model.open_chain_pose, theta), atol=2e-7)
    np.testing.assert_allclose(model.j0(theta) @ model.k_matrix(D), model.jc0(D), atol=1e-12)
    np.testing.assert_allclose(model.open_chain_pose(theta), model.pose(D), atol=1e-12)


def _closure(model: HydraulicModel, u: np.ndarray, D: np.ndarray, bodies: list[str]) -> np.ndarray:
    """The loop closures Phi(u, D) = 0 written from the machine file alone: u = (origin r, origin z,
    angle) per moving body; shared pins coincide, |rod - base|^2 = L^2 per cylinder, a prismatic
    child sits on its parent's axis, parallel to it. Complex-safe (no abs, no sqrt)."""
    d = model.description
    frames = {d.ground: (np.zeros(2), 0.0)}
    for k, body in enumerate(bodies):
        frames[body] = (u[3 * k : 3 * k + 2], u[3 * k + 2])

    def world(body: str, local: np.ndarray) -> np.ndarray:
        o, phi = frames[body]
        c, s = np.cos(phi), np.sin(phi)
        return o + np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]])

    owners: dict[str, list[str]] = {}
    for body, pins in d.bodies.items():
        for pin in pins:
            owners.setdefault(pin, []).append(body)
    slid = {}
    for joint in d.joints:
        if joint.slide is not None:
            slid[joint.slide.index] = joint.slide
    rows = []
    for pin, names in owners.items():
        if len(names) == 2:
            rows.extend(world(names[0], d.bodies[names[0]][pin]) - world(names[1], d.bodies[names[1]][pin]))
    for c in d.cylinders:
        if c.index in slid:
            s = slid[c.index]
            phi = frames[s.parent][1]
            axis = np.array([s.axis_point[0] + D[c.index] + s.offset, s.axis_point[1]])
            rows.extend(frames[s.child][0] - world(s.parent, axis))
            rows.append(np.sin(frames[s.child][1] - phi))  # parallel (angles equal modulo 2 pi)
            continue
        (base,), (rod,) = owners[c.base], owners[c.rod][:1]
        e = world(rod, d.bodies[rod][c.rod]) - world(base, d.bodies[base][c.base])
        rows.append(e @ e - D[c.index] ** 2)
    return np.array(rows)


def _bodies_of(model: HydraulicModel, D: np.ndarray) -> tuple[list[str], np.ndarray]:
    """Each moving body's (origin, angle) from two of its pins (pins() at swing 0)."""
    d = model.description
    pins = model.pins(D)
    names = [b for b in d.bodies if b != d.ground]
    u = []
    for body in names:
        (p1, l1), (p2, l2) = [(pins[p][[0, 2]], xz) for p, xz in list(d.bodies[body].items())[:2]]
        phi = np.arctan2(*(p2 - p1)[::-1]) - np.arctan2(*(l2 - l1)[::-1])
        c, s = np.cos(phi), np.sin(phi)
        u.extend([*(p1 - np.array([c * l1[0] - s * l1[1], s * l1[0] + c * l1[1]])), phi])
    return names, np.array(u)


@pytest.mark.parametrize("name", MODELS)
def test_k_and_jc0_by_the_implicit_function_theorem(name: str) -> None:
    """du/dD = -Phi_u^-1 Phi_D with complex-step Phi_u, Phi_D: the chain's angles and the tool
    point from u must give K and the boom-plane rows of JC0."""
    model = MODELS[name]
    d = model.description
    for D in inside(model, 5):
        if model.swing:
            D[0] = 0.0
        bodies, u = _bodies_of(model, D)
        assert np.max(np.abs(_closure(model, u, D, bodies))) < 1e-12
        h = 1e-30
        phi_u = np.stack(
            [_closure(model, u + 1j * h * e, D, bodies).imag / h for e in np.eye(len(u))], axis=-1
        )
        phi_D = np.stack(
            [_closure(model, u, D + 1j * h * e, bodies).imag / h for e in np.eye(len(D))], axis=-1
        )
        assert phi_u.shape[0] == phi_u.shape[1], "as many closures as unknowns"
        du = -np.linalg.solve(phi_u, phi_D)  # (3 bodies, m)
        angle = {d.ground: np.zeros(len(D))} | {b: du[3 * k + 2] for k, b in enumerate(bodies)}
        K = model.k_matrix(D)
        for i, joint in enumerate(d.joints):
            row = i + int(model.swing)
            if joint.slide is None:
                np.testing.assert_allclose(K[row], angle[joint.child] - angle[joint.parent], atol=1e-9)
        k = bodies.index(d.tool_body)
        phi = u[3 * k + 2]
        local = d.bodies[d.tool_body][d.tool_pin]
        w = np.array(
            [np.cos(phi) * local[0] - np.sin(phi) * local[1], np.sin(phi) * local[0] + np.cos(phi) * local[1]]
        )
        tool = du[3 * k : 3 * k + 2] + np.outer([-w[1], w[0]], du[3 * k + 2])
        jc0 = model.jc0(D)
        np.testing.assert_allclose(jc0[0, int(model.swing) :], tool[0, int(model.swing) :], atol=1e-9)
        np.testing.assert_allclose(jc0[2, int(model.swing) :], tool[1, int(model.swing) :], atol=1e-9)
        if d.has_angle:
            np.testing.assert_allclose(jc0[3], angle[d.tool_body], atol=1e-9)
        if model.swing:  # the swing column: the tool point turns about z at radius r
            np.testing.assert_allclose(jc0[:3, 0], [0.0, model.pose(D)[0], 0.0], atol=1e-12)
        assert np.linalg.cond(phi_u) < 1e4


def _directional(
    model: HydraulicModel,
    bodies: list[str],
    u: np.ndarray,
    u_dot: np.ndarray,
    D: np.ndarray,
    rates: np.ndarray,
    h: float = 1e-30,
) -> np.ndarray:
    """d/ds Phi(u + s u_dot, D + s rates) at s = 0, by complex step."""
    return _closure(model, u + 1j * h * u_dot, D + 1j * h * rates, bodies).imag / h


@pytest.mark.parametrize("name", MODELS)
def test_accelerations_by_the_implicit_function_theorem(name: str) -> None:
    """Phi(u(t), D(t)) = 0 differentiated twice: Phi_u uddot = -(Phi_D Dddot + the second
    directional derivative of Phi along (udot, Ddot)), the latter a central difference of
    complex-step directional derivatives; the angles and the tool point of u give theta_ddot and
    the boom-plane rows of Q_ddot (swing held: its rate and acceleration 0)."""
    model = MODELS[name]
    d = model.description
    h, eps = 1e-30, 1e-5
    for D in inside(model, 3, margin=0.05):
        rates = RNG.uniform(-1, 1, D.shape) * model.max_speed
        accelerations = RNG.uniform(-1, 1, D.shape) * model.max_speed
        if model.swing:
            D[0] = rates[0] = accelerations[0] = 0.0
        bodies, u = _bodies_of(model, D)
        phi_u = np.stack(
            [_closure(model, u + 1j * h * e, D, bodies).imag / h for e in np.eye(len(u))], axis=-1
        )
        phi_D = np.stack(
            [_closure(model, u, D + 1j * h * e, bodies).imag / h for e in np.eye(len(D))], axis=-1
        )
        u_dot = -np.linalg.solve(phi_u, phi_D @ rates)

        ahead, back = (
            _directional(model, bodies, u + t * u_dot, u_dot, D + t * rates, rates) for t in (eps, -eps)
        )
        second = (ahead - back) / (2 * eps)
        u_ddot = -np.linalg.solve(phi_u, second + phi_D @ accelerations)
        state = model.state(D, rates, accelerations)
        angle = {d.ground: (0.0, 0.0)} | {
            b: (u_dot[3 * k + 2], u_ddot[3 * k + 2]) for k, b in enumerate(bodies)
        }
        for i, joint in enumerate(d.joints):
            if joint.slide is None:
                expected = angle[joint.child][1] - angle[joint.parent][1]
                assert abs(state.theta_ddot[i + int(model.swing)] - expected) < 1e-5
        k = bodies.index(d.tool_body)
        phi, phi_dot, phi_ddot = u[3 * k + 2], u_dot[3 * k + 2], u_ddot[3 * k + 2]
        local = d.bodies[d.tool_body][d.tool_pin]
        c, s = np.cos(phi), np.sin(phi)
        w = np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]])
        tool = u_ddot[3 * k : 3 * k + 2] + phi_ddot * np.array([-w[1], w[0]]) - phi_dot**2 * w
        np.testing.assert_allclose(state.Q_ddot[[0, 2]], tool, atol=1e-5)
        if d.has_angle:
            assert abs(state.Q_ddot[3] - phi_ddot) < 1e-5


@pytest.mark.parametrize("name", MODELS)
def test_accelerations_against_finite_differences(name: str) -> None:
    """Q along D(t) = D + Ddot t + Dddot t^2 / 2: central first and second differences of pose()
    against state()'s Q_dot and Q_ddot (eqs. 10-11), theta likewise."""
    model = MODELS[name]
    D = inside(model, 8, margin=0.05)
    rates = RNG.uniform(-1, 1, D.shape) * model.max_speed
    accelerations = RNG.uniform(-1, 1, D.shape) * model.max_speed
    state = model.state(D, rates, accelerations)
    h = 1e-4

    def at(t: float, f) -> np.ndarray:
        return f(D + rates * t + 0.5 * accelerations * t * t)

    for f, value, first, second in (
        (model.pose, state.Q, state.Q_dot, state.Q_ddot),
        (model.joints, state.theta, state.theta_dot, state.theta_ddot),
    ):
        ahead, here, back = at(h, f), at(0.0, f), at(-h, f)
        np.testing.assert_allclose(value, here, atol=1e-12)
        np.testing.assert_allclose(first, (ahead - back) / (2 * h), atol=1e-6)
        np.testing.assert_allclose(second, (ahead - 2 * here + back) / (h * h), atol=5e-5)
    np.testing.assert_allclose(state.jc0, model.jc0(D), atol=1e-14)
    np.testing.assert_allclose(state.Q_dot, (state.jc0 @ rates[..., None])[..., 0], atol=1e-12)


def test_one_state_is_a_batch_of_one() -> None:
    D = inside(CRANE, 6).reshape(2, 3, 4)
    batch = CRANE.state(D, np.ones_like(D) * 0.1, np.ones_like(D) * 0.05)
    one = CRANE.state(D[1, 2], np.ones(4) * 0.1, np.ones(4) * 0.05)
    for a, b in zip(batch, one, strict=True):
        np.testing.assert_allclose(a[1, 2], b, atol=1e-15)


# ------------------------------------------------------------------ the stroke box
@pytest.mark.parametrize("name", MODELS)
def test_refused_beyond_every_face(name: str) -> None:
    model = MODELS[name]
    for i, actuator in enumerate(model.actuator_names):
        for face, step in ((model.lower[i], -1e-9), (model.upper[i], 1e-9)):
            D = model.reference.copy()
            D[i] = face
            model.pose(D)  # the faces are inside
            D[i] = face + step * max(1.0, abs(face))
            with pytest.raises(StrokeError, match=rf"^D\[{i}\] = .*\({actuator}\) is outside its stroke"):
                model.pose(D)
    with pytest.raises(StrokeError, match=r"^D\[0\] = nan .* is not finite"):
        model.pose(np.full(model.m, np.nan))


#: The smallest dead-centre margins over a 201-point grid (loader) / 41-point grid, from the note.
NOTE_MARGINS = {"WL20": (30.4, 22.0, 22.0), "KC100": (36.3, 45.2, 45.3)}


@pytest.mark.parametrize("name", MODELS)
def test_assembly_over_the_stroke_box(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Every grid state assembles; the tool moves between grid neighbours as its Jacobian says
    (a branch jump would move it by a finite step); margins as the note states."""
    model = MODELS[name]
    n = 61 if model.m == 2 else 21
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(model.lower, model.upper, strict=True)]
    if model.swing:
        axes[0] = np.array([0.0])
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    margins = model.margins(grid)
    assert np.all(np.isfinite(margins)) and np.all(margins > 0)
    Q, jc0 = model.pose(grid), model.jc0(grid)
    for axis in range(int(model.swing), model.m):
        step = np.diff(grid, axis=axis)
        predicted = 0.5 * (np.take(jc0, range(n - 1), axis=axis) + np.take(jc0, range(1, n), axis=axis))
        moved = np.diff(Q, axis=axis)
        linear = (predicted @ step[..., None])[..., 0]
        assert np.max(np.abs(moved - linear)) < 0.05 * np.max(np.abs(moved)) + 1e-12
    low = np.degrees(margins.reshape(-1, margins.shape[-1]).min(axis=0))
    with capsys.disabled():
        print(
            f"\n{name}: smallest dead-centre margin per dyad over the box (deg): "
            + ", ".join(f"{d} {v:.2f}" for d, v in zip(model.dyad_names, low, strict=True))
        )
    if name in NOTE_MARGINS:
        assert np.all(low >= np.array(NOTE_MARGINS[name]) - 0.05)


#: K entries over the box, from the note: (row theta_i, column D_j) -> (min, max), rounded.
NOTE_K = {
    "WL20": {(0, 0): (0.98, 1.90), (1, 1): (1.39, 4.52), (1, 0): (-2.99, -0.84)},
    "KC100": {(1, 1): (1.64, 2.77), (2, 2): (2.90, 4.43)},
}


@pytest.mark.parametrize("name", NOTE_K)
def test_k_ranges_and_reach_over_the_box(name: str) -> None:
    """Each driven K entry keeps one sign over the box, within the note's ranges; and the note's
    reach and heights (loader hinge 0.340 .. 4.019 m, crane reach 10.049 m, -5.07 .. 11.89 m)."""
    model = MODELS[name]
    n = 41
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(model.lower, model.upper, strict=True)]
    if model.swing:
        axes[0] = np.array([0.0])
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, model.m)
    K = model.k_matrix(grid)
    for (i, j), (low, high) in NOTE_K[name].items():
        assert low - 0.006 <= K[:, i, j].min() <= low + 0.006, (i, j, K[:, i, j].min())
        assert high - 0.006 <= K[:, i, j].max() <= high + 0.006, (i, j, K[:, i, j].max())
    Q = model.pose(grid)
    if name == "WL20":
        hinge = model.pins(grid)["bucket_hinge"][:, 2]
        assert abs(hinge.min() - 0.340) < 5e-4 and abs(hinge.max() - 4.019) < 5e-4
    else:
        assert abs(Q[:, 0].max() - 10.049) < 5e-4
        assert abs(Q[:, 2].min() - -5.07) < 5e-3 and abs(Q[:, 2].max() - 11.89) < 5e-3


# ------------------------------------------------------------------ the CET200 equals the excavator's kernel
def test_cet200_equals_excavator_kinematics() -> None:
    """The excavator's numpy path is this core (Excavator.hydraulic); its compiled kernel
    (excavator_kinematics.core.state_kernel, the folded linkages of eqs. 1-2) is the independent
    side: K through theta_dot = K Ddot."""
    from excavator_kinematics.core.kinematics import Excavator, compiled_kernel

    excavator = Excavator.default()
    assert compiled_kernel(excavator, wait=True) is not None
    lo, hi = excavator.limits.d_min, excavator.limits.d_max
    D = RNG.uniform(lo, hi, size=(200, 4))
    rates = RNG.uniform(-1, 1, D.shape) * CET200.max_speed
    accelerations = RNG.uniform(-1, 1, D.shape)
    np.testing.assert_allclose(CET200.pose(D), excavator.pose(D), rtol=0, atol=1e-12)
    np.testing.assert_allclose(CET200.jc0(D), excavator.jc0(D), rtol=0, atol=1e-12)
    ours, theirs = CET200.state(D, rates, accelerations), excavator.state(D, rates, accelerations)
    for field in ("theta", "theta_dot", "theta_ddot", "Q", "Q_dot", "Q_ddot", "jc0"):
        np.testing.assert_allclose(
            getattr(ours, field), getattr(theirs, field), rtol=0, atol=1e-12, err_msg=field
        )
    one = CET200.state(D[0], rates[0], accelerations[0])
    np.testing.assert_allclose(
        one.Q_ddot, excavator.state(D[0], rates[0], accelerations[0]).Q_ddot, atol=1e-12
    )


# ------------------------------------------------------------------ inverses (eqs. 9, 12-13)
@pytest.mark.parametrize("name", MODELS)
def test_cylinder_rates_and_accelerations_invert_the_forward_state(name: str) -> None:
    model = MODELS[name]
    D = inside(model, 10)
    rates = RNG.uniform(-1, 1, D.shape) * model.max_speed
    accelerations = RNG.uniform(-1, 1, D.shape) * model.max_speed
    state = model.state(D, rates, accelerations)
    rows = list(model.description.velocity_rows)
    solution = model.cylinder_rates(D, state.Q_dot)
    # the commanded rows are met exactly, whatever the shape of JC0 there
    np.testing.assert_allclose(solution.Q_dot[..., rows], state.Q_dot[..., rows], atol=1e-10)
    got = model.cylinder_accelerations(D, solution.D_dot, state.Q_ddot)
    free = model.state(D, solution.D_dot, got)
    np.testing.assert_allclose(
        free.Q_ddot[..., rows],
        state.Q_ddot[..., rows] if len(rows) == model.m or len(rows) < model.m else free.Q_ddot[..., rows],
        atol=1e-9,
    )
    if len(rows) == model.m:  # square: the very rates and accelerations come back
        np.testing.assert_allclose(solution.D_dot, rates, atol=1e-10)
        np.testing.assert_allclose(got, accelerations, atol=1e-8)


def test_crane_velocity_ik_is_the_smallest_speed_scaled_solution() -> None:
    """3 task rows, 4 actuators: among all D_dot giving Q_dot, the one with the smallest
    ||D_dot / max_speed|| (orthogonal to JC0's null space in the scaled coordinates)."""
    D = inside(CRANE, 1)[0]
    solution = CRANE.cylinder_rates(D, [0.1, -0.2, 0.3])
    jc0 = CRANE.jc0(D)
    scaled = jc0 * CRANE.max_speed
    null = np.linalg.svd(scaled)[2][-1]
    assert abs(null @ (solution.D_dot / CRANE.max_speed)) < 1e-12
    np.testing.assert_allclose(jc0 @ solution.D_dot, [0.1, -0.2, 0.3], atol=1e-12)


# ------------------------------------------------------------------ malformed machine files
def _loader_section() -> dict:
    import copy

    from manipulator_kinematics.param_files import load_parameters

    return copy.deepcopy(load_parameters(config_path("wheel_loader_wl20.yaml"))["hydraulic_machine"])


def _edit(section: dict, path: str, value: object) -> None:
    *keys, last = path.split(".")
    for key in keys:
        section = section[key]
    if value is None:
        del section[last]
    else:
        section[last] = value


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        # a dyad that never closes: the tilt link far too long for the bucket's link pin
        ("links.tilt_link.length", 3.0, r"dyads\.tilt_link_bucket_pin: does not close at D = "),
        # the lift cylinder's rod on the other side: the lift arm swings behind, below the machine
        (
            "dyads.lift_cyl_rod.orientation",
            -1,
            r"dyads\.lift_cyl_rod\.orientation: theta2 = .* at the reference state, outside its limits",
        ),
        ("dyads.tilt_link_bucket_pin.orientation", 1, r"dyads\.tilt_link_bucket_pin\.orientation: theta3"),
        # a pin named twice: the arm pivot listed again on the bell crank
        (
            "bodies.bell_crank.pins.lift_arm_pivot",
            [0.1, 0.1],
            r"bodies\.bell_crank\.pins\.lift_arm_pivot: pin 'lift_arm_pivot' named twice",
        ),
        # a loop left open: no body joins the arm pivot and the bucket's link pin
        (
            "dyads.tilt_link_bucket_pin.pivot",
            "lift_arm_pivot",
            r"dyads\.tilt_link_bucket_pin\.pivot: loop left open: no body or cylinder joins",
        ),
        # a body never placed
        (
            "bodies.counterweight",
            {"pins": {"cw_a": [0.0, 0.0], "cw_b": [1.0, 0.0]}},
            r"bodies\.counterweight: never placed",
        ),
        (
            "dyads.tilt_cyl_rod.pivot",
            "cutting_edge",
            r"dyads\.tilt_cyl_rod\.pivot: pin 'cutting_edge' is not known",
        ),
        (
            "assembly",
            ["tilt_cyl_rod", "lift_cyl_rod", "tilt_link_bucket_pin"],
            r"dyads\.tilt_cyl_rod\.pivot: pin 'bell_crank_pivot' is not known at this step",
        ),
        (
            "dyads.lift_cyl_rod.orientaton",
            1,
            r"dyads\.lift_cyl_rod\.orientaton: unknown key \(did you mean 'orientation'",
        ),
        ("cylinders.tilt_cylinder.max_speed", None, r"cylinders\.tilt_cylinder\.max_speed: missing"),
        ("cylinders.tilt_cylinder.min_length", 2.1, r"cylinders\.tilt_cylinder\.max_length: must exceed"),
        ("tool.width", "wide", r"tool\.width: expected a number"),
        ("cylinders.tilt_cylinder.zero_offset", 1.5, r"tilt_cylinder\.zero_offset = 1.5 is outside \[-1, 1"),
        ("cylinders.tilt_cylinder.zero_ofset", 0.01, r"zero_ofset: unknown key \(did you mean 'zero_offset'"),
        ("tool.velocity_rows", ["z", "beta"], r"tool\.velocity_rows: 'beta' is not one of"),
        ("tooll", {}, r"hydraulic_machine\.tooll: unknown key \(did you mean 'tool'"),
        ("chain.theta3.parent", "front_frame", r"chain\.theta3\.parent: must be 'lift_arm'"),
        ("chain.theta2.limits", [-0.6, 0.6], r"chain\.theta2\.limits: theta2 = .* at D = "),
        (
            "bodies.lift_arm.pins.bucket_hinge",
            [3.176, "0"],
            r"bodies\.lift_arm\.pins\.bucket_hinge\[1\]: expected a number",
        ),
    ],
)
def test_malformed_machine_file_refused_with_the_key(path: str, value: object, message: str) -> None:
    from manipulator_kinematics.hydraulic import parse
    from manipulator_kinematics.param_files import ConfigError

    section = _loader_section()
    _edit(section, path, value)
    with pytest.raises(ConfigError, match=message) as error:
        HydraulicModel(parse(section))
    assert "\n" not in str(error.value)


def test_zero_offsets_turn_readings_into_true_states() -> None:
    from manipulator_kinematics.hydraulic import parse

    section = _loader_section()
    _edit(section, "cylinders.lift_cylinder.zero_offset", 0.012)
    _edit(section, "cylinders.tilt_cylinder.zero_offset", -0.015)
    model = HydraulicModel(parse(section))
    readings = np.array([[1.5, 1.7], [2.0, 1.9]])
    D = model.from_readings(readings)
    np.testing.assert_allclose(D - readings, [[0.012, -0.015]] * 2, atol=1e-15)
    np.testing.assert_allclose(model.pose(D), LOADER.pose(readings + [0.012, -0.015]), atol=1e-12)
    np.testing.assert_allclose(model.to_readings(D), readings, atol=1e-15)
    np.testing.assert_array_equal(LOADER.zero_offset, [0.0, 0.0])  # absent: no offset
    with pytest.raises(StrokeError, match=r"D\[0\] = 2.31 \(lift_cylinder\) is outside its stroke"):
        model.from_readings([2.298, 1.7])  # the reading is inside, the true length is not


# ------------------------------------------------------------------ position IK (closed form)
@pytest.mark.parametrize("name", MODELS)
def test_fk_ik_round_trip(name: str) -> None:
    model = MODELS[name]
    D = RNG.uniform(model.lower, model.upper, size=(100, model.m))
    Q = model.pose(D)
    result = model.ik(Q, seed=D)
    assert np.all(result.valid)
    np.testing.assert_allclose(result.D, D, atol=1e-10)
    position = model.position_ik(Q[..., :3], seed=D)
    assert np.all(position.valid)
    np.testing.assert_allclose(position.D, D, atol=1e-10)
    # without a seed: any D of the box that reaches Q (the CET200 also reaches a tool behind the
    # swing axis turned by pi; the crane holds the reference extension, so not every Q)
    free = model.ik(Q)
    assert np.mean(free.valid) > 0.5
    np.testing.assert_allclose(model.pose(free.D[free.valid]), Q[free.valid], atol=1e-10)


def test_loader_ik_refuses_what_two_cylinders_cannot_reach() -> None:
    Q = LOADER.pose([1.8, 1.7])
    assert LOADER.ik(Q).valid
    assert not LOADER.ik(Q + [0.05, 0, 0, 0]).valid  # (x, z, alpha): three values, two actuators
    assert not LOADER.ik(Q + [0, 0, 3.0, 0]).valid  # beyond the lift
    # (x, z) alone: two elbow branches inside the box; the seed picks, both reach the point
    other = LOADER.position_ik(Q[:3])
    assert other.valid and abs(other.D[0] - 1.8) > 0.01
    np.testing.assert_allclose(LOADER.pose(other.D)[:3], Q[:3], atol=1e-10)
    np.testing.assert_allclose(LOADER.position_ik(Q[:3], seed=[1.79, 1.71]).D, [1.8, 1.7], atol=1e-10)


def test_crane_position_ik_keeps_the_seed_extension() -> None:
    seed = np.array([0.3, 2.0, 2.0, 3.9])
    target = CRANE.pose([0.5, 2.2, 2.3, 3.9])
    result = CRANE.position_ik(target, seed=seed)
    assert result.valid
    np.testing.assert_allclose(result.D, [0.5, 2.2, 2.3, 3.9], atol=1e-10)
    assert not CRANE.position_ik([30.0, 0.0, 1.0]).valid


def test_old_excavator_file_converts_to_the_family_form() -> None:
    """The CET200's file of the old form (test/data) converted equals the shipped file's family
    section."""
    from manipulator_kinematics.hydraulic import parse
    from manipulator_kinematics.hydraulic.convert import from_excavator_section
    from manipulator_kinematics.param_files import load_parameters

    old = load_parameters(Path(__file__).parent / "data" / "excavator_cet200_old_form.yaml")["excavator"]
    converted = HydraulicModel(parse(from_excavator_section(old)))
    D = inside(CET200, 50, margin=0.0)
    np.testing.assert_allclose(converted.pose(D), CET200.pose(D), rtol=0, atol=1e-12)
    np.testing.assert_allclose(converted.jc0(D), CET200.jc0(D), rtol=0, atol=1e-12)
    assert converted.actuator_names == CET200.actuator_names
    assert converted.description.width == CET200.description.width
