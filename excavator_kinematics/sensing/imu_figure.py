"""The figure of docs/excavator_imu.md: the IMU bodies, their frames and the side angles.

``python -m excavator_kinematics.sensing.imu_figure OUT.png [--pitch PERCENT]`` draws the machine file's
machine (side view, swing 0) standing on a slope of ``--pitch`` percent (nose down for a negative
value), in the gravity-aligned level frame: each sensor body's frame (x red, z blue; a sensor with
``rotation_rpy: [0, 0, 0]`` has these axes), world up, and each body's side angle a = atan2(ux, uz)
of up in its frame (:mod:`excavator_kinematics.sensing.imu`). matplotlib, no rclpy.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from excavator_kinematics.core.kinematics import Excavator


def draw(exc: Excavator, path: Path, pitch_percent: float = -5.0) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    D = exc.limits.reference.copy()
    pins = {name: p[[0, 2]] for name, p in exc.pins(D).items()}  # side view [r, z], base frame
    theta = exc.state(D, np.zeros(4)).theta
    pitch = math.atan(pitch_percent / 100.0)  # the base frame turned about -y by this in the level frame
    c, s = math.cos(pitch), math.sin(pitch)

    def level(p: np.ndarray) -> np.ndarray:
        return np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])

    fig, ax = plt.subplots(figsize=(11, 6.5))
    ground = np.array([[-3.0, 0.0], [10.0, 0.0]])
    ax.plot(
        *np.array([level(p) for p in ground]).T,
        color="saddlebrown",
        lw=2,
        label=f"ground, {pitch_percent:+g} % (base frame x axis)",
    )
    chains = [
        ("boom_foot", "arm_pin", "bucket_pin", "bucket_tip"),
        ("side_link_pivot", "bucket_cylinder_rod", "h_link_pin"),
        ("bucket_pin", "h_link_pin"),
        ("boom_cylinder_base", "boom_cylinder_rod"),
        ("arm_cylinder_base", "arm_cylinder_rod"),
        ("bucket_cylinder_base", "bucket_cylinder_rod"),
    ]
    for chain in chains:
        ax.plot(*np.array([level(pins[n]) for n in chain]).T, "-o", color="0.35", ms=3, lw=2)
    cab = np.array([[-1.5, 0.4], [1.3, 0.4], [1.3, 2.9], [-1.5, 2.9], [-1.5, 0.4]])
    ax.plot(*np.array([level(p) for p in cab]).T, color="0.6", lw=1)
    h = pins["h_link_pin"] - pins["bucket_cylinder_rod"]
    bodies = [  # name, where the frame is drawn, body angle in the base frame's side view
        ("cab = base frame\n(upper structure)", np.array([0.0, 2.2]), 0.0),
        ("boom", 0.5 * (pins["boom_foot"] + pins["arm_pin"]), theta[1]),
        ("arm", 0.5 * (pins["arm_pin"] + pins["bucket_pin"]), theta[1] + theta[2]),
        ("H-link (dogbone):\nx rod pin -> H-link pin", pins["h_link_pin"], math.atan2(h[1], h[0])),
        ("bucket", 0.5 * (pins["bucket_pin"] + pins["bucket_tip"]), theta[1] + theta[2] + theta[3]),
    ]
    length = 0.7
    for name, origin, angle in bodies:
        o = level(origin)
        turn = angle + pitch  # in the level frame
        x_axis = length * np.array([math.cos(turn), math.sin(turn)])
        z_axis = length * np.array([-math.sin(turn), math.cos(turn)])
        ax.annotate("", o + x_axis, o, arrowprops={"arrowstyle": "->", "color": "tab:red", "lw": 2})
        ax.annotate("", o + z_axis, o, arrowprops={"arrowstyle": "->", "color": "tab:blue", "lw": 2})
        ax.annotate("", o + [0.0, 0.55], o, arrowprops={"arrowstyle": "->", "color": "tab:green", "lw": 1})
        side = turn  # a = atan2(ux, uz) of world up in the body frame: its turn from level
        ax.text(*(o + [0.12, -0.35]), f"{name}\na = {math.degrees(side):+.1f} deg", fontsize=8)
    ax.plot([], [], color="tab:red", lw=2, label="body x (sensor x at rotation_rpy [0, 0, 0])")
    ax.plot(
        [],
        [],
        color="tab:blue",
        lw=2,
        label="body z (sensor z); body y points into the page (the machine's left)",
    )
    ax.plot([], [], color="tab:green", lw=1, label="world up (gravity aligned, level frame z)")
    ax.set_title(
        f"{exc.name}: IMU bodies and their frames, side view from the right, on a "
        f"{pitch_percent:+g} % slope\n theta2 = a_boom - a_cab, theta3 = a_arm - a_boom, "
        "theta4 = a_bucket - a_arm (or from the H-link's angle through the four-bar)"
    )
    ax.set_xlabel("level frame x (m)")
    ax.set_ylabel("level frame z (m)")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", type=Path)
    parser.add_argument("--pitch", type=float, default=-5.0, help="slope in percent (default -5)")
    args = parser.parse_args(argv)
    draw(Excavator.default(), args.output, args.pitch)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
