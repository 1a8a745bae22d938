"""Palletizer statics (eqs. 12-15) against an independent virtual-work computation, and the paper's
conclusion; the door trajectory (item 4): FK(IK) on the path, P0 = home, no jumps, timing, outputs."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from manipulator_kinematics.bag.evaluate import evaluate_bag, load_setup
from manipulator_kinematics.bag.reader import BagReader
from manipulator_kinematics.serial_chain import SerialChain, transl
from palletizer_kinematics.door import DOOR_POINTS, door_trajectory, leg_times
from palletizer_kinematics.kinematics import VARIANTS, Palletizer, axis_from_dh, dh_from_axis
from palletizer_kinematics.plots import PAPER_CASE_SINGLE, main, paper_case
from palletizer_kinematics.statics import holding_torques

RNG = np.random.default_rng(4600)


@pytest.fixture(scope="module")
def model() -> Palletizer:
    return Palletizer.default()


def virtual_work(model: Palletizer, axis: np.ndarray, variant: str) -> np.ndarray:
    """tau_A = sum over bodies of m g dz_com/dA, every dz/dtheta from the shared chain's geometric Jacobian.

    Each body's centre velocity is written with Jacobians of points on chain links (sub-chains of
    the D-H rows, the coupling row of theta4 included): a body turning like link k about a point
    that moves like point r has v = J(r) + J_k(o_k + d) - J_k(o_k), d its centre's offset in
    frame k. dtheta/dA is the variant's parallelogram constraint (dh_from_axis).
    """
    chain, m = model.chain, model.masses
    theta = dh_from_axis(axis, variant)

    def point(k: int, offset=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Linear Jacobian (3, 4) of a point fixed in frame {k} (k = 6: the TCP frame)."""
        rows, tool = (chain.rows, chain.tool) if k == 6 else (chain.rows[:k], np.eye(4))
        sub = SerialChain(
            rows, modified=True, tool=tool @ transl(*offset), coupling=chain.coupling[: len(rows)]
        )
        return sub.jacob0(theta)[:3]

    def turning(
        k: int, distance: float
    ) -> np.ndarray:  # rotation of link k's direction x_k, about a moving point
        return point(k, (distance, 0.0, 0.0)) - point(k)

    origin2 = point(2)
    bodies = [
        (m.m2, point(2, (m.lc2, 0.0, 0.0))),
        (m.m_r1, origin2 + turning(2, m.l_r1)),  # parallel to the lower arm, pivot on the base
        (m.m_p, point(3)),  # translates with the elbow
        (m.m3, point(3, (m.lc3, 0.0, 0.0))),
        (m.m_r2, point(3) + turning(3, m.l_r2)),
        (m.m_w, point(5, (0.08, -0.05, 0.1))),  # any offset: the wrist does not tilt
        (m.payload, point(6, (0.2, 0.1, -0.05))),
    ]
    if variant == "double":
        bodies += [
            (m.m_k, origin2 + turning(3, -m.lck)),  # crank parallel to the upper arm, behind axis 2
            (m.m_m, origin2 + turning(3, -m.r_k) + turning(2, m.l_m)),
        ]  # rod from the crank pin
    dtheta_da = np.linalg.inv(axis_from_dh(np.eye(4), variant) - axis_from_dh(np.zeros((4, 4)), variant)).T
    dz = sum(mass * jacobian[2] for mass, jacobian in bodies)
    return m.gravity * dz @ dtheta_da


@pytest.mark.parametrize("variant", VARIANTS)
def test_closed_form_equals_virtual_work(model: Palletizer, variant: str) -> None:
    for axis in RNG.uniform(model.limits.lower, model.limits.upper, size=(25, 4)):
        tau = virtual_work(model, axis, variant)
        closed = holding_torques(model, axis, variant)
        np.testing.assert_allclose(tau[[0, 3]], 0.0, atol=1e-9)  # vertical axes 1 and 6 hold nothing
        np.testing.assert_allclose(closed, tau[1:3], rtol=1e-9, atol=1e-9 * np.abs(tau).max())


