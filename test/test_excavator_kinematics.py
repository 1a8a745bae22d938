"""Excavator core against independent references: the reference note's check values, central
finite differences of every analytic derivative, rigid-body invariants of the pins, round trips,
batch == scalar, and the errors bad input must raise."""

from __future__ import annotations

import copy
from importlib.metadata import entry_points

import numpy as np
import pytest
import yaml

from excavator_kinematics.core.kinematics import (
    ACTUATORS,
    CYLINDERS,
    Excavator,
    StrokeError,
    bucket_angular_acceleration,
    bucket_angular_velocity,
    bucket_quaternion,
)
from excavator_kinematics.core.machine_file import GEOMETRY, SCHEMA
from excavator_kinematics.machine import MACHINE
from manipulator_kinematics.bag.topics import ACCEL, JOINT_STATE, POSE, TWIST
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.schema import validate

EXC = Excavator.default()
LIM = EXC.limits
RNG = np.random.default_rng(20261122)


def random_states(n: int, margin: float = 0.02) -> np.ndarray:
    """States inside the stroke box, away from the ends by `margin` of the stroke."""
    lo, hi = LIM.d_min.copy(), LIM.d_max.copy()
    span = hi - lo
    return RNG.uniform(lo + margin * span, hi - margin * span, size=(n, 4))


def random_rates(n: int) -> np.ndarray:
    return RNG.uniform(-1.0, 1.0, size=(n, 4)) * LIM.max_rates


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


# ---------------------------------------------------------------- the reference note's values
def test_reference_state_check_values():
    theta = np.degrees(EXC.joint_angles(LIM.reference[1:]))
    np.testing.assert_allclose(theta, [34.124, -124.136, -31.496], atol=5e-4)
    Q = EXC.pose(LIM.reference)
    np.testing.assert_allclose(Q[:3], [4.209238, 0.0, 1.008412], atol=5e-7)
    assert Q[3] == pytest.approx(np.radians(34.124 - 124.136 - 31.496), abs=1e-5)


def test_reference_assembly_branch_pins():
    pins = EXC.pins(LIM.reference)
    # Arm frame at the reference: rod pin (2.55558, 0.61407), H-link pin (3.10344, 0.42369).
    arm_pin, bucket_pin = pins["arm_pin"], pins["bucket_pin"]
    axis = (bucket_pin - arm_pin) / np.linalg.norm(bucket_pin - arm_pin)
    normal = np.array([-axis[2], 0.0, axis[0]])  # swing 0: the boom plane is x-z

    def arm_frame(p: np.ndarray) -> np.ndarray:
        return np.array([(p - arm_pin) @ axis, (p - arm_pin) @ normal])

    np.testing.assert_allclose(arm_frame(pins["bucket_cylinder_rod"]), [2.55558, 0.61407], atol=5e-6)
    np.testing.assert_allclose(arm_frame(pins["h_link_pin"]), [3.10344, 0.42369], atol=5e-6)


def test_joint_ranges_at_stroke_ends():
    # The note prints two decimals; its -44.05 is -44.0447 here (0.0053 deg, a rounding of the
    # note's), so compare at the printed precision.
    ends = np.degrees(EXC.joint_angles(np.stack((LIM.stroke_min, LIM.stroke_max))))
    np.testing.assert_allclose(np.sort(ends[:, 0]), [-30.42, 59.53], atol=1e-2)
    np.testing.assert_allclose(np.sort(ends[:, 1]), [-161.25, -44.05], atol=1e-2)
    np.testing.assert_allclose(np.sort(ends[:, 2]), [-132.91, 39.32], atol=1e-2)


def test_extension_senses():
    """Boom cylinder out raises the boom; arm and bucket cylinders out curl arm and bucket in."""
    k, _ = EXC.k_entries(random_states(500)[:, 1:])
    assert np.all(k[:, 0] > 0) and np.all(k[:, 1] < 0) and np.all(k[:, 2] < 0)


