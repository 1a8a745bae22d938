"""The figure of docs/zones.md: the excavator stopping at a ceiling (a power line), side view.

``python -m excavator_kinematics.tools.zones_figure OUT.png`` drives the machine file's machine from its
reference state with a constant target (the tip straight up at 0.6 m/s, bucket angle
held) through the velocity IK's steps at 100 Hz (twist split, rate command, zone factor of
:class:`manipulator_kinematics.zone_guard.ZoneGuard` for the monitored points of
:class:`excavator_kinematics.core.monitored.MonitoredPoints`, as ``excavator_velocity_ik`` checks a
command: the points' paths to second order, with their accelerations, and the command's period
and the command in force's delay from :class:`manipulator_kinematics.zone_guard.CommandTimes`, here
a state of no age) on ideal actuators, under a ceiling at
7.5 m with a 0.5 m margin, and draws the machine every 0.5 s until it stops (the last pose bold, its monitored
points as dots, the one nearest the ceiling ringed), the ceiling and its margin, and the zone
factor and the smallest clearance over time. matplotlib, no rclpy.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.core.plant import Plant
from excavator_kinematics.core.rate_command import rate_command
from excavator_kinematics.core.twist import split_twist
from excavator_kinematics.tools.scene import BODIES, LINKAGE
from manipulator_kinematics.zone_guard import CommandTimes, ZoneGuard
from manipulator_kinematics.zones import Zone

HEIGHT, MARGIN = 7.5, 0.5
RATE, SECONDS = 100.0, 5.0
TARGET = np.array([0.0, 0.0, 0.6])


def drive(exc: Excavator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, states D and zone factors of the drive at the ceiling (module docstring)."""
    points = MonitoredPoints(exc)
    ceiling = Zone("power_line", "ceiling", "base", MARGIN, {"height": HEIGHT})
    guard = ZoneGuard([ceiling], points.names, exc.limits.max_rates / 0.3, 0.05)
    plant = Plant(exc.limits, exc.limits.reference)
    times = CommandTimes()
    states, scales = [plant.d.copy()], [1.0]
    for k in range(int(SECONDS * RATE)):
        D = plant.d.copy()
        split = split_twist(D[0], exc.pose(D)[:3], TARGET, np.zeros(3))
        rates = rate_command(exc.jc0(D), D, split.q_dot, exc.limits, 50.0, 0.1)
        p, v, a = points.motion(D, rates.d_dot)
        period, delay = times(k / RATE, k / RATE)  # computed at once from the state just sampled
        verdict = guard.check(p, v, rates.d_dot, period=period, accelerations=a, delay=delay)
        plant.step(verdict.scale * rates.d_dot, 1.0 / RATE)
        states.append(plant.d.copy())
        scales.append(verdict.scale * rates.scale)
    return np.arange(len(states)) / RATE, np.array(states), np.array(scales)


def draw(exc: Excavator, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, states, scales = drive(exc)
    points = MonitoredPoints(exc)
    positions = points.positions(states)  # (N, P, 3); swing 0: the side view is x, z
    clearance = HEIGHT - MARGIN - positions[..., 2].max(axis=-1)
    fig, (side, timeline) = plt.subplots(
        1, 2, figsize=(12, 5.2), gridspec_kw={"width_ratios": [1.25, 1]}, constrained_layout=True
    )
    side.axhspan(HEIGHT, HEIGHT + 1.5, color="tab:red", alpha=0.25, lw=0)
    side.axhspan(HEIGHT - MARGIN, HEIGHT, color="tab:orange", alpha=0.2, lw=0)
    side.axhline(HEIGHT, color="tab:red", lw=1.5)
    side.axhline(HEIGHT - MARGIN, color="tab:orange", lw=1, ls="--")
    side.text(-2.6, HEIGHT + 0.15, f"ceiling (power line) {HEIGHT:g} m", color="tab:red")
    side.text(-2.6, HEIGHT - MARGIN + 0.1, f"margin {MARGIN:g} m", color="tab:orange")
    stop = int(np.argmax(scales < 1e-9)) if np.any(scales < 1e-9) else len(t) - 1
    for k in [*range(0, stop, int(RATE / 2)), len(states) - 1]:
        final = k == len(states) - 1
        pins = exc.pins(states[k])
        style = (
            {"color": "k", "lw": 2.2, "alpha": 1.0}
            if final
            else {"color": "tab:blue", "lw": 1.0, "alpha": 0.35}
        )
        for outline in (*BODIES.values(), *LINKAGE.values()):
            xz = np.array([pins[name][[0, 2]] for name in outline])
            side.plot(xz[:, 0], xz[:, 1], **style)
        for cylinder in ("boom_cylinder", "arm_cylinder", "bucket_cylinder"):
            xz = np.array([pins[f"{cylinder}_base"][[0, 2]], pins[f"{cylinder}_rod"][[0, 2]]])
            side.plot(
                xz[:, 0], xz[:, 1], color=style["color"], lw=style["lw"] * 1.8, alpha=style["alpha"] * 0.5
            )
    last = positions[-1]
    side.plot(last[:, 0], last[:, 2], "o", ms=4, color="tab:green", label="monitored points")
    top = int(np.argmax(last[:, 2]))
    side.plot(
        last[top, 0],
        last[top, 2],
        "o",
        ms=12,
        mfc="none",
        color="tab:red",
        label=f"nearest: {points.names[top]}",
    )
    side.fill_between([-2.75, 0.9], 1.05, 2.25, color="0.85", lw=0, zorder=0)  # the upper structure
    side.set(
        xlabel="x (m), base frame", ylabel="z (m)", xlim=(-3.2, 7.0), ylim=(0.0, HEIGHT + 1.0), aspect="equal"
    )
    side.set_title("CET200, target: the tip straight up at 0.6 m/s; a pose every 0.5 s")
    side.legend(loc="lower right")
    timeline.plot(t, scales, color="tab:blue", label="command scale (zone x stroke rule)")
    timeline.set(xlabel="time (s)", ylabel="scale of the target", ylim=(-0.05, 1.1))
    right = timeline.twinx()
    right.plot(t, clearance, color="tab:red", label="smallest clearance")
    right.set_ylabel("smallest clearance to ceiling - margin (m)", color="tab:red")
    right.set_ylim(-0.05 * clearance.max(), clearance.max() * 1.1)
    timeline.axvline(t[stop], color="0.5", ls=":")
    timeline.text(t[stop], 0.5, f" stopped {clearance[stop] * 1000:.1f} mm\n before the margin", color="0.3")
    lines = timeline.get_lines()[:1] + right.get_lines()
    timeline.legend(lines, [line.get_label() for line in lines], loc="upper right")
    timeline.set_title(
        "slowed approaching the zone, stopped at it\n(the node's check: the points' paths to second order)"
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", type=Path)
    args = parser.parse_args(argv)
    draw(Excavator.default(), args.output)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
