"""Animated GIFs of a machine's scene (matplotlib, Pillow writer): the plot commands' animations.

:func:`animate` draws a batch of states (a :class:`manipulator_kinematics.scene.Scene` of shape
(N,)) in one or more 2-D views: segments as lines as thick as their solids (in the view's
metres), spheres as discs, the tool point's trace so far and, optionally, a reference path.
A view is a projection of base-frame points (..., 3) to the plane (..., 2): :func:`view_xz`
(side), :func:`view_xy` (top), or :func:`boom_plane` (the vertical plane turning with a swing
angle: the excavator's side view, whatever it swings). Import it with the Agg backend selected
(the plot commands set ``MPLBACKEND``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.collections import LineCollection

from manipulator_kinematics.scene import COLORS, Scene

#: Drawing order of the kinds (later on top).
ORDER = ("base", "link", "linkage", "barrel", "rod", "joint", "tool")

#: (points (..., 3), state index (...) or None) -> plane points (..., 2).
Projection = Callable[[np.ndarray, np.ndarray | None], np.ndarray]


def view_xz(points: np.ndarray, frame: np.ndarray | None) -> np.ndarray:
    """Side view from the machine's right: (x, z)."""
    return points[..., [0, 2]]


def view_xy(points: np.ndarray, frame: np.ndarray | None) -> np.ndarray:
    """Top view: (x, y)."""
    return points[..., [0, 1]]


def boom_plane(heading: np.ndarray) -> Projection:
    """Side view of the vertical plane at ``heading`` (N,) rad about z of each state: (r, z), r
    along the heading. Points without a state (``frame`` None: a reference path) are taken in the
    vertical plane through themselves, as a path of the excavator's bucket tip always is."""

    def project(points: np.ndarray, frame: np.ndarray | None) -> np.ndarray:
        h = np.arctan2(points[..., 1], points[..., 0]) if frame is None else heading[frame]
        c, s = np.cos(h), np.sin(h)  # frame: broadcastable to points.shape[:-1]
        return np.stack((points[..., 0] * c + points[..., 1] * s, points[..., 2]), axis=-1)

    return project


@dataclass(frozen=True)
class View:
    """One panel: a projection, its axis labels and title."""

    project: Projection
    xlabel: str = "x (m)"
    ylabel: str = "z (m)"
    title: str = ""


def frames_for(count: int, duration: float, fps: float, max_frames: int) -> np.ndarray:
    """Indices of the states shown: ``fps`` frames per second of ``duration`` (s of the motion),
    at most ``max_frames``, evenly spaced, last state included."""
    n = int(min(max_frames, max(2, round(duration * fps) + 1)))
    return np.unique(np.round(np.linspace(0, count - 1, n)).astype(int))


def animate(
    scene: Scene,
    path: str | Path,
    views: Sequence[View],
    *,
    times: np.ndarray | None = None,
    reference: np.ndarray | None = None,
    title: str = "",
    fps: float = 10.0,
    speed: float = 1.0,
    max_frames: int = 300,
    size: tuple[float, float] = (6.0, 4.0),
    dpi: int = 80,
    ground: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Write an animated GIF of ``scene`` (N states) to ``path`` and return it.

    ``times`` (N,) s of the states (default: 1 s apart), played ``speed`` times real time at
    ``fps``; ``reference`` (M, 3) a path drawn dashed (base frame); ``ground`` a z drawn as the
    ground line in views whose vertical axis is z; ``progress(frame, frames)`` is called as each
    frame is written (a long GIF takes minutes on a busy machine)."""
    path = Path(path)
    count = scene.shape[0]
    times = np.arange(count, dtype=float) if times is None else np.asarray(times, dtype=float)
    shown = frames_for(count, (times[-1] - times[0]) / speed, fps, max_frames)
    segments = sorted(scene.segments, key=lambda s: ORDER.index(s.kind))
    spheres = sorted(scene.spheres, key=lambda s: ORDER.index(s.kind))
    starts = np.stack([s.start for s in segments], axis=1)  # (N, m, 3)
    ends = np.stack([s.end for s in segments], axis=1)
    centres = np.stack([s.center for s in spheres], axis=1)
    tool = scene.tool_point()
    all_frames = np.arange(count)

    fig, axes = plt.subplots(1, len(views), figsize=size, dpi=dpi, squeeze=False)
    panels = []
    for ax, view in zip(axes[0], views, strict=True):
        # Extent over every state (not only the shown ones), so nothing leaves the picture.
        pts = view.project(scene.points(), all_frames[:, None])
        if reference is not None:
            pts = np.concatenate([pts.reshape(-1, 2), view.project(reference, None)])
        lo, hi = pts.reshape(-1, 2).min(axis=0), pts.reshape(-1, 2).max(axis=0)
        pad = 0.06 * float(np.max(hi - lo))
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel(view.xlabel)
        ax.set_ylabel(view.ylabel)
        ax.set_title(view.title, fontsize=9)
        ax.grid(True, linewidth=0.3, alpha=0.5)
        if ground is not None and view.ylabel.startswith("z"):
            ax.axhline(ground, color="0.45", linewidth=1.0)
        if reference is not None:
            r = view.project(reference, None)
            ax.plot(r[:, 0], r[:, 1], "--", color="tab:blue", linewidth=0.9, label="reference")
        panels.append((ax, view))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.canvas.draw()

    artists = []
    for ax, view in panels:
        # Metres -> points of this panel (equal aspect: one scale for x and y).
        metre = (ax.transData.transform((1.0, 0.0)) - ax.transData.transform((0.0, 0.0)))[0] * 72.0 / dpi
        lines = LineCollection(
            [],
            linewidths=[2.0 * s.radius * metre for s in segments],
            colors=[COLORS[s.kind] for s in segments],
            capstyle="round",
        )
        ax.add_collection(lines)
        first = view.project(centres[shown[0]], shown[0])
        discs = ax.scatter(
            first[:, 0],
            first[:, 1],
            s=[(2.0 * s.radius * metre) ** 2 for s in spheres],
            c=[COLORS[s.kind] for s in spheres],
            zorder=3,
            linewidths=0,
        )
        (trace,) = ax.plot([], [], color="tab:red", linewidth=1.0, label="tool trace", zorder=4)
        if reference is not None:
            ax.legend(loc="best", fontsize=9, framealpha=0.6)
        artists.append((view, lines, discs, trace))
    clock = fig.text(0.01, 0.01, "", fontsize=9)

    def draw(k: int) -> list:
        i = int(shown[k])
        out = []
        for view, lines, discs, trace in artists:
            a, b = view.project(starts[i], i), view.project(ends[i], i)
            lines.set_segments(np.stack((a, b), axis=1))
            discs.set_offsets(view.project(centres[i], i))
            done = shown[: k + 1]
            t = view.project(tool[done], done)
            trace.set_data(t[:, 0], t[:, 1])
            out += [lines, discs, trace]
        clock.set_text(f"t = {times[i] - times[0]:5.1f} s")
        return [*out, clock]

    animation = FuncAnimation(fig, draw, frames=len(shown), blit=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    animation.save(path, writer=PillowWriter(fps=fps), progress_callback=progress)
    plt.close(fig)
    return path


__all__ = ["View", "animate", "boom_plane", "frames_for", "view_xy", "view_xz"]