def test_vectorised_and_variant_default(model: Palletizer) -> None:
    axis = RNG.uniform(-1, 1, size=(3, 5, 4))
    batch = holding_torques(model, axis)
    assert batch.shape == (3, 5, 2)
    np.testing.assert_array_equal(batch[1, 2], holding_torques(model, axis[1, 2], "double"))
    with pytest.raises(ValueError, match="unknown variant"):
        holding_torques(model, axis, "triple")


def test_payload_enters_with_the_wrist_pin_lever(model: Palletizer) -> None:
    # 10 kg more at the TCP adds g * 10 * a3 cos(psi) to T3 and g * 10 * a2 sin(A2) to the double's T2.
    axis = np.radians([0.0, 30.0, 45.0, 0.0])
    heavier = Palletizer(model.geometry, "double", model.limits, masses=model.masses.with_payload(120.0))
    delta = holding_torques(heavier, axis) - holding_torques(model, axis)
    g, a2, a3 = model.masses.gravity, model.geometry.a2, model.geometry.a3
    np.testing.assert_allclose(
        delta, [-g * 10 * a2 * 0.5, -g * 10 * a3 * math.cos(math.radians(45))], rtol=1e-12
    )


def test_paper_conclusion(model: Palletizer) -> None:
    # Same physical pose (single A2 = 30, A3 = 15 deg): the double robot roughly halves T2, T3 similar.
    theta = dh_from_axis(PAPER_CASE_SINGLE, "single")
    single = holding_torques(model, axis_from_dh(theta, "single"), "single")
    double = holding_torques(model, axis_from_dh(theta, "double"), "double")
    assert 0.4 < double[0] / single[0] < 0.65  # paper: 1580.5 / 2959.6 = 0.534
    assert 0.85 < double[1] / single[1] < 1.15  # paper: 1335.9 / 1426.9 = 0.936
    # Without the crank and main rod the two T3 are equal and T2_single = T2_double + T3 exactly.
    from dataclasses import replace

    bare = Palletizer(model.geometry, "double", model.limits, masses=replace(model.masses, m_k=0.0, m_m=0.0))
    s2, s3 = holding_torques(bare, axis_from_dh(theta, "single"), "single")
    d2, d3 = holding_torques(bare, axis_from_dh(theta, "double"), "double")
    assert d3 == pytest.approx(s3, rel=1e-12) and s2 == pytest.approx(d2 + d3, rel=1e-12)
    text = paper_case(model)
    assert "double / single T2 = 0.5" in text


def test_door_trajectory_follows_the_path(model: Palletizer) -> None:
    step = 0.01
    trajectory = door_trajectory(model, step=step)
    # FK(IK) is the sampled path at every sample; every sample on its leg's segment.
    np.testing.assert_allclose(
        model.fkine(trajectory.axis["double"])[:, :3, 3], trajectory.position, atol=1e-9
    )
    pose = model.fkine(trajectory.axis["double"])
    np.testing.assert_allclose(
        pose[:, :3, :3], np.tile(np.diag([1.0, -1.0, -1.0]), (len(pose), 1, 1)), atol=1e-12
    )
    for k in range(4):
        p = trajectory.position[trajectory.segment == k]
        p0, p1 = DOOR_POINTS[k], DOOR_POINTS[k + 1]
        direction = (p1 - p0) / np.linalg.norm(p1 - p0)
        offset = p - p0
        np.testing.assert_allclose(offset - np.outer(offset @ direction, direction), 0.0, atol=1e-12)
    # P0 is home: all axis angles 0 in both variants; the control points are samples.
    for variant in VARIANTS:
        np.testing.assert_allclose(trajectory.axis[variant][0], 0.0, atol=1e-12)
    for point in DOOR_POINTS:
        assert np.min(np.linalg.norm(trajectory.position - point, axis=1)) < 1e-12
    # No jump: spacing <= step, and every axis moves at most what the Jacobian allows for that spacing.
    spacing = np.linalg.norm(np.diff(trajectory.position, axis=0), axis=1)
    assert spacing.max() <= step * (1 + 1e-12)
    jacobian = model.jacob0(trajectory.axis["double"])[:, [0, 1, 2, 5], :]
    gain = np.linalg.norm(np.linalg.inv(jacobian), ord=2, axis=(1, 2))
    bound = 1.5 * step * np.maximum(gain[1:], gain[:-1])
    assert np.all(np.abs(np.diff(trajectory.axis["double"], axis=0)).max(axis=1) <= bound)
    # Times increase; the legs start and end at rest.
    assert np.all(np.diff(trajectory.t) > 0)
    speed = np.linalg.norm(trajectory.velocity, axis=1)
    corners = np.flatnonzero(np.diff(trajectory.segment)) + 1
    np.testing.assert_allclose(speed[[0, -1]], 0.0, atol=1e-12)
    assert speed.max() <= 1.0 + 1e-9
    np.testing.assert_allclose(speed[corners - 1], 0.0, atol=1e-12)
    # Axis rates: J qdot gives back the TCP velocity (and zero yaw rate).
    twist = np.einsum("nij,nj->ni", jacobian, trajectory.axis_rates)
    np.testing.assert_allclose(twist[:, :3], trajectory.velocity, atol=1e-9)
    np.testing.assert_allclose(twist[:, 3], 0.0, atol=1e-9)


