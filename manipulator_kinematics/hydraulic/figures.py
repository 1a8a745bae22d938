"""Pictures of any hydraulic-family machine from its pins: an animated GIF of a motion through
keyframes of D (:func:`family_gif`) and the working-range diagram (:func:`working_range`).
scripts/make_family_figures.py writes the wheel loader's and the knuckle crane's into docs/.
Import with the Agg backend selected (``MPLBACKEND=Agg``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from manipulator_kinematics.animation import View, animate, boom_plane, view_xy
from manipulator_kinematics.hydraulic.check import box_grid
from manipulator_kinematics.hydraulic.drawing import family_scene
from manipulator_kinematics.scene import COLORS

__all__ = ["family_gif", "keyframe_motion", "working_range"]


def keyframe_motion(
    keyframes: Sequence[Sequence[float]], seconds: Sequence[float], rate: float = 20.0
) -> np.ndarray:
    """States (N, m) through ``keyframes`` (K, m), each leg of ``seconds[k]`` s at ``rate`` Hz,
    eased in and out (3 s^2 - 2 s^3: every actuator at rest at each keyframe)."""
    keys = np.asarray(keyframes, dtype=float)
    legs = []
    for (a, b), duration in zip(itertools.pairwise(keys), seconds, strict=True):
        s = np.linspace(0.0, 1.0, max(2, round(duration * rate)), endpoint=False)
        ease = 3.0 * s**2 - 2.0 * s**3
        legs.append(a + ease[:, None] * (b - a))
    return np.concatenate((*legs, keys[-1:]))


def family_gif(arm: Any, D: np.ndarray, path: str | Path, title: str, rate: float = 20.0) -> Path:
    """GIF of the machine (a FamilyArm) along states D (N, m) sampled at ``rate`` Hz: the side view
    in the boom plane (it turns with the swing) and, for a swinging machine, the top view."""
    h = arm.hydraulic
    scene = family_scene(arm, D)
    heading = D[:, 0] if h.swing else np.zeros(len(D))
    views = [View(boom_plane(heading), "r (m), in the boom plane", "z (m)", "side view")]
    size = (6.0, 4.0)
    if h.swing:
        views.append(View(view_xy, "x (m)", "y (m)", "top view"))
        size = (9.0, 4.2)
    times = np.arange(len(D)) / rate
    return animate(scene, path, views, times=times, title=title, fps=10.0, size=size, ground=0.0)


def working_range(arm: Any, path: str | Path, title: str, n: int = 25) -> Path:
    """PNG of the tool point over an n-point grid of every cylinder's stroke (swing at its
    reference) in the boom plane, with the linkage drawn at the reference state."""
    h = arm.hydraulic
    grid = box_grid(h, n)
    Q = h.pose(grid)
    t1 = grid[:, 0] if h.swing else np.zeros(len(grid))
    r = Q[:, 0] * np.cos(t1) + Q[:, 1] * np.sin(t1)
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    ax.scatter(
        r, Q[:, 2], s=2, color="tab:blue", alpha=0.35, linewidths=0, label="tool point over the stroke box"
    )
    scene = family_scene(arm, h.reference)
    for s in scene.segments:
        a, b = s.start, s.end
        ax.plot([a[0], b[0]], [a[2], b[2]], color=COLORS[s.kind], linewidth=2.5, solid_capstyle="round")
    pins = np.array([s.center for s in scene.spheres])
    ax.scatter(pins[:, 0], pins[:, 2], s=10, color=COLORS["joint"], zorder=3)
    ax.axhline(0.0, color="0.45", linewidth=1.0)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("r (m), forward in the boom plane")
    ax.set_ylabel("z (m)")
    ax.set_title(
        f"{title}\nreach {r.min():.2f} .. {r.max():.2f} m, "
        f"height {Q[:, 2].min():.2f} .. {Q[:, 2].max():.2f} m",
        fontsize=10,
    )
    ax.grid(True, linewidth=0.3, alpha=0.5)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
