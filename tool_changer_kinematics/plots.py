"""``tool_changer_plots OUTDIR``: the paper's figures for the tool changer as PNG (matplotlib, Agg).

* ``tool_changer_workspace.png``: Monte-Carlo tool points (Fig. 5) with the extents printed;
* ``tool_changer_section.png``: J1 = 90 deg, the y0-z0 plane (Fig. 6);
* ``tool_changer_trajectory.png``: the quintic's positions, velocities, accelerations (Figs. 7-9);
* ``tool_changer_solutions.png``: every closed-form IK candidate of one pose, valid ones coloured;
* ``tool_changer_trajectory.gif``: the arm moving along that trajectory (side and top view).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from manipulator_kinematics.help_text import plain
from tool_changer_kinematics.kinematics import BRANCHES, ToolChanger
from tool_changer_kinematics.trajectory import paper_trajectory
from tool_changer_kinematics.workspace import Workspace, sample, section

#: The note's pose reached by two in-limit joint vectors (deg).
TWO_SOLUTION_POSE = (-11.06, 128.98, -82.79, 32.96, 82.48, -152.27)
#: Points drawn in the clouds (all samples count for the extents).
DRAWN = 30_000


def plot_workspace(workspace: Workspace, path: Path) -> None:
    points = workspace.points[:: max(1, workspace.samples // DRAWN)]
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ax.scatter(points[:, 0], points[:, 1], points[:, 2], s=0.5, c=points[:, 2], cmap="viridis", alpha=0.4)
    ax.set(xlabel="x0 (m)", ylabel="y0 (m)", zlabel="z0 (m)")
    ax.set_title(f"Tool-point workspace (cf. paper Fig. 5)\n{workspace.summary()}", fontsize=9)
    ax.set_box_aspect((1, 1, 0.8))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_section(workspace: Workspace, path: Path) -> None:
    points = workspace.points[:: max(1, workspace.samples // DRAWN)]
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    ax.scatter(points[:, 1], points[:, 2], s=0.5, alpha=0.3)
    ax.plot(0.0, 0.0, "k+", ms=12)
    ax.set(
        xlabel="y0 (m)",
        ylabel="z0 (m)",
        aspect="equal",
        title=f"J1 = 90 deg: section in the y0-z0 plane (cf. paper Fig. 6), {workspace.samples} samples",
    )
    ax.title.set_fontsize(9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_trajectory(path: Path) -> None:
    trajectory = paper_trajectory()
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    labels = ("position (deg)", "velocity (deg/s)", "acceleration (deg/s^2)")
    for values, ax, label in zip((trajectory.q, trajectory.qd, trajectory.qdd), axes, labels, strict=True):
        for j in range(6):  # J4 and J6 dashed: they lie on J3 and J1
            style = "--" if j in (3, 5) else "-"
            ax.plot(trajectory.t, np.degrees(values[:, j]), label=f"J{j + 1}", ls=style)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(ncol=6, fontsize=8)
    axes[0].set_title("Quintic joint trajectory, tf = 30 s (cf. paper Figs. 7-9); J1/J6, J3/J4 overlap")
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_solutions(arm: ToolChanger, path: Path) -> None:
    q = np.radians(TWO_SOLUTION_POSE)
    solutions = arm.solve_ik(arm.fkine(q), seed=q)
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    for i, candidate in enumerate(solutions.q):
        if not np.isfinite(candidate).all():
            continue
        joints = arm.frames(candidate)[:, :3, 3]
        valid = bool(solutions.valid[i])
        ax.plot(
            *joints.T,
            "-o",
            ms=3,
            lw=2.5 if valid else 1.0,
            alpha=1.0 if valid else 0.35,
            color=None if valid else "grey",
            label=f"{BRANCHES[i]}{' (selected)' if i == solutions.selected else ''}" if valid else None,
        )
    ax.plot([], [], color="grey", alpha=0.35, label="outside the joint limits")
    ax.set(xlabel="x0 (m)", ylabel="y0 (m)", zlabel="z0 (m)")
    ax.set_title("All closed-form solutions of one pose: two inside every limit", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def animate_trajectory(arm: ToolChanger, path: Path) -> Path:
    """The arm along the paper's quintic (shared scene, side and top view), 3x real time."""
    from manipulator_kinematics.animation import View, animate, view_xy, view_xz
    from tool_changer_kinematics.machine import MACHINE

    trajectory = paper_trajectory()
    return animate(
        MACHINE.scene(arm, trajectory.q),
        path,
        [View(view_xz, "x (m)", "z (m)", "side"), View(view_xy, "x (m)", "y (m)", "top")],
        times=trajectory.t,
        speed=3.0,
        size=(7.0, 3.6),
        title="Tool changer: quintic joint trajectory (Figs. 7-9), 3x speed",
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=plain(__doc__.splitlines()[0]))
    parser.add_argument("outdir", type=Path, help="directory for the PNG files (created)")
    parser.add_argument("--samples", type=int, default=1_000_000, help="Monte-Carlo samples (Fig. 5)")
    parser.add_argument(
        "--section-samples", type=int, default=200_000, help="samples with J1 = 90 deg (Fig. 6)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument("--config", type=Path, help="machine file (default: the shipped tool_changer.yaml)")
    args = parser.parse_args(argv)
    from tool_changer_kinematics.machine import MACHINE

    arm = MACHINE.model(args.config)
    args.outdir.mkdir(parents=True, exist_ok=True)
    workspace = sample(arm, args.samples, args.seed)
    print(f"workspace: {workspace.summary()}")
    plane = section(arm, args.section_samples, args.seed + 1)
    print(f"J1 = 90 deg section: {plane.summary()}")
    plot_workspace(workspace, args.outdir / "tool_changer_workspace.png")
    plot_section(plane, args.outdir / "tool_changer_section.png")
    plot_trajectory(args.outdir / "tool_changer_trajectory.png")
    plot_solutions(arm, args.outdir / "tool_changer_solutions.png")
    animate_trajectory(arm, args.outdir / "tool_changer_trajectory.gif")
    print(f"wrote 4 PNG files and tool_changer_trajectory.gif to {args.outdir}")
