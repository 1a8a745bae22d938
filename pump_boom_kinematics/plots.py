"""Pictures of the pump boom in the style of paper 001's figures, and ``pump_boom_plots``.

* Fig. 5: the area swept by the paper's example angles, positive-envelope part marked;
* Fig. 6: the region table's squares over the reachable region of the pour plane;
* Figs. 9-12: the two typical straight-line pours (a horizontal line in a vertical plane, a
  slanted line in a horizontal plane) with the boom drawn at a few points, the six joint angles
  along each path, and a CSV of every point;
* each pour animated (``pump_boom_<pour>.gif``: boom plane and top view, from the shared scene).

matplotlib with the Agg backend (no display needed).
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from pump_boom_kinematics.build_regions import Coverage, reachable_area
from pump_boom_kinematics.kinematics import PumpBoom
from pump_boom_kinematics.pour import TYPICAL_POURS, PathPlan, pour_line

PREFIX = "pump_boom_"


def _boom_side(ax: plt.Axes, plane: np.ndarray, **style: object) -> None:
    ax.plot(plane[:, 0], plane[:, 1], "-o", ms=3, lw=1.5, **style)


def _truck(ax: plt.Axes, boom: PumpBoom) -> None:
    ax.add_patch(Rectangle((-6.0, 0.0), 12.0, boom.root[1] - 0.5, color="0.6", alpha=0.5))
    ax.axhline(0.0, color="0.3", lw=0.8)


def plot_regions(boom: PumpBoom, out: Path, area: Coverage | None = None) -> Path:
    """Fig. 6: the region table's squares over the reachable region, the positive-envelope part
    covered and not covered by the table in different colours."""
    area = reachable_area(boom) if area is None else area
    table = boom.table
    centres = area.centres
    covered = table.contains(centres[..., 0], centres[..., 1])
    # 1: reachable, not positive envelope; 2: positive envelope, not covered; 3: covered.
    shade = np.where(covered, 3, np.where(area.envelope, 2, np.where(area.reachable, 1, 0)))
    colours = ListedColormap(["white", "0.8", "tab:red", "#b9dcb0"])
    fig, ax = plt.subplots(figsize=(9, 11))
    extent = (area.r_edges[0], area.r_edges[-1], area.z_edges[0], area.z_edges[-1])
    ax.imshow(
        shade.T, origin="lower", extent=extent, cmap=colours, vmin=-0.5, vmax=3.5, interpolation="nearest"
    )
    half = table.grid.band / 2
    for (i, j, level), t in zip(table.index.tolist(), np.degrees(table.triples)):
        r, z = table.grid.corner(i, j, level)
        s = float(table.grid.side(level))
        ax.add_patch(
            Rectangle(
                (r, z),
                s,
                s,
                fill=False,
                ec="tab:green" if level else "darkgreen",
                lw=0.8 if level == 0 else 0.3,
            )
        )
        if level == 0:
            core = Rectangle((r + half, z + half), s - 2 * half, s - 2 * half, fill=False, ec="darkgreen")
            core.set_linestyle(":")
            core.set_linewidth(0.4)
            ax.add_patch(core)
            ax.text(
                r + s / 2,
                z + s / 2,
                f"{t[0]:.0f}/{t[1]:.0f}/{t[2]:.0f}",
                ha="center",
                va="center",
                fontsize=6.5,
            )
    _truck(ax, boom)
    ax.plot(*boom.root, "k^")
    c = table.coverage
    levels, counts = np.unique(table.index[:, 2], return_counts=True)
    sizes = ", ".join(f"{n} x {float(table.grid.side(level)):g} m" for level, n in zip(levels, counts))
    ax.set_title(
        f"Region table: {len(table)} squares, {c['covered_area']:.0f} m²\n({sizes})\n"
        f"green: covered, {100 * c['covered_share']:.1f} % of the {c['envelope_area']:.0f} m² reachable "
        "in positive envelope;\nred: not covered; grey: reachable only outside positive envelope;\n"
        f"5 m squares: θ2/θ3/θ4 (deg), dotted: {table.grid.band:g} m bands",
        fontsize=10,
    )
    ax.set_xlabel("r (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal")
    ax.set_xlim(-7, extent[1])
    ax.set_ylim(extent[2], extent[3])
    return _save(fig, out / f"{PREFIX}regions.png")


def plot_example_area(boom: PumpBoom, out: Path) -> Path:
    """Fig. 5: the area swept by the paper's example angles (theta5, theta6 over their ranges)."""
    q = boom.example_sweep(201)
    tips = boom.plane_points(q)[..., -1, :].reshape(-1, 2)
    envelope = boom.positive_envelope(q).reshape(-1)
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot(*tips[envelope].T, ",", color="tab:blue", label="positive envelope")
    ax.plot(*tips[~envelope].T, ",", color="tab:orange", label="not positive envelope")
    for k in ((0, 0), (100, 100), (200, 200), (0, 200), (200, 0)):
        _boom_side(ax, boom.plane_points(q[k]), color="0.3")
    lo = np.floor(tips.min(axis=0) / 5.0) * 5.0
    hi = np.ceil(tips.max(axis=0) / 5.0) * 5.0
    for r in np.arange(lo[0], hi[0], 5.0):
        for z in np.arange(lo[1], hi[1], 5.0):
            ax.add_patch(Rectangle((r, z), 5, 5, fill=False, ec="0.7", lw=0.5))
    _truck(ax, boom)
    ax.set_title(
        "Area of the paper's example (Fig. 5): θ1 = 0, θ2 = 75, θ3 = 165, θ4 = 160,\n"
        "θ5 = 160-240, θ6 = 30-170 deg; grey: 5 m squares aligned at (0, 0)",
        fontsize=9,
    )
    # The tips are drawn as single pixels: the legend gets markers of its own (markerscale does
    # not scale the pixel marker).
    ax.legend(
        handles=[
            Line2D([], [], ls="", marker="s", ms=9, color=c, label=label)
            for c, label in (("tab:blue", "positive envelope"), ("tab:orange", "not positive envelope"))
        ],
        loc="lower right",
    )
    ax.set_xlabel("r (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal")
    return _save(fig, out / f"{PREFIX}example_area.png")


