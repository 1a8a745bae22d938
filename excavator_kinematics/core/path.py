"""Straight bucket-tip lines through waypoints at a constant bucket angle, timed within the
actuators' speed limits (numpy only): the excavator's ``plan_path``.

1. The bucket angle alpha of the whole path: the seed's (its pose, the seed moved into the limits
   first), else that of the first waypoint's solution (position only: the widest stroke margin,
   :mod:`excavator_kinematics.core.inverse`).
2. The first waypoint is solved at that angle (selected by the seed, else the first valid branch);
   each straight line to the next waypoint is sampled every ``step``
   (:func:`manipulator_kinematics.trajectory.straight_line`) and every sample solved on the same
   branch, so D is continuous along the path; a sample that is not solvable, or whose swing jumps
   by more than :data:`MAX_SWING_STEP` (the line passes the swing axis), ends the path at the
   farthest reachable point of that line (bisection to :data:`END_TOLERANCE`), with the reason and
   the last waypoint reached in full.
3. The samples are timed by the shared :func:`manipulator_kinematics.time_scaling.time_scale`:
   no actuator above its max speed, the tip not above ``tip_speed``, the tip's acceleration along
   the path at most ``acceleration``, at rest at both ends and at every corner (a turn at speed
   would take an unbounded acceleration; lines in one direction run on); slowed only where a
   limit binds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from excavator_kinematics.core.inverse import BRANCHES, seed_bucket_angle
from manipulator_kinematics.plan_bounds import MAX_DURATION, MAX_POINTS, check_plan  # noqa: F401 - MAX_POINTS re-exported
from manipulator_kinematics.time_scaling import TimeScaling, time_scale
from manipulator_kinematics.trajectory import straight_line

if TYPE_CHECKING:
    from excavator_kinematics.core.kinematics import Excavator

#: Bisection of the reachable end of a line stops when the bracket is shorter than this (m).
END_TOLERANCE = 1e-6
#: A swing change between neighbouring samples above this (rad) is a line passing the swing axis:
#: the machine would have to turn on the spot, the path ends before it.
MAX_SWING_STEP = 0.5
#: Two lines whose directions differ by less than this (rad) are one stretch, no stop between.
CORNER = 1e-9


@dataclass(frozen=True)
class BucketPlan:
    """A planned path: ``points`` (M, 3) tip positions, ``alpha`` the bucket angle (rad),
    ``timing`` the timed D (``timing.q`` (M, 4), None when not even the first waypoint is
    solvable); ``truncated`` the path ends short of the last waypoint; ``last_waypoint`` the last
    waypoint reached in full (-1: none); ``message`` what happened, in words."""

    points: np.ndarray
    alpha: float
    timing: TimeScaling | None
    truncated: bool
    last_waypoint: int
    message: str

    @property
    def ok(self) -> bool:
        return self.timing is not None


def plan_path(
    exc: Excavator,
    waypoints: ArrayLike,
    step: float,
    tip_speed: float,
    acceleration: float,
    seed: ArrayLike | None = None,
) -> BucketPlan:
    """Plan through ``waypoints`` (K, 3) (module docstring). ValueError for a request beyond the
    bounds of every machine's plan (:func:`manipulator_kinematics.plan_bounds.check_plan`)."""
    waypoints = check_plan(waypoints, step, tip_speed, acceleration)
    if seed is not None:
        alpha = float(seed_bucket_angle(exc, seed))
    else:
        free = exc.position_ik(waypoints[0])
        alpha = float(exc.pose(free.solution)[3]) if bool(free.ok) else 0.0
    first = exc.ik(np.append(waypoints[0], alpha), seed=seed)
    if not bool(first.ok):
        return BucketPlan(
            waypoints[:0],
            alpha,
            None,
            True,
            -1,
            f"the first waypoint {_show(waypoints[0])} is not reachable: {first.note()}",
        )
    branch = BRANCHES[int(first.selected)]
    # Each line from its start (the previous line's end) to its end: points and D.
    lines: list[tuple[np.ndarray, np.ndarray]] = []
    start, previous = waypoints[0], first.solution
    for k in range(1, len(waypoints)):
        goal = waypoints[k]
        line = straight_line(start, goal, step)[1:]
        if len(line) == 0:
            continue
        solved, bad, reason = _solve_line(exc, line, alpha, branch, previous)
        if bad is not None:
            before = start if bad == 0 else line[bad - 1]
            end = _farthest(exc, before, line[bad], alpha, branch, previous if bad == 0 else solved[bad - 1])
            line = straight_line(start, end, step)[1:]
            if len(line):
                lines.append(
                    (
                        np.vstack((start, line)),
                        np.vstack((previous, _solve_line(exc, line, alpha, branch, previous)[0])),
                    )
                )
            text = (
                f"waypoint {k} {_show(goal)} cannot be reached along the line from {_show(start)}: "
                f"{reason}; the path ends at the farthest reachable point of the line {_show(end)}"
            )
            return _timed(exc, lines, first.solution, alpha, tip_speed, acceleration, True, k - 1, text)
        lines.append((np.vstack((start, line)), np.vstack((previous, solved))))
        start, previous = line[-1], solved[-1]
    text = f"through {len(waypoints)} waypoint(s), step {step:g} m, bucket angle {np.degrees(alpha):.6g} deg"
    return _timed(exc, lines, first.solution, alpha, tip_speed, acceleration, False, len(waypoints) - 1, text)


