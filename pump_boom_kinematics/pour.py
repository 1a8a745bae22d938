"""Straight-line pours and paths of the pump boom (paper 001, section 3, eqs. 5-7). numpy only.

A path is a polyline through waypoints (base frame). Each segment is interpolated as eqs. 5-7:
L = |p1 - p0|, N = ceil(L / step), p_i = p0 + i (p1 - p0) / N (the shared
:func:`manipulator_kinematics.trajectory.straight_line`), and every point is solved by the region
IK. The trajectory is timed by the shared :func:`manipulator_kinematics.time_scaling.time_scale`:
the tip at the asked speed wherever the joints allow it, slower only where a joint would exceed
its speed limit (``PumpBoom.joint_speed``), starting and ending at rest with the tip's acceleration
along the path bounded (``acceleration``); positions, velocities and accelerations of every point.

Section 3.3 step 1: an end point outside the automatic pour workspace is replaced by the
farthest reachable point of the line. Here: the path is followed from the first waypoint while
every interpolated point is solvable; at the first point that is not, the boundary between it and
the previous point is found by bisection (to 1 um) and the path ends there, re-interpolated from
the segment's start. The plan says so (``truncated``, ``message``) and gives the index of the
last waypoint reached in full. theta1 is unwrapped along the path (no jump of 2 pi when the pour
passes behind the truck).

A plan is bounded before any point is solved by the rule of every machine,
:func:`manipulator_kinematics.plan_bounds.check_plan` (waypoints, points, duration, the ranges of
step, speed and acceleration); anything else is a ValueError with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.plan_bounds import (  # noqa: F401 - re-exported: the pump boom's bounds
    ACCELERATION_RANGE,
    MAX_DURATION,
    MAX_POINTS,
    MAX_WAYPOINTS,
    check_plan,
)
from manipulator_kinematics.planar import wrap_angle
from manipulator_kinematics.time_scaling import TimeScaling, time_scale
from manipulator_kinematics.trajectory import straight_line
from pump_boom_kinematics.kinematics import PumpBoom

_C30, _S30 = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
#: The paper's two typical pours (section 3.4, Figs. 9-10) on the default boom: name ->
#: (title, start, end) in the base frame (m).
TYPICAL_POURS = {
    "horizontal_line": (
        "Horizontal line in a vertical plane (θ1 = 30 deg)",
        (16.0 * _C30, 16.0 * _S30, 17.5),
        (35.0 * _C30, 35.0 * _S30, 17.5),
    ),
    "slanted_line": (
        "Slanted line in a horizontal plane (z = 12.5 m)",
        (28.0, -8.0, 12.5),
        (12.0, 16.0, 12.5),
    ),
}

#: Bisection of the reachable end of a line stops when the bracket is shorter than this (m).
END_TOLERANCE = 1e-6


@dataclass(frozen=True)
class PathPlan:
    """A planned pour: ``points`` (M, 3), ``q``, ``qd``, ``qdd`` (M, 6), ``s`` (M,) path length (m),
    ``t`` (M,) s, ``speed`` (M,) tip speed (m/s), ``active`` (M,) what sets it there (a joint
    index, or ``time_scaling.TIP_SPEED`` / ``ACCELERATION``); ``timing`` the whole time scaling
    (None without a point).

    ``ok``: at least the first waypoint is solvable (M >= 1); ``truncated``: the path ends short
    of the last waypoint; ``last_waypoint``: index of the last waypoint reached (-1: none);
    ``end``: where the path ends; ``message``: what happened, in words.
    """

    points: np.ndarray
    q: np.ndarray
    s: np.ndarray
    t: np.ndarray
    ok: bool
    truncated: bool
    last_waypoint: int
    end: np.ndarray
    message: str
    blended: np.ndarray  # (M,) True where a transition band set theta2..theta4
    qd: np.ndarray
    qdd: np.ndarray
    speed: np.ndarray
    active: np.ndarray
    timing: TimeScaling | None


#: Default bound of the tip's acceleration along the path (m/s^2): the node's ``tip_acceleration``.
ACCELERATION = 0.1


def plan_path(
    boom: PumpBoom,
    waypoints: ArrayLike,
    step: float | None = None,
    tip_speed: float | None = None,
    seed: ArrayLike | None = None,
    acceleration: float = ACCELERATION,
) -> PathPlan:
    """Plan a pour through ``waypoints`` (K, 3) (module docstring); ``step`` (m) and ``tip_speed``
    (m/s) default to the machine's; ``seed`` (6,) the current joint state (the slew turn);
    ``acceleration`` (m/s^2) bounds the tip's acceleration along the path.

    Raises ValueError for a request out of the bounds (module docstring), and its subclass
    RegionTableError when the boom's region table was built for another geometry.
    """
    step = boom.pour_step if step is None else float(step)
    speed = boom.tip_speed if tip_speed is None else float(tip_speed)
    waypoints = check_plan(waypoints, step, speed, acceleration)
    first = boom.region_ik(waypoints[0], seed)
    if not first.ok:
        return _plan(
            boom,
            np.empty((0, 3)),
            np.empty((0, 6)),
            np.empty(0, bool),
            (speed, acceleration),
            False,
            -1,
            waypoints[0],
            f"the first waypoint is not reachable: {first.reason()}",
        )
    points, q, blended = [waypoints[:1]], [first.q[None]], [np.array([first.blended])]
    for k in range(1, len(waypoints)):
        start, goal = points[-1][-1], waypoints[k]
        line = straight_line(start, goal, step)[1:]
        if len(line) == 0:
            continue
        solved = boom.region_ik(line, q[-1][-1])
        bad = np.flatnonzero(~solved.ok)
        if len(bad) == 0:
            points.append(line)
            q.append(solved.q)
            blended.append(solved.blended)
            continue
        reason = solved.reason(int(bad[0]))
        end = _farthest(boom, np.vstack([start[None], line])[bad[0]], line[bad[0]], q[-1][-1])
        line = straight_line(start, end, step)[1:]
        if len(line):
            solved = boom.region_ik(line, q[-1][-1])
            # The line spaced anew puts points between the first ones: one may catch the corner of
            # a gap in the table that the first ones stepped over. The path then ends before it.
            reached = len(line) if solved.ok.all() else int(np.argmin(solved.ok))
            if reached < len(line):
                end = line[reached - 1] if reached else start
            points.append(line[:reached])
            q.append(solved.q[:reached])
            blended.append(solved.blended[:reached])
        text = (
            f"waypoint {k} {_show(goal)} cannot be reached along the line from {_show(start)}: {reason}; "
            f"the path ends at the farthest reachable point of the line {_show(end)}"
        )
        return _plan(
            boom,
            np.vstack(points),
            np.vstack(q),
            np.concatenate(blended),
            (speed, acceleration),
            True,
            k - 1,
            end,
            text,
        )
    pts = np.vstack(points)
    text = f"{len(pts)} points through {len(waypoints)} waypoint(s), step {step:g} m"
    return _plan(
        boom,
        pts,
        np.vstack(q),
        np.concatenate(blended),
        (speed, acceleration),
        False,
        len(waypoints) - 1,
        pts[-1],
        text,
    )


def pour_line(
    boom: PumpBoom,
    start: ArrayLike,
    end: ArrayLike,
    step: float | None = None,
    tip_speed: float | None = None,
    seed: ArrayLike | None = None,
    acceleration: float = ACCELERATION,
) -> PathPlan:
    """The paper's straight-line pour from ``start`` to ``end`` (section 3.2)."""
    waypoints = np.stack([np.asarray(start, float), np.asarray(end, float)])
    return plan_path(boom, waypoints, step, tip_speed, seed, acceleration)