def test_leg_time_law_inverts_the_quintic() -> None:
    arc = np.linspace(0.0, 2.0, 41)
    t, duration = leg_times(2.0, 1.0, arc)
    tau = t / duration
    np.testing.assert_allclose(2.0 * (10 * tau**3 - 15 * tau**4 + 6 * tau**5), arc, atol=1e-12)
    assert duration == pytest.approx(15 / 8 * 2.0)


def test_door_single_variant_and_a_failing_point() -> None:
    single = Palletizer.default("single")
    trajectory = door_trajectory(single, step=0.05)
    np.testing.assert_allclose(trajectory.axis["single"], single.axis_angles(trajectory.dh), atol=1e-15)
    with pytest.raises(ValueError, match="no valid IK solution"):
        door_trajectory(single, [[1.505, 0.0, 1.436], [4.0, 0.0, 1.0]])


@pytest.mark.slow
def test_palletizer_plots_writes_everything(tmp_path, capsys) -> None:
    assert main([str(tmp_path), "--step", "0.05"]) == 0
    names = {p.name for p in tmp_path.iterdir()}
    assert {
        "palletizer_door_axes.png",
        "palletizer_door_path.png",
        "palletizer_statics_map.png",
        "palletizer_door.csv",
        "palletizer_door_trajectory.yaml",
    } <= names
    with open(tmp_path / "palletizer_door.csv", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert float(rows[0]["double_A2_rad"]) == 0.0 and float(rows[-1]["x_m"]) == pytest.approx(1.722)
    assert "same pose: double / single T2" in capsys.readouterr().out
    # The door bag reads back as a recorded run whose outputs are the kinematics of its inputs.
    report, _ = evaluate_bag(BagReader(tmp_path / "palletizer_door_bag"), load_setup([]))
    [machine] = report["machines"]
    assert machine["kind"] == "palletizer" and machine["joint_states"] == len(rows)
    assert machine["consistency"]["tool_pose"]["position_m"]["max"] < 1e-12


def test_joint_trajectory_message(model: Palletizer) -> None:
    from palletizer_kinematics.trajectory_message import joint_trajectory

    trajectory = door_trajectory(model, step=0.05)
    msg = joint_trajectory(model.joint_names, trajectory.t, trajectory.axis["double"], trajectory.axis_rates)
    assert list(msg.joint_names) == ["axis_1", "axis_2", "axis_3", "axis_6"]
    assert len(msg.points) == len(trajectory.t)
    last = msg.points[-1]
    assert last.time_from_start.sec + last.time_from_start.nanosec * 1e-9 == pytest.approx(
        trajectory.t[-1], abs=1e-9
    )
    np.testing.assert_array_equal(last.positions, trajectory.axis["double"][-1])
    with pytest.raises(ValueError, match="increasing"):
        joint_trajectory(model.joint_names, trajectory.t[::-1], trajectory.axis["double"])
