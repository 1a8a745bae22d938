"""``palletizer_plots OUT_DIR``: the paper's door trajectory and statics as PNG, CSV and a JointTrajectory.

Writes into OUT_DIR:

* ``palletizer_door_axes.png``: A1, A2, A3 and the flange A6 against time for both variants
  (cf. the paper's Fig. 9); ``palletizer_door_path.png``: the TCP path in 3-D with P0..P4;
* ``palletizer_door.csv``: every sample (time, leg, TCP, D-H angles, both variants' axis angles,
  the configured variant's axis rates);
* ``palletizer_door_trajectory.yaml``: the configured variant's trajectory_msgs/JointTrajectory
  (axis names, positions, velocities) as the YAML ``ros2 topic pub`` takes, when the message
  types are installed;
* ``palletizer_statics_map.png``: T2 and T3 of both variants over the reachable vertical plane;
* ``palletizer_door_path.gif``: the arm along the door path (shared scene, side and top view);
* ``palletizer_door_bag/``: the door trajectory as a rosbag2 bag (joint_states, tool_pose,
  tool_twist) for ``mk_evaluate``, Foxglove or a replay into ``palletizer_forward``;

and prints the paper's statics case (payload 110 kg, A2 = 30 deg, A3 = 15 deg) side by side.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from manipulator_kinematics.bag.synthetic import START_NS, serial_topics, write_bag
from manipulator_kinematics.help_text import plain
from palletizer_kinematics.door import DOOR_POINTS, DoorTrajectory, door_trajectory
from palletizer_kinematics.kinematics import VARIANTS, Palletizer, axis_from_dh, dh_from_axis
from palletizer_kinematics.statics import holding_torques

DEG = 180.0 / math.pi
#: The paper's statics case: A2 = 30 deg, A3 = 15 deg given in the single robot's axis angles.
PAPER_CASE_SINGLE = np.radians([0.0, 30.0, 15.0, 0.0])
#: The paper's results (N m): T2, T3 of each variant (N mm / 1000), theory and simulation.
PAPER_TORQUES = {
    "single": ((2959.6, 1426.9), (2996.6, 1450.2)),
    "double": ((1580.5, 1335.9), (1594.1, 1361.0)),
}


def paper_case(model: Palletizer) -> str:
    """Table of the paper's statics case for both variants (same physical pose, and same numbers)."""
    single_to_dh = dh_from_axis(PAPER_CASE_SINGLE, "single")
    lines = [
        f"paper's statics case: payload {model.masses.payload:g} kg; torques in N m (holding torque, "
        "sign = axis sense; the paper prints magnitudes)",
        "variant  pose                         A2 deg  A3 deg     T2 N m     T3 N m   "
        "paper |T2|, |T3| (sim.)",
    ]
    rows = [
        ("single", "same pose", axis_from_dh(single_to_dh, "single")),
        ("double", "same pose", axis_from_dh(single_to_dh, "double")),
        ("double", "A2 = 30, A3 = 15 as its own", PAPER_CASE_SINGLE),
    ]
    torques = {}
    for variant, pose, axis in rows:
        t2, t3 = holding_torques(model, axis, variant)
        torques[(variant, pose)] = (t2, t3)
        (p2, p3), (s2, s3) = PAPER_TORQUES[variant]
        paper = f"{p2:7.1f}, {p3:7.1f} ({s2:.1f}, {s3:.1f})" if pose == "same pose" else ""
        lines.append(
            f"{variant:8s} {pose:28s} {axis[1] * DEG:6.1f}  {axis[2] * DEG:6.1f}  "
            f"{t2:9.1f}  {t3:9.1f}   {paper}"
        )
    (s2, s3), (d2, d3) = torques[("single", "same pose")], torques[("double", "same pose")]
    lines.append(
        f"same pose: double / single T2 = {d2 / s2:.3f} (paper {1580.5 / 2959.6:.3f}), "
        f"T3 = {d3 / s3:.3f} (paper {1335.9 / 1426.9:.3f})"
    )
    return "\n".join(lines)


