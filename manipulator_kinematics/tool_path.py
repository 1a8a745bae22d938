"""Straight tool-point lines through waypoints, timed within the actuators' speed limits (numpy
only): the walk, the timing and the zone check every machine's ``plan_path`` of this kind shares
(the excavator's bucket paths, :mod:`excavator_kinematics.core.path`; the hydraulic family's,
:mod:`manipulator_kinematics.hydraulic.path`). The machine gives a :data:`LineSolver`: the
actuator coordinates D of sample points, on the branch and with the tool angle it holds.

1. Each straight line to the next waypoint is sampled every ``step``
   (:func:`manipulator_kinematics.trajectory.straight_line`) and every sample solved; a sample
   the solver refuses ends the path at the farthest solvable point of that line (bisection to
   :data:`END_TOLERANCE`), with the solver's reason (for the sample beyond, from the state where
   the line ends) and the last waypoint reached in full.
2. The samples are timed by :func:`manipulator_kinematics.time_scaling.time_scale`: no actuator
   above its max speed, the tip not above ``tip_speed``, the tip's acceleration along the path
   at most ``acceleration``, at rest at both ends and at every corner (a turn at speed would take
   an unbounded acceleration; lines in one direction run on); slowed only where a limit binds.
3. :func:`clear_of_zones`: the plan's monitored points checked against avoidance zones
   (docs/zones.md) at every sample; the path ends at the sample before the first entry.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from manipulator_kinematics.plan_bounds import MAX_DURATION
from manipulator_kinematics.time_scaling import TimeScaling, time_scale
from manipulator_kinematics.trajectory import straight_line
from manipulator_kinematics.zone_guard import first_entry
from manipulator_kinematics.zones import Zone

#: Bisection of the reachable end of a line stops when the bracket is shorter than this (m).
END_TOLERANCE = 1e-6
#: Two lines whose directions differ by less than this (rad) are one stretch, no stop between.
CORNER = 1e-9

#: ``solve(points (N, 3), previous D (m,)) -> (D (N, m), first refused sample or None, why)``:
#: the machine's D of consecutive samples after the state ``previous``; a sample it cannot reach
#: on the held branch and tool angle (or reached by a jump from its neighbour) is refused.
LineSolver = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, int | None, str]]


@dataclass(frozen=True)
class ToolPlan:
    """A planned path: ``points`` (M, 3) tool positions, ``timing`` the timed D (``timing.q``
    (M, m), None when not even the first waypoint is solvable); ``truncated`` the path ends short
    of the last waypoint; ``last_waypoint`` the last waypoint reached in full (-1: none);
    ``message`` what happened, in words."""

    points: np.ndarray
    timing: TimeScaling | None
    truncated: bool
    last_waypoint: int
    message: str

    @property
    def ok(self) -> bool:
        return self.timing is not None


def show(p: np.ndarray) -> str:
    """A point in a message: ``(x, y, z) m``."""
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ") m"


def walk_lines(
    waypoints: np.ndarray,
    first: np.ndarray,
    step: float,
    solve: LineSolver,
    max_rates: np.ndarray,
    names: Sequence[str],
    tip_speed: float,
    acceleration: float,
    held: str,
) -> ToolPlan:
    """The path through ``waypoints`` (K, 3) (checked by
    :func:`manipulator_kinematics.plan_bounds.check_plan`) from ``first``, the solved D of the
    first waypoint (module docstring, steps 1-2); ``held`` ends the message of a full path (what
    the machine kept constant, e.g. ", bucket angle 12 deg")."""
    # Each line from its start (the previous line's end) to its end: points and D.
    lines: list[tuple[np.ndarray, np.ndarray]] = []
    start, previous = waypoints[0], first
    for k in range(1, len(waypoints)):
        goal = waypoints[k]
        line = straight_line(start, goal, step)[1:]
        if len(line) == 0:
            continue
        solved, bad, reason = solve(line, previous)
        if bad is not None:
            before = start if bad == 0 else line[bad - 1]
            end = _farthest(solve, before, line[bad], previous if bad == 0 else solved[bad - 1])
            beyond, line = line[bad], straight_line(start, end, step)[1:]
            reached = previous
            if len(line):
                reached = solve(line, previous)[0]
                lines.append((np.vstack((start, line)), np.vstack((previous, reached))))
                reached = reached[-1]
            # Why, from where the line ends: the state there says what stops it.
            reason = solve(beyond[None], reached)[2] or reason
            text = (
                f"waypoint {k} {show(goal)} cannot be reached along the line from {show(start)}: "
                f"{reason}; the path ends at the farthest reachable point of the line {show(end)}"
            )
            return _timed(lines, first, max_rates, names, tip_speed, acceleration, True, k - 1, text)
        lines.append((np.vstack((start, line)), np.vstack((previous, solved))))
        start, previous = line[-1], solved[-1]
    text = f"through {len(waypoints)} waypoint(s), step {step:g} m{held}"
    return _timed(lines, first, max_rates, names, tip_speed, acceleration, False, len(waypoints) - 1, text)


def _farthest(solve: LineSolver, good: np.ndarray, bad: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """The boundary between a solvable point ``good`` and an unsolvable ``bad`` (bisection)."""
    while np.linalg.norm(bad - good) > END_TOLERANCE:
        middle = 0.5 * (good + bad)
        if solve(middle[None], previous)[1] is None:
            good = middle
        else:
            bad = middle
    return good


def _timed(
    lines: list[tuple[np.ndarray, np.ndarray]],
    first: np.ndarray,
    max_rates: np.ndarray,
    names: Sequence[str],
    tip_speed: float,
    acceleration: float,
    truncated: bool,
    last: int,
    text: str,
) -> ToolPlan:
    """Time the lines, each from rest to rest where the path turns a corner (a direction change at
    speed would need an unbounded acceleration); lines in one direction are one stretch."""
    stretches: list[tuple[np.ndarray, np.ndarray]] = []
    for points, D in lines:
        direction = points[-1] - points[0]
        if stretches:
            before = stretches[-1][0]
            previous = before[-1] - before[0]
            scale = np.linalg.norm(previous) * np.linalg.norm(direction)
            if np.linalg.norm(np.cross(previous, direction)) <= CORNER * scale and previous @ direction > 0.0:
                stretches[-1] = (np.vstack((before, points[1:])), np.vstack((stretches[-1][1], D[1:])))
                continue
        stretches.append((points, D))
    if not stretches:  # one point: at rest
        stretches = [(lines[0][0][:1] if lines else np.empty((0, 3)), first[None])]
    timings = []
    for points, D in stretches:
        s = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))))
        timings.append(time_scale(D, s, max_rates, tip_speed, acceleration))
    timing = _joined(timings)
    if not timing.duration <= MAX_DURATION:
        raise ValueError(
            f"the path would take {timing.duration:.3g} s; at most {MAX_DURATION:g} s (a higher "
            "tip speed or acceleration, or a shorter path)"
        )
    limited = ", ".join(f"{name} {n}" for name, n in timing.limited_by(list(names)).items())
    message = (
        f"{len(timing.t)} points {text}, tip speed <= {tip_speed:g} m/s, {timing.duration:.4g} s, "
        f"{len(stretches)} stretch(es) from rest to rest; samples set by: {limited}"
    )
    points = np.vstack([stretches[0][0][:1], *(p[1:] for p, _ in stretches)])
    return ToolPlan(points, timing, truncated, last, message)


def _joined(timings: list[TimeScaling]) -> TimeScaling:
    """One timing of stretches that meet at rest: times and arc lengths run on, the meeting
    sample once, its acceleration the mean of the braking and the starting one (as within a
    stretch: the mean of the adjacent segments')."""
    first = timings[0]
    t, s, rows = (
        [first.t],
        [first.s],
        {name: [getattr(first, name)] for name in ("q", "qd", "qdd", "speed", "sdd", "active")},
    )
    for timing in timings[1:]:
        t.append(t[-1][-1] + timing.t[1:])
        s.append(s[-1][-1] + timing.s[1:])
        for name, row in rows.items():
            values = getattr(timing, name)
            if name in ("qdd", "sdd"):
                row[-1] = row[-1].copy()
                row[-1][-1] = 0.5 * (row[-1][-1] + values[0])
            row.append(values[1:])
    return TimeScaling(
        t=np.concatenate(t), s=np.concatenate(s), **{name: np.concatenate(row) for name, row in rows.items()}
    )


P = TypeVar("P", bound=ToolPlan)


def clear_of_zones(
    plan: Callable[[np.ndarray], P],
    waypoints: np.ndarray,
    zones: Sequence[Zone],
    names: Sequence[str],
    positions: Callable[[np.ndarray], np.ndarray],
    site: tuple[np.ndarray, np.ndarray] | None = None,
) -> P:
    """``plan(waypoints)`` ended before the first zone a monitored point would enter; the plan as
    it is when none would. ``positions(D (M, m)) -> (M, P, 3)``: the monitored points ``names``
    in the base frame, checked at every sample (``step`` apart along the tool's path; between
    samples a point moves by about that, which the zones' margins cover). Where a point would
    enter a zone the path ends at the sample before, planned again through the waypoints reached
    so it comes to rest there, with the reason. A path whose first sample is already inside a
    zone is refused (no trajectory): the velocity IK moves a machine out of a zone, a plan does
    not start in one. ``site`` = (R, t), base frame in the site frame (p_site = R p + t), places
    site-frame zones (ValueError when one is given without it)."""
    full = plan(waypoints)
    if full.timing is None or not zones:
        return full
    hit = first_entry(zones, names, positions(full.timing.q), site)
    if hit is None:
        return full
    k, zone, point = hit
    where = f"{point} enters zone {zone} (zones.{zone}) at {show(full.points[k])} of the tip's path"
    if k == 0:
        return dataclasses.replace(
            full,
            points=full.points[:0],
            timing=None,
            truncated=True,
            last_waypoint=-1,
            message=f"the path starts inside a zone: {where}",
        )
    end = full.points[k - 1]
    # The waypoints passed in full before the sample: their arc lengths along the path.
    reached = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))))
    last = int(np.searchsorted(reached, full.timing.s[k - 1] + 1e-9, side="right")) - 1
    short = plan(np.vstack((waypoints[: last + 1], end)))
    message = f"{where}; the path ends before it at {show(end)}, after waypoint {last}: {short.message}"
    return dataclasses.replace(short, truncated=True, last_waypoint=last, message=message)