def _solve_line(
    exc: Excavator, line: np.ndarray, alpha: float, branch: str, previous: np.ndarray
) -> tuple[np.ndarray, int | None, str]:
    """D of every sample on ``branch``; the index of the first sample that fails (None: all
    pass) and why."""
    result = exc.ik(np.column_stack((line, np.full(len(line), alpha))), branch=branch)
    D = result.solution
    swing = np.diff(np.concatenate(([previous[0]], D[:, 0])))
    jump = ~(np.abs(swing) <= MAX_SWING_STEP)  # NaN (no solution) counts as a jump too
    failed = ~result.ok | jump
    if not failed.any():
        return D, None, ""
    bad = int(np.argmax(failed))
    if not bool(result.ok[bad]):
        return D, bad, result.note(bad)
    return (
        D,
        bad,
        (
            f"the swing would jump by {np.degrees(abs(swing[bad])):.4g} deg between samples "
            "(the line passes the swing axis)"
        ),
    )


def _farthest(
    exc: Excavator, good: np.ndarray, bad: np.ndarray, alpha: float, branch: str, previous: np.ndarray
) -> np.ndarray:
    """The boundary between a solvable point ``good`` and an unsolvable ``bad`` (bisection)."""
    while np.linalg.norm(bad - good) > END_TOLERANCE:
        middle = 0.5 * (good + bad)
        if _solve_line(exc, middle[None], alpha, branch, previous)[1] is None:
            good = middle
        else:
            bad = middle
    return good


def _timed(
    exc: Excavator,
    lines: list[tuple[np.ndarray, np.ndarray]],
    first: np.ndarray,
    alpha: float,
    tip_speed: float,
    acceleration: float,
    truncated: bool,
    last: int,
    text: str,
) -> BucketPlan:
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
        timings.append(time_scale(D, s, exc.limits.max_rates, tip_speed, acceleration))
    timing = _joined(timings)
    if not timing.duration <= MAX_DURATION:
        raise ValueError(
            f"the path would take {timing.duration:.3g} s; at most {MAX_DURATION:g} s (a higher "
            "tip speed or acceleration, or a shorter path)"
        )
    limited = ", ".join(f"{name} {n}" for name, n in timing.limited_by(exc.joint_names).items())
    message = (
        f"{len(timing.t)} points {text}, tip speed <= {tip_speed:g} m/s, {timing.duration:.4g} s, "
        f"{len(stretches)} stretch(es) from rest to rest; samples set by: {limited}"
    )
    points = np.vstack([stretches[0][0][:1], *(p[1:] for p, _ in stretches)])
    return BucketPlan(points, alpha, timing, truncated, last, message)


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


def _show(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ") m"