# ---------------------------------------------------------------- finite differences
H = 1e-6


def central_difference(f, x: np.ndarray, j: int, h: float = H) -> np.ndarray:
    """(f(x + h e_j) - f(x - h e_j)) / 2h for the last axis of a batch x."""
    step = np.zeros(x.shape[-1])
    step[j] = h
    return (f(x + step) - f(x - step)) / (2 * h)


@pytest.mark.parametrize("i", range(3))
def test_k_and_k1_against_central_differences(i):
    lengths = random_states(200)[:, 1:]
    k, dk = EXC.k_entries(lengths)
    fd_k = central_difference(EXC.joint_angles, lengths, i)[:, i]
    assert rel_err(k[:, i], fd_k) < 1e-6
    fd_dk = central_difference(lambda d: EXC.k_entries(d)[0], lengths, i, h=1e-5)[:, i]
    assert rel_err(dk[:, i], fd_dk) < 1e-6


def test_j0_against_central_differences():
    theta = EXC.state(random_states(100), np.zeros((100, 4))).theta
    j0 = EXC.j0(theta)
    for j in range(4):
        assert rel_err(j0[:, :, j], central_difference(EXC.open_chain_pose, theta, j)) < 1e-6


def test_jc0_against_central_differences_of_pose():
    D = random_states(100)
    jc0 = EXC.jc0(D)
    for j in range(4):
        assert rel_err(jc0[:, :, j], central_difference(EXC.pose, D, j)) < 1e-6


def test_jc0_is_j0_times_k():
    D = random_states(50)
    theta = EXC.state(D, np.zeros_like(D)).theta
    np.testing.assert_allclose(EXC.jc0(D), EXC.j0(theta) @ EXC.k_matrix(D), rtol=1e-13, atol=1e-13)


def _trajectory(D0, V, A, t):
    return D0 + V * t + 0.5 * A * t * t, V + A * t


def test_velocity_and_acceleration_against_differences_along_a_motion():
    """Qdot and Qddot of the state, differentiated numerically along D(t) = D0 + V t + A t^2/2."""
    D0, V = random_states(100, margin=0.1), random_rates(100)
    A = RNG.uniform(-0.5, 0.5, size=(100, 4))
    h = 1e-5
    now = EXC.state(D0, V, A)
    ahead = EXC.state(*_trajectory(D0, V, A, h), A)
    behind = EXC.state(*_trajectory(D0, V, A, -h), A)
    assert rel_err(now.Q_dot, (ahead.Q - behind.Q) / (2 * h)) < 1e-6
    assert rel_err(now.Q_ddot, (ahead.Q_dot - behind.Q_dot) / (2 * h)) < 1e-6
    assert rel_err(now.theta_ddot, (ahead.theta_dot - behind.theta_dot) / (2 * h)) < 1e-6


def test_paper_acceleration_matrices_match_state():
    """Eq. 11 (JC0 Dddot + JC1_0 Ddot^2 + JC2_0 DDdot, built from the Hessian) == eq. 10 path."""
    D, V = random_states(100), random_rates(100)
    A = RNG.uniform(-0.5, 0.5, size=(100, 4))
    jc1, jc2 = EXC.acceleration_matrices(D)
    pairs = np.stack([V[:, i] * V[:, j] for i in range(4) for j in range(i + 1, 4)], axis=-1)
    eq11 = (
        (EXC.jc0(D) @ A[..., None])[..., 0]
        + (jc1 @ (V * V)[..., None])[..., 0]
        + (jc2 @ pairs[..., None])[..., 0]
    )
    assert rel_err(eq11, EXC.state(D, V, A).Q_ddot) < 1e-12