def plot_pour(boom: PumpBoom, plan: PathPlan, name: str, title: str, out: Path) -> list[Path]:
    """Path with the boom drawn at a few points (Figs. 9/10), the six angles (Figs. 11/12), a CSV."""
    fig, (top, side) = plt.subplots(1, 2, figsize=(12, 5.5))
    picks = np.linspace(0, len(plan.q) - 1, 5).astype(int)
    points = boom.points(plan.q[picks])
    for k, p in enumerate(points):
        colour = plt.cm.viridis(k / max(len(points) - 1, 1))
        top.plot(p[:, 0], p[:, 1], "-o", ms=3, color=colour)
        radius = np.hypot(p[:, 0], p[:, 1])
        side.plot(radius, p[:, 2], "-o", ms=3, color=colour)
    top.plot(plan.points[:, 0], plan.points[:, 1], "r-", lw=2, label="pour path")
    side.plot(np.hypot(plan.points[:, 0], plan.points[:, 1]), plan.points[:, 2], "r-", lw=2)
    top.plot(0, 0, "k+")
    top.set(xlabel="x (m)", ylabel="y (m)", title="top view", aspect="equal")
    side.set(xlabel="r = hypot(x, y) (m)", ylabel="z (m)", title="boom plane (r, z)", aspect="equal")
    _truck(side, boom)
    top.legend()
    fig.suptitle(title)
    paths = [_save(fig, out / f"{PREFIX}{name}_path.png")]
    fig, ax = plt.subplots(figsize=(10, 5))
    degrees = np.degrees(plan.q)
    for k, label in enumerate(("θ1", "θ2", "θ3", "θ4", "θ5", "θ6")):
        ax.plot(plan.s, degrees[:, k], label=label)
    band = plan.blended.astype(float)
    ax.fill_between(
        plan.s,
        0,
        1,
        where=band > 0,
        color="0.85",
        transform=ax.get_xaxis_transform(),
        label="transition band",
    )
    ax.set(
        xlabel="path length (m)",
        ylabel="joint angle (deg, paper convention)",
        title=f"{title}: joint angles along the path (cf. Figs. 11/12)",
    )
    ax.legend(ncol=7, fontsize=8, loc="upper center")
    paths.append(_save(fig, out / f"{PREFIX}{name}_angles.png"))
    csv_path = out / f"{PREFIX}{name}.csv"
    with open(csv_path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(["t_s", "s_m", "x_m", "y_m", "z_m", *(f"theta{k}_rad" for k in range(1, 7)), "band"])
        for t, s, p, q, b in zip(plan.t, plan.s, plan.points, plan.q, plan.blended):
            writer.writerow(
                [f"{t:.4f}", f"{s:.4f}", *(f"{v:.6f}" for v in p), *(f"{v:.9f}" for v in q), int(b)]
            )
    paths.append(csv_path)
    return paths


def animate_pour(boom: PumpBoom, plan: PathPlan, name: str, title: str, out: Path) -> Path:
    """The boom along a pour (shared scene): its plane (r, z) and the top view, about 12 s long."""
    from manipulator_kinematics.animation import View, animate, boom_plane, view_xy
    from pump_boom_kinematics.machine import MACHINE

    scene = MACHINE.scene(boom, plan.q)
    root = scene.frames["frame_1"][:, :3, 3]  # the root pin: in the boom's vertical plane
    heading = np.arctan2(root[:, 1], root[:, 0])
    speed = max(1.0, float(plan.t[-1] - plan.t[0]) / 12.0)
    views = [
        View(boom_plane(heading), "r (m)", "z (m)", "boom plane"),
        View(view_xy, "x (m)", "y (m)", "top"),
    ]
    return animate(
        scene,
        out / f"{PREFIX}{name}.gif",
        views,
        times=plan.t,
        reference=plan.points,
        ground=0.0,
        speed=speed,
        size=(8.0, 3.8),
        title=f"{title} ({speed:.0f}x speed)",
    )


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")  # equal-aspect axes: keep every label inside
    plt.close(fig)
    return path


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="pump_boom_plots", description="Figures 5, 6 and 9-12 of paper 001 for the default pump boom."
    )
    parser.add_argument("output", type=Path, help="directory for the PNGs and CSVs")
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    boom = PumpBoom.default()
    written = [plot_regions(boom, args.output), plot_example_area(boom, args.output)]
    for name, (title, start, end) in TYPICAL_POURS.items():
        plan = pour_line(boom, start, end)
        print(f"{name}: {plan.message}")
        written += plot_pour(boom, plan, name, title, args.output)
        written.append(animate_pour(boom, plan, name, title, args.output))
    for path in written:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