def _farthest(boom: PumpBoom, good: np.ndarray, bad: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """The boundary point between a solvable point ``good`` and an unsolvable ``bad`` (bisection)."""
    while np.linalg.norm(bad - good) > END_TOLERANCE:
        middle = 0.5 * (good + bad)
        if boom.region_ik(middle, seed).ok:
            good = middle
        else:
            bad = middle
    return good


def _plan(
    boom: PumpBoom,
    points: np.ndarray,
    q: np.ndarray,
    blended: np.ndarray,
    limits: tuple[float, float],
    truncated: bool,
    last: int,
    end: np.ndarray,
    message: str,
) -> PathPlan:
    """The plan of the solved ``points``, timed within ``limits`` = (tip speed, acceleration)."""
    speed, acceleration = limits
    if not len(q):
        empty = np.empty((0, 6))
        return PathPlan(
            points=points,
            q=q,
            s=np.empty(0),
            t=np.empty(0),
            ok=False,
            truncated=truncated,
            last_waypoint=last,
            end=np.asarray(end, dtype=float),
            message=message,
            blended=blended,
            qd=empty,
            qdd=empty,
            speed=np.empty(0),
            active=np.empty(0, int),
            timing=None,
        )
    # Unwrap the slew angle along the path: each point's turn follows the previous one.
    q = q.copy()
    q[:, 0] = q[0, 0] + np.concatenate([[0.0], np.cumsum(wrap_angle(np.diff(q[:, 0])))])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    timing = time_scale(q, s, boom.joint_speed, speed, acceleration)
    counts = ", ".join(f"{name} {count}" for name, count in timing.limited_by(boom.joint_names).items())
    message = (
        f"{message}; tip speed up to {speed:g} m/s, acceleration {acceleration:g} m/s^2, "
        f"{timing.duration:.4g} s; speed set at (points): {counts}"
    )
    return PathPlan(
        points=points,
        q=q,
        s=s,
        t=timing.t,
        ok=True,
        truncated=truncated,
        last_waypoint=last,
        end=np.asarray(end, dtype=float),
        message=message,
        blended=blended,
        qd=timing.qd,
        qdd=timing.qdd,
        speed=timing.speed,
        active=timing.active,
        timing=timing,
    )


def _show(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ") m"