# ---------------------------------------------------------------- rigid bodies
BODIES = {
    "upper structure": ("boom_foot", "boom_cylinder_base"),
    "boom": ("boom_foot", "boom_cylinder_rod", "arm_pin", "arm_cylinder_base"),
    "arm": ("arm_pin", "arm_cylinder_rod", "bucket_pin", "bucket_cylinder_base", "side_link_pivot"),
    "bucket": ("bucket_pin", "h_link_pin_on_bucket", "bucket_tip"),
}


def _dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a - b, axis=-1)


@pytest.mark.parametrize("body", BODIES)
def test_pin_distances_on_one_body_are_constant(body):
    pins = EXC.pins(random_states(300, margin=0.0))
    names = BODIES[body]
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            d = _dist(pins[a], pins[b])
            assert np.ptp(d) < 1e-12, (body, a, b)


def test_links_and_cylinders_close():
    D = random_states(300, margin=0.0)
    pins = EXC.pins(D)
    np.testing.assert_allclose(
        _dist(pins["boom_cylinder_base"], pins["boom_cylinder_rod"]), D[:, 1], atol=1e-12
    )
    np.testing.assert_allclose(
        _dist(pins["arm_cylinder_base"], pins["arm_cylinder_rod"]), D[:, 2], atol=1e-12
    )
    np.testing.assert_allclose(
        _dist(pins["bucket_cylinder_base"], pins["bucket_cylinder_rod"]), D[:, 3], atol=1e-12
    )
    np.testing.assert_allclose(_dist(pins["side_link_pivot"], pins["bucket_cylinder_rod"]), 0.62, atol=1e-12)
    np.testing.assert_allclose(_dist(pins["bucket_cylinder_rod"], pins["h_link_pin"]), 0.58, atol=1e-12)
    # The H-link reaches the bucket's own pin: the bucket four-bar closes.
    np.testing.assert_allclose(pins["h_link_pin"], pins["h_link_pin_on_bucket"], atol=1e-12)
    np.testing.assert_allclose(pins["bucket_tip"], EXC.pose(D)[:, :3], atol=1e-12)
    # Everything lies in the boom plane: normal (-sin t1, cos t1, 0).
    normal = np.stack((-np.sin(D[:, 0]), np.cos(D[:, 0]), np.zeros(len(D))), axis=-1)
    for p in pins.values():
        assert np.max(np.abs(np.sum(p * normal, axis=-1))) < 1e-12


def test_bucket_branch_is_continuous_over_the_stroke():
    d4 = np.linspace(LIM.stroke_min[2], LIM.stroke_max[2], 20001)
    lengths = np.column_stack((np.full_like(d4, LIM.reference[1]), np.full_like(d4, LIM.reference[2]), d4))
    theta4 = EXC.joint_angles(lengths)[:, 2]
    k4 = EXC.k_entries(lengths)[0][:, 2]
    assert np.max(np.abs(np.diff(theta4))) < 1.1 * np.max(np.abs(k4)) * (d4[1] - d4[0])


# ---------------------------------------------------------------- round trips
def test_lengths_angles_lengths_round_trip():
    lengths = random_states(10_000, margin=0.0)[:, 1:]
    lengths = np.vstack((lengths, LIM.stroke_min, LIM.stroke_max))
    back = EXC.cylinder_lengths(EXC.joint_angles(lengths))
    assert np.max(np.abs(back - lengths)) < 1e-9


def test_rates_round_trip_through_jc0():
    D, V = random_states(5000), random_rates(5000)
    q_dot = EXC.state(D, V).Q_dot
    solution = EXC.cylinder_rates(D, q_dot)
    assert np.max(np.abs(solution.D_dot - V)) < 1e-9
    assert np.all(solution.condition > 1.0) and np.all(np.isfinite(solution.condition))


def test_accelerations_round_trip_eq12_eq13():
    D, V = random_states(2000), random_rates(2000)
    A = RNG.uniform(-0.5, 0.5, size=(2000, 4))
    state = EXC.state(D, V, A)
    assert np.max(np.abs(EXC.cylinder_accelerations(D, V, state.Q_ddot) - A)) < 1e-9
    assert np.max(np.abs(EXC.joint_accelerations(D, V, state.Q_ddot) - state.theta_ddot)) < 1e-9