def plot_axes(trajectory: DoorTrajectory, path: Path) -> None:
    fig, axes = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    labels = ("A1 (axis 1)", "A2 (lower arm)", "A3 (upper arm)", "A6 (flange)")
    corners = trajectory.t[np.flatnonzero(np.diff(trajectory.segment)) + 1]
    for i, ax in enumerate(axes):
        for variant, style in zip(VARIANTS, ("-", "--")):
            ax.plot(
                trajectory.t, trajectory.axis[variant][:, i] * DEG, style, label=f"{variant} parallelogram"
            )
        for corner in corners:
            ax.axvline(corner, color="0.8", lw=0.8)
        ax.set_ylabel(f"{labels[i]}, deg")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best")
    axes[0].set_title("Door trajectory P0-P1-P2-P3-P4: axis angles (A1, A2, A6 coincide for both variants)")
    axes[-1].set_xlabel("time, s (grey: corners P1, P2, P3)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_path(trajectory: DoorTrajectory, points: np.ndarray, path: Path) -> None:
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    p = trajectory.position
    ax.plot(p[:, 0], p[:, 1], p[:, 2], ".-", ms=2, lw=1, label="TCP samples")
    for k, point in enumerate(points):
        ax.scatter(*point, color="C3")
        ax.text(*point, f" P{k}")
    ax.scatter(0, 0, 0, color="k", marker="^", label="base (axis 1)")
    ax.set_xlabel("x, m")
    ax.set_ylabel("y, m")
    ax.set_zlabel("z, m")
    ax.set_title("TCP path (constant flange orientation)")
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def torque_map(
    model: Palletizer, resolution: int = 241
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """T2, T3 (N m) of both variants over a grid of TCP positions (x, z) in the plane y = 0.

    Home elbow branch; NaN where that variant's axis limits exclude the pose or nothing reaches it.
    """
    g = model.geometry
    reach = g.a1 + g.a2 + g.a3 + g.a4
    x = np.linspace(0.0, reach + 0.05, resolution)
    z = np.linspace(g.d1 - g.d6 - g.a2 - g.a3, g.d1 - g.d6 + g.a2 + g.a3, resolution)
    xx, zz = np.meshgrid(x, z)
    position = np.stack([xx, np.zeros_like(xx), zz], axis=-1)
    theta = model.ik_dh(position, np.zeros(xx.shape))[0][..., 0, :]  # front_elbow_up, inner flange turn
    maps = {}
    for variant in VARIANTS:
        axis = axis_from_dh(theta, variant)
        inside = model.limits.within(axis)
        maps[variant] = np.where(inside[..., None], holding_torques(model, axis, variant), np.nan)
    return x, z, maps


def plot_torque_map(model: Palletizer, path: Path) -> None:
    x, z, maps = torque_map(model)
    limit = max(np.nanmax(np.abs(m)) for m in maps.values())
    fig, axes = plt.subplots(2, 2, figsize=(10, 8.5), sharex=True, sharey=True)
    for row, variant in enumerate(VARIANTS):
        for col, name in enumerate(("T2", "T3")):
            ax = axes[row, col]
            mesh = ax.pcolormesh(
                x, z, maps[variant][..., col], cmap="RdBu_r", vmin=-limit, vmax=limit, shading="auto"
            )
            ax.set_title(f"{variant} parallelogram: {name}")
            ax.set_aspect("equal")
            ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("TCP x, m (y = 0)")
    for ax in axes[:, 0]:
        ax.set_ylabel("TCP z, m")
    rows = np.flatnonzero(
        np.any(np.isfinite(maps["single"][..., 0]) | np.isfinite(maps["double"][..., 0]), axis=1)
    )
    axes[0, 0].set_ylim(z[rows[0]] - 0.05, z[rows[-1]] + 0.05)
    fig.colorbar(mesh, ax=axes, label="holding torque, N m (blank: outside that variant's axis limits)")
    fig.suptitle(f"Static torques of axes 2 and 3, payload {model.masses.payload:g} kg, home elbow branch")
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_csv(trajectory: DoorTrajectory, path: Path) -> None:
    header = ["t_s", "leg", "x_m", "y_m", "z_m", "theta1_rad", "theta2_rad", "theta3_rad", "theta5_rad"]
    header += [f"{v}_{a}_rad" for v in VARIANTS for a in ("A1", "A2", "A3", "A6")]
    header += [f"{trajectory.variant}_{a}_rate_rad_s" for a in ("A1", "A2", "A3", "A6")]
    columns = np.column_stack(
        [
            trajectory.t,
            trajectory.segment,
            trajectory.position,
            trajectory.dh,
            *(trajectory.axis[v] for v in VARIANTS),
            trajectory.axis_rates,
        ]
    )
    with open(path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(header)
        for row in columns:
            writer.writerow([int(row[1]) if i == 1 else repr(float(v)) for i, v in enumerate(row)])


def write_trajectory_yaml(model: Palletizer, trajectory: DoorTrajectory, path: Path) -> bool:
    """The JointTrajectory as YAML; False when trajectory_msgs cannot be imported."""
    try:
        from palletizer_kinematics.trajectory_message import joint_trajectory, trajectory_dict
    except ImportError:
        return False
    import yaml

    msg = joint_trajectory(
        model.joint_names, trajectory.t, trajectory.axis[model.variant], trajectory.axis_rates
    )
    path.write_text(yaml.safe_dump(trajectory_dict(msg), sort_keys=False), encoding="utf-8")
    return True


def animate_door(model: Palletizer, trajectory: DoorTrajectory, path: Path) -> Path:
    """The configured variant's axis angles along the door path, drawn from the shared scene."""
    from manipulator_kinematics.animation import View, animate, view_xy, view_xz
    from palletizer_kinematics.machine import MACHINE

    return animate(
        MACHINE.scene(model, trajectory.axis[model.variant]),
        path,
        [View(view_xz, "x (m)", "z (m)", "side"), View(view_xy, "x (m)", "y (m)", "top")],
        times=trajectory.t,
        reference=trajectory.position,
        size=(7.0, 3.6),
        ground=0.0,
        title=f"Palletizer ({model.variant}): door path P0..P4",
    )


def write_door_bag(model: Palletizer, trajectory: DoorTrajectory, path: Path) -> int:
    """The door trajectory as a rosbag2 bag (mcap): ``joint_states`` (axis angles and rates of
    the model's variant) with the ``tool_pose``/``tool_twist`` the forward node publishes for
    them; ``mk_evaluate`` checks it like a recorded run. Returns the message count."""
    stamp = START_NS + np.round(trajectory.t * 1e9).astype(np.int64)
    topics = serial_topics(model, stamp, trajectory.axis[model.variant], trajectory.axis_rates)
    return write_bag(path, topics, overwrite=True)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="palletizer_plots", description=plain(__doc__.split("\n")[0]))
    parser.add_argument("out_dir", type=Path, help="directory to write into (created if missing)")
    parser.add_argument(
        "--config", type=Path, default=None, help="machine file (default: config/irb460.yaml)"
    )
    parser.add_argument("--step", type=float, default=0.01, help="largest TCP spacing between samples, m")
    parser.add_argument("--speed", type=float, default=1.0, help="peak TCP speed on every leg, m/s")
    args = parser.parse_args(argv)
    from palletizer_kinematics.machine import MACHINE

    model = MACHINE.model(args.config)
    out = args.out_dir
    out.mkdir(parents=True, exist_ok=True)
    trajectory = door_trajectory(model, DOOR_POINTS, step=args.step, speed=args.speed)
    plot_axes(trajectory, out / "palletizer_door_axes.png")
    plot_path(trajectory, DOOR_POINTS, out / "palletizer_door_path.png")
    write_csv(trajectory, out / "palletizer_door.csv")
    wrote_yaml = write_trajectory_yaml(model, trajectory, out / "palletizer_door_trajectory.yaml")
    plot_torque_map(model, out / "palletizer_statics_map.png")
    animate_door(model, trajectory, out / "palletizer_door_path.gif")
    write_door_bag(model, trajectory, out / "palletizer_door_bag")
    print(
        f"door trajectory: {len(trajectory.t)} samples over {trajectory.t[-1]:.3f} s "
        f"(step {args.step:g} m, peak speed {args.speed:g} m/s), variant {model.variant}"
    )
    print(paper_case(model))
    if not wrote_yaml:
        print("trajectory_msgs is not installed: no palletizer_door_trajectory.yaml", file=sys.stderr)
    print(f"wrote {out}")
    return 0
