"""Straight-line pours and paths of the pump boom (paper 001, section 3, eqs. 5-7). numpy only.

A path is a polyline through waypoints (base frame). Each segment is interpolated as eqs. 5-7:
L = |p1 - p0|, N = ceil(L / step), p_i = p0 + i (p1 - p0) / N (the shared
:func:`manipulator_kinematics.trajectory.straight_line`), and every point is solved by the region
IK. The tip moves at constant speed, so point i is reached at t_i = s_i / v (s_i the path
length up to it).

Section 3.3 step 1: an end point outside the automatic pour workspace is replaced by the
farthest reachable point of the line. Here: the path is followed from the first waypoint while
every interpolated point is solvable; at the first point that is not, the boundary between it and
the previous point is found by bisection (to 1 um) and the path ends there, re-interpolated from
the segment's start. The plan says so (``truncated``, ``message``) and gives the index of the
last waypoint reached in full. theta1 is unwrapped along the path (no jump of 2 pi when the pour
passes behind the truck).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.planar import wrap_angle
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
    """A planned pour: ``points`` (M, 3), ``q`` (M, 6), ``s`` (M,) path length (m), ``t`` (M,) s.

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


#: Most points one plan may have (10^6: 100 km at the default 0.1 m step), so that a request with
#: a tiny step or far waypoints cannot make the planner allocate without bound.
MAX_POINTS = 1_000_000


def plan_path(
    boom: PumpBoom,
    waypoints: ArrayLike,
    step: float | None = None,
    tip_speed: float | None = None,
    seed: ArrayLike | None = None,
) -> PathPlan:
    """Plan a pour through ``waypoints`` (K, 3) (module docstring); ``step`` (m) and ``tip_speed``
    (m/s) default to the machine's; ``seed`` (6,) the current joint state (the slew turn).

    Raises ValueError for a malformed request (no waypoint, not finite, step or speed <= 0), and
    its subclass RegionTableError when the boom's region table was built for another geometry.
    """
    waypoints = np.asarray(waypoints, dtype=float)
    step = boom.pour_step if step is None else float(step)
    speed = boom.tip_speed if tip_speed is None else float(tip_speed)
    if waypoints.ndim != 2 or waypoints.shape[1] != 3 or len(waypoints) == 0:
        raise ValueError(f"waypoints must have shape (K, 3) with K >= 1, got {waypoints.shape}")
    if not np.all(np.isfinite(waypoints)):
        raise ValueError("waypoints must be finite")
    if not (np.isfinite(step) and step > 0.0 and np.isfinite(speed) and speed > 0.0):
        raise ValueError(f"step and tip speed must be > 0, got {step} m and {speed} m/s")
    with np.errstate(over="ignore"):
        count = float(np.sum(np.ceil(np.linalg.norm(np.diff(waypoints, axis=0), axis=1) / step)))
    if not count <= MAX_POINTS:
        raise ValueError(f"the path would have {count:.3g} points at step {step:g} m; at most {MAX_POINTS} "
                         "(a longer step, or fewer or closer waypoints)")
    first = boom.region_ik(waypoints[0], seed)
    if not first.ok:
        return _plan(
            boom,
            np.empty((0, 3)),
            np.empty((0, 6)),
            np.empty(0, bool),
            speed,
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
            points.append(line)
            q.append(solved.q)
            blended.append(solved.blended)
        text = (
            f"waypoint {k} {_show(goal)} cannot be reached along the line from {_show(start)}: {reason}; "
            f"the path ends at the farthest reachable point of the line {_show(end)}"
        )
        return _plan(
            boom, np.vstack(points), np.vstack(q), np.concatenate(blended), speed, True, k - 1, end, text
        )
    pts = np.vstack(points)
    text = f"{len(pts)} points through {len(waypoints)} waypoint(s), step {step:g} m, tip speed {speed:g} m/s"
    return _plan(
        boom, pts, np.vstack(q), np.concatenate(blended), speed, False, len(waypoints) - 1, pts[-1], text
    )


def pour_line(
    boom: PumpBoom,
    start: ArrayLike,
    end: ArrayLike,
    step: float | None = None,
    tip_speed: float | None = None,
    seed: ArrayLike | None = None,
) -> PathPlan:
    """The paper's straight-line pour from ``start`` to ``end`` (section 3.2)."""
    return plan_path(
        boom, np.stack([np.asarray(start, float), np.asarray(end, float)]), step, tip_speed, seed
    )


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
    speed: float,
    truncated: bool,
    last: int,
    end: np.ndarray,
    message: str,
) -> PathPlan:
    if len(q):
        # Unwrap the slew angle along the path: each point's turn follows the previous one.
        q = q.copy()
        q[:, 0] = q[0, 0] + np.concatenate([[0.0], np.cumsum(wrap_angle(np.diff(q[:, 0])))])
    s = (
        np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
        if len(points)
        else np.empty(0)
    )
    return PathPlan(
        points=points,
        q=q,
        s=s,
        t=s / speed,
        ok=len(points) > 0,
        truncated=truncated,
        last_waypoint=last,
        end=np.asarray(end, dtype=float),
        message=message,
        blended=blended,
    )


def _show(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ") m"