# ---------------------------------------------------------------- batch == scalar
def test_batch_equals_scalar():
    D, V = random_states(40), random_rates(40)
    A = RNG.uniform(-0.5, 0.5, size=(40, 4))
    batch = EXC.state(D, V, A)
    rates = EXC.cylinder_rates(D, batch.Q_dot)
    for i in range(len(D)):
        one = EXC.state(D[i], V[i], A[i])
        for field in ("theta", "theta_dot", "theta_ddot", "Q", "Q_dot", "Q_ddot", "jc0"):
            np.testing.assert_allclose(getattr(one, field), getattr(batch, field)[i], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(EXC.pose(D[i]), EXC.pose(D)[i], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(EXC.jc0(D[i]), EXC.jc0(D)[i], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(EXC.joint_angles(D[i, 1:]), EXC.joint_angles(D[:, 1:])[i], rtol=1e-13)
        np.testing.assert_allclose(EXC.cylinder_rates(D[i], batch.Q_dot[i]).D_dot, rates.D_dot[i], atol=1e-12)


# ---------------------------------------------------------------- ROS-facing geometry
def _rotation(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_bucket_orientation_points_along_the_bucket_line():
    for D in random_states(50):
        pins = EXC.pins(D)
        Q = EXC.pose(D)
        R = _rotation(bucket_quaternion(D[0], Q[3]))
        line = (pins["bucket_tip"] - pins["bucket_pin"]) / EXC.l4
        np.testing.assert_allclose(R @ [1.0, 0.0, 0.0], line, atol=1e-12)
        np.testing.assert_allclose(R @ [0.0, 1.0, 0.0], [-np.sin(D[0]), np.cos(D[0]), 0.0], atol=1e-12)


def test_angular_velocity_and_acceleration_against_differences():
    D0, V = random_states(30, margin=0.1), random_rates(30)
    A = RNG.uniform(-0.5, 0.5, size=(30, 4))
    h = 1e-5
    for i in range(30):
        states = [EXC.state(*_trajectory(D0[i], V[i], A[i], t), A[i]) for t in (-h, 0.0, h)]
        rotations = [_rotation(bucket_quaternion(s.theta[0], s.Q[3])) for s in states]
        skew = (rotations[2] - rotations[0]) / (2 * h) @ rotations[1].T
        fd_omega = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        now = states[1]
        omega = bucket_angular_velocity(now.theta[0], now.theta_dot[0], now.Q_dot[3])
        np.testing.assert_allclose(omega, fd_omega, atol=1e-8)
        omegas = [bucket_angular_velocity(s.theta[0], s.theta_dot[0], s.Q_dot[3]) for s in states]
        alpha = bucket_angular_acceleration(
            now.theta[0], now.theta_dot[0], now.theta_ddot[0], now.Q_dot[3], now.Q_ddot[3]
        )
        np.testing.assert_allclose(alpha, (omegas[2] - omegas[0]) / (2 * h), atol=1e-8)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("i", range(3))
@pytest.mark.parametrize("where", ["below", "above"])
def test_out_of_stroke_names_cylinder_and_range(i, where):
    D = LIM.reference.copy()
    D[i + 1] = LIM.stroke_min[i] - 0.01 if where == "below" else LIM.stroke_max[i] + 0.01
    with pytest.raises(StrokeError, match=CYLINDERS[i]) as info:
        EXC.pose(D)
    assert f"{LIM.stroke_min[i]:.6g}" in str(info.value) and f"{LIM.stroke_max[i]:.6g}" in str(info.value)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_raises_never_returns_nan(bad):
    for index in range(4):
        D = LIM.reference.copy()
        D[index] = bad
        with pytest.raises(StrokeError, match="not finite"):
            EXC.state(D, np.zeros(4))
    with pytest.raises(StrokeError, match="D_dot"):
        EXC.state(LIM.reference, [0.0, bad, 0.0, 0.0])
    with pytest.raises(StrokeError, match="Q_dot"):
        EXC.cylinder_rates(LIM.reference, [bad, 0.0, 0.0, 0.0])


def test_one_bad_state_in_a_batch_is_found():
    D = random_states(100)
    D[57, 2] = LIM.stroke_max[1] + 0.5
    with pytest.raises(StrokeError, match="arm_cylinder length"):
        EXC.state(D, np.zeros_like(D))


def test_swing_limit_raises():
    D = LIM.reference.copy()
    D[0] = LIM.swing_max + 0.1
    with pytest.raises(StrokeError, match="swing_joint"):
        EXC.pose(D)


BATCH = random_states(6)
STATE = LIM.reference


@pytest.mark.parametrize(
    "call",
    [
        lambda: EXC.pose([1.0, 2.0, 3.0]),
        lambda: EXC.pose(np.zeros((2, 3, 4))),
        lambda: EXC.jc0(np.zeros((5, 3))),
        lambda: EXC.state(BATCH, np.zeros((5, 4))),
        lambda: EXC.state(BATCH, np.zeros(4), np.zeros(3)),
        lambda: EXC.state(STATE, np.zeros(3)),
        lambda: EXC.state(STATE, np.zeros((6, 4))),
        lambda: EXC.state(STATE, np.zeros(4), np.zeros(5)),
        lambda: EXC.cylinder_rates(BATCH, np.zeros((6, 3))),
        lambda: EXC.cylinder_rates(STATE, np.zeros((2, 4))),
        lambda: EXC.cylinder_accelerations(BATCH, np.zeros(4), np.zeros((6, 2))),
        lambda: EXC.joint_accelerations(BATCH, np.zeros((6, 5)), np.zeros(4)),
        lambda: EXC.joint_angles(np.zeros(4)),
        lambda: EXC.k_entries(np.zeros((3, 2))),
        lambda: EXC.cylinder_lengths(np.zeros(2)),
        lambda: EXC.j0(np.zeros(3)),
        lambda: EXC.open_chain_pose(np.zeros((2, 5))),
        lambda: EXC.joint_rates(np.zeros(4), np.zeros(3)),
    ],
)
def test_shape_errors_are_value_errors_saying_shape(call):
    with pytest.raises(ValueError, match="shape") as info:
        call()
    assert not isinstance(info.value, StrokeError)  # a wrong shape is the caller's bug, not a state


def test_a_vector_of_rates_is_broadcast_over_a_batch():
    D, V, A = random_states(50), random_rates(1)[0], RNG.uniform(-0.5, 0.5, size=4)
    tiled = np.tile(V, (50, 1)), np.tile(A, (50, 1))
    broadcast, explicit = EXC.state(D, V, A), EXC.state(D, *tiled)
    for field in broadcast._fields:
        np.testing.assert_array_equal(getattr(broadcast, field), getattr(explicit, field))
    q_dot = broadcast.Q_dot[7]
    np.testing.assert_array_equal(
        EXC.cylinder_rates(D, q_dot).D_dot, EXC.cylinder_rates(D, np.tile(q_dot, (50, 1))).D_dot
    )
    np.testing.assert_array_equal(
        EXC.cylinder_accelerations(D, V, A), EXC.cylinder_accelerations(D, tiled[0], tiled[1])
    )
    np.testing.assert_array_equal(EXC.joint_accelerations(D, V, A), EXC.joint_accelerations(D, *tiled))
    # The batch call of docs/machines.md, as written there.
    assert EXC.state(np.tile(STATE, (1000, 1)), [0.1, 0.05, -0.05, 0.08]).Q.shape == (1000, 4)


def test_eq6_joint_rates_invert_j0():
    D, V = random_states(200), random_rates(200)
    state = EXC.state(D, V)
    np.testing.assert_allclose(EXC.joint_rates(state.theta, state.Q_dot), state.theta_dot, atol=1e-10)
    one = EXC.state(STATE, V[0])
    np.testing.assert_allclose(EXC.joint_rates(one.theta, one.Q_dot), one.theta_dot, atol=1e-10)


def test_unreachable_angles_raise():
    with pytest.raises(StrokeError, match="boom_cylinder"):
        EXC.cylinder_lengths([np.radians(80.0), np.radians(-100.0), np.radians(-30.0)])


def _description() -> dict:
    """The shipped file's top-level sections (hydraulic_machine, excavator), a copy."""
    return copy.deepcopy(load_parameters(config_path("excavator_cet200.yaml")))


def _parent(d: dict, path: str) -> tuple[dict, str]:
    *parents, key = path.split(".")
    for part in parents:
        d = d[part]
    return d, key


def _set(path: str, value):
    return lambda d: _parent(d, path)[0].__setitem__(_parent(d, path)[1], value)


def _pop(path: str):
    return lambda d: _parent(d, path)[0].pop(_parent(d, path)[1])


def _rename(path: str, new: str):
    def rename(d: dict) -> None:
        parent, key = _parent(d, path)
        parent[new] = parent.pop(key)

    return rename


G = "hydraulic_machine"
# (change to the shipped CET200 sections, the dotted key the error must name, more of its message)
INVALID = {
    "misspelt key": (
        _rename(f"{G}.links.h_link.length", "lenght"),
        f"{G}.links.h_link.lenght",
        "did you mean 'length'",
    ),
    "unknown section": (_set(f"{G}.stick", {}), f"{G}.stick", "unknown key"),
    "unknown excavator key": (_set("excavator.stick", 1.0), "excavator.stick", "unknown key"),
    "missing key": (_pop(f"{G}.bodies.boom.pins.arm_pin"), f"{G}.bodies.boom.pins.arm_pin", "missing"),
    "missing base height": (_pop("excavator.base_height"), "excavator.base_height", "missing"),
    "missing reference angle": (_pop(f"{G}.swing.reference_angle"), f"{G}.swing.reference_angle", "missing"),
    "missing reference length": (
        _pop(f"{G}.cylinders.arm_cylinder.reference_length"),
        f"{G}.cylinders.arm_cylinder.reference_length",
        "missing",
    ),
    "missing section": (_pop(f"{G}.links.side_link"), f"{G}.links.side_link", "missing"),
    "missing name": (_pop(f"{G}.name"), f"{G}.name", "missing"),
    "empty name": (_set(f"{G}.name", ""), f"{G}.name", "empty"),
    "string in a point": (
        _set(f"{G}.bodies.upper_structure.pins.boom_foot", [0.18, "x"]),
        f"{G}.bodies.upper_structure.pins.boom_foot[1]",
        "number",
    ),
    "short point": (
        _set(f"{G}.bodies.boom.pins.boom_cyl_rod", [1.0]),
        f"{G}.bodies.boom.pins.boom_cyl_rod",
        "2 numbers",
    ),
    "point not a list": (
        _set(f"{G}.bodies.arm.pins.ilink_pin_on_arm", "2.47, 0"),
        f"{G}.bodies.arm.pins.ilink_pin_on_arm",
        "list",
    ),
    "true for a number": (_set(f"{G}.links.side_link.length", True), f"{G}.links.side_link.length", "number"),
    "true for an orientation": (
        _set(f"{G}.dyads.hlink_pin_on_bucket.orientation", True),
        f"{G}.dyads.hlink_pin_on_bucket.orientation",
        "number",
    ),
    "string for a number": (_set(f"{G}.swing.max_speed", "fast"), f"{G}.swing.max_speed", "number"),
    "negative length": (_set(f"{G}.links.h_link.length", -0.58), f"{G}.links.h_link.length", "outside"),
    "zero length": (_set(f"{G}.links.h_link.length", 0.0), f"{G}.links.h_link.length", "outside"),
    "absurd length": (
        _set(f"{G}.bodies.bucket.pins.tip", [1e300, 0.0]),
        f"{G}.bodies.bucket.pins.tip[0]",
        "outside",
    ),
    "absurd swing limit": (_set(f"{G}.swing.max_angle", 1e12), f"{G}.swing.max_angle", "outside"),
    "absurd stroke": (
        _set(f"{G}.cylinders.boom_cylinder.max_length", 1e6),
        f"{G}.cylinders.boom_cylinder.max_length",
        "outside",
    ),
    "absurd speed": (
        _set(f"{G}.cylinders.arm_cylinder.max_speed", 50.0),
        f"{G}.cylinders.arm_cylinder.max_speed",
        "outside",
    ),
    "not finite": (_set(f"{G}.swing.max_speed", float("nan")), f"{G}.swing.max_speed", "finite"),
    "orientation 0": (
        _set(f"{G}.dyads.hlink_pin_on_bucket.orientation", 0),
        f"{G}.dyads.hlink_pin_on_bucket.orientation",
        "1 or -1",
    ),
    "orientation 2": (
        _set(f"{G}.dyads.boom_cyl_rod.orientation", 2),
        f"{G}.dyads.boom_cyl_rod.orientation",
        "outside",
    ),
    "fractional orientation": (
        _set(f"{G}.dyads.arm_cyl_rod.orientation", 0.5),
        f"{G}.dyads.arm_cyl_rod.orientation",
        "whole",
    ),
    "reference angle outside the swing limits": (
        _set(f"{G}.swing.reference_angle", 3.5),
        f"{G}.swing.reference_angle",
        "outside [min_angle, max_angle]",
    ),
    "swing limits reversed": (_set(f"{G}.swing.min_angle", 3.2), f"{G}.swing.max_angle", "above min_angle"),
    "reference length outside the stroke": (
        _set(f"{G}.cylinders.boom_cylinder.reference_length", 3.5),
        f"{G}.cylinders.boom_cylinder.reference_length",
        "outside the stroke",
    ),
    "stroke reversed": (
        _set(f"{G}.cylinders.bucket_cylinder.min_length", 3.0),
        f"{G}.cylinders.bucket_cylinder.max_length",
        "above",
    ),
    "imu body": (
        _set("excavator.imu.bucket_linkage.body", "stick"),
        "excavator.imu.bucket_linkage.body",
        "expected one of 'h_link', 'bucket'",
    ),
    # Whole-stroke assembly: every length of the stroke box must close the linkages.
    "arm stroke cannot assemble": (
        _set(f"{G}.cylinders.arm_cylinder.max_length", 9.0),
        f"{G}.cylinders.arm_cylinder",
        "assembled",
    ),
    "side link too short": (
        _set(f"{G}.links.side_link.length", 0.05),
        f"{G}.cylinders.bucket_cylinder",
        "assembled",
    ),
}


@pytest.mark.parametrize("case", INVALID)
def test_invalid_machine_description_names_the_key(case):
    mutate, key, message = INVALID[case]
    description = _description()
    mutate(description)
    with pytest.raises(ConfigError) as info:
        Excavator.from_parameters(description)
    text = str(info.value)
    assert text.startswith(key) and message in text and "\n" not in text, text


def test_the_shipped_file_is_complete_and_exact():
    """Every key of the schemas is given (none falls back to a default, but the zero offsets a
    calibrated file adds) and the file loads through the registered machine as through the class."""
    shipped = _description()
    assert validate(shipped["excavator"], SCHEMA, "excavator") == shipped["excavator"]
    geometry = validate(shipped[G], GEOMETRY, G)
    geometry["swing"].pop("zero_offset")
    for cylinder in geometry["cylinders"].values():
        cylinder.pop("zero_offset")
    assert geometry == shipped[G]
    assert MACHINE.parameters() == {**shipped["excavator"], G: validate(shipped[G], GEOMETRY, G)}
    np.testing.assert_array_equal(MACHINE.model().pose(LIM.reference), EXC.pose(LIM.reference))


def test_registered_machine():
    found = [e for e in entry_points(group="manipulator_kinematics.machines") if e.name == "excavator"]
    assert len(found) == 1 and found[0].load() is MACHINE
    model = MACHINE.model()
    assert MACHINE.joint_names(model) == ACTUATORS == ("swing_joint", *CYLINDERS)
    limits = MACHINE.limits(model)
    assert limits.names == ACTUATORS and limits.prismatic == (False, True, True, True)
    np.testing.assert_array_equal(limits.lower, [LIM.swing_min, *LIM.stroke_min])
    np.testing.assert_array_equal(limits.upper, [LIM.swing_max, *LIM.stroke_max])
    assert limits.within(LIM.reference) and not limits.within(LIM.d_max + 0.01)
    sections = _description()
    sections[G]["bodies"]["bucket"]["pins"]["tip"] = [1e300, 0.0]
    with pytest.raises(ConfigError, match=r"^hydraulic_machine\.bodies\.bucket\.pins\.tip\[0\]"):
        MACHINE.model_of(sections)


# What flows on each topic key of the excavator nodes' settings (their publishers/subscriptions).
TYPE_OF_TOPIC_KEY = {
    "cylinder_lengths": JOINT_STATE,
    "joint_states": JOINT_STATE,
    "open_chain_joint_states": JOINT_STATE,
    "rate_commands": JOINT_STATE,
    "rate_command_array": "std_msgs/msg/Float64MultiArray",
    "status": "diagnostic_msgs/msg/DiagnosticArray",
    "zone_clearance": "diagnostic_msgs/msg/DiagnosticArray",
    "bucket_pose": POSE,
    "bucket_twist": TWIST,
    "bucket_accel": ACCEL,
    "target_bucket_twist": TWIST,
    "urdf_joint_states": JOINT_STATE,
    "grade_height": "geometry_msgs/msg/PointStamped",
    "site_pose": POSE,
    "machine_tilt": "geometry_msgs/msg/Vector3Stamped",
    "bucket_pose_level": POSE,
    "imu_cab": "sensor_msgs/msg/Imu",
    "imu_boom": "sensor_msgs/msg/Imu",
    "imu_arm": "sensor_msgs/msg/Imu",
    "imu_bucket_linkage": "sensor_msgs/msg/Imu",
    "grade_tip": "geometry_msgs/msg/PointStamped",
    "grade_left": "geometry_msgs/msg/PointStamped",
    "grade_right": "geometry_msgs/msg/PointStamped",
    "grade_status": "diagnostic_msgs/msg/DiagnosticArray",
}


def test_registered_topics_are_the_nodes_topics():
    """Every topic named in config/excavator_nodes.yaml, typed by its key, and no other."""
    with open(config_path("excavator_nodes.yaml"), encoding="utf-8") as stream:
        document = yaml.safe_load(stream)
    topics = {
        name: TYPE_OF_TOPIC_KEY[key]
        for section in document.values()
        for key, name in section["ros__parameters"].get("topics", {}).items()
    }
    assert MACHINE.topics == topics


def test_custom_machine_changes_the_numbers():
    description = _description()
    description[G]["bodies"]["bucket"]["pins"]["tip"] = [1.5, 0.0]
    other = Excavator.from_parameters(description)
    reach = other.pose(LIM.reference)[0] - EXC.pose(LIM.reference)[0]
    alpha = EXC.pose(LIM.reference)[3]
    assert reach == pytest.approx((1.5 - EXC.l4) * np.cos(alpha), abs=1e-12)
