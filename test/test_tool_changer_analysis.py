"""Tool changer: the paper's quintic observations (Figs. 7-9), Monte-Carlo workspace extents
(Figs. 5-6) against the reference values, the JointTrajectory message and the plot script."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tool_changer_kinematics.kinematics import ToolChanger
from tool_changer_kinematics.plots import main as plots_main
from tool_changer_kinematics.trajectory import (
    PAPER_END,
    PAPER_START,
    joint_trajectory_message,
    paper_trajectory,
)
from tool_changer_kinematics.workspace import sample, section


@pytest.fixture(scope="module")
def arm() -> ToolChanger:
    return ToolChanger.default()


def test_quintic_matches_the_papers_observations() -> None:
    trajectory = paper_trajectory(601)  # 0.05 s steps: 15 s is a sample
    speed = np.abs(trajectory.qd)
    np.testing.assert_allclose(trajectory.t[np.argmax(speed, axis=0)], 15.0)  # every joint peaks at 15 s
    np.testing.assert_allclose(trajectory.qd[-1], 0.0, atol=1e-15)
    np.testing.assert_allclose(trajectory.q[[0, -1]], [PAPER_START, PAPER_END], atol=1e-15)
    for first, second in ((0, 5), (2, 3)):  # J1/J6 and J3/J4 curves coincide
        np.testing.assert_allclose(trajectory.qd[:, first], trajectory.qd[:, second], atol=1e-15)
        np.testing.assert_allclose(trajectory.qdd[:, first], trajectory.qdd[:, second], atol=1e-15)
    peak = np.abs(trajectory.qdd).max(axis=0)
    assert np.argmax(peak) == 4 and peak[4] > 2 * np.delete(peak, 4).max()  # J5 accelerates most
    # Closed form: peak speed 15/8 delta / T, peak acceleration 10 sqrt(3)/3 delta / T^2.
    delta = PAPER_END - PAPER_START
    np.testing.assert_allclose(speed.max(axis=0), 15 / 8 * np.abs(delta) / 30, rtol=1e-12)
    np.testing.assert_allclose(peak, 10 * math.sqrt(3) / 3 * np.abs(delta) / 900, rtol=1e-4)


def test_trajectory_as_a_joint_trajectory_message(arm: ToolChanger) -> None:
    trajectory = paper_trajectory(31)
    message = joint_trajectory_message(trajectory, arm.joint_names, "base_link")
    assert message.joint_names == list(arm.joint_names) and len(message.points) == 31
    last = message.points[-1]
    assert (last.time_from_start.sec, last.time_from_start.nanosec) == (30, 0)
    np.testing.assert_allclose(last.positions, PAPER_END)
    np.testing.assert_allclose(message.points[15].velocities, trajectory.qd[15])


def test_workspace_extents_approach_the_reference_values(arm: ToolChanger) -> None:
    workspace = sample(arm, 200_000, seed=3)
    assert workspace.samples == 200_000 and arm.limits.within(workspace.q).all()
    # Reconstruction, all limits: about 2190 / 2250 / 970 mm; Monte Carlo approaches them from inside.
    assert 2.15 < workspace.max_radius < 2.197  # 2.197 m: the horizontal reach without joint limits
    assert 2.20 < workspace.max_height < 2.26
    assert 0.90 < workspace.max_depth < 0.978  # exact optimum about 977 mm
    np.testing.assert_allclose(workspace.points, arm.fkine(workspace.q)[:, :3, 3], atol=0)
    plane = section(arm, 20_000)
    np.testing.assert_allclose(plane.q[:, 0], math.pi / 2)
    # With J1 = 90 deg the tool point stays near the y0-z0 plane: only the wrist's lateral reach (k7 + k5).
    assert np.abs(plane.points[:, 0]).max() < 0.552 + 0.175 + 1e-9


@pytest.mark.slow
def test_plot_script_writes_the_pngs(tmp_path, capsys) -> None:
    plots_main([str(tmp_path), "--samples", "20000", "--section-samples", "5000"])
    names = sorted(p.name for p in tmp_path.glob("*.png"))
    assert names == [
        "tool_changer_section.png",
        "tool_changer_solutions.png",
        "tool_changer_trajectory.png",
        "tool_changer_workspace.png",
    ]
    assert all((tmp_path / n).stat().st_size > 10_000 for n in names)
    assert "20000 samples: max radius" in capsys.readouterr().out
