"""Straight bucket-tip lines through waypoints at a constant bucket angle, timed within the
actuators' speed limits (numpy only): the excavator's ``plan_path``.

1. The bucket angle alpha of the whole path: the seed's (its pose, the seed moved into the limits
   first), else that of the first waypoint's solution (position only: the widest stroke margin,
   :mod:`excavator_kinematics.core.inverse`).
2. The first waypoint is solved at that angle (selected by the seed, else the first valid branch);
   the shared walk (:func:`manipulator_kinematics.tool_path.walk_lines`) samples each straight
   line every ``step`` and this module solves every sample on the same branch, so D is continuous
   along the path; a sample that is not solvable, or whose swing jumps by more than
   :data:`MAX_SWING_STEP` (the line passes the swing axis), ends the path at the farthest
   reachable point of that line, with the reason and the last waypoint reached in full.
3. The samples are timed by the shared walk: no actuator above its max speed, the tip not above
   ``tip_speed``, the tip's acceleration along the path at most ``acceleration``, at rest at both
   ends and at every corner; slowed only where a limit binds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from excavator_kinematics.core.inverse import BRANCHES, seed_bucket_angle
from manipulator_kinematics.plan_bounds import MAX_POINTS, check_plan  # noqa: F401 - MAX_POINTS re-exported
from manipulator_kinematics.tool_path import END_TOLERANCE, ToolPlan, show, walk_lines  # noqa: F401 - END_TOLERANCE re-exported

if TYPE_CHECKING:
    from excavator_kinematics.core.kinematics import Excavator

#: A swing change between neighbouring samples above this (rad) is a line passing the swing axis:
#: the machine would have to turn on the spot, the path ends before it.
MAX_SWING_STEP = 0.5


@dataclass(frozen=True)
class BucketPlan(ToolPlan):
    """A planned path (:class:`manipulator_kinematics.tool_path.ToolPlan`, ``timing.q`` (M, 4))
    and ``alpha``, the bucket angle held along it (rad)."""

    alpha: float


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
            None,
            True,
            -1,
            f"the first waypoint {show(waypoints[0])} is not reachable: {first.note()}",
            alpha,
        )
    branch = BRANCHES[int(first.selected)]
    plan = walk_lines(
        waypoints,
        first.solution,
        step,
        lambda line, previous: _solve_line(exc, line, alpha, branch, previous),
        exc.limits.max_rates,
        exc.joint_names,
        tip_speed,
        acceleration,
        f", bucket angle {np.degrees(alpha):.6g} deg",
    )
    return BucketPlan(plan.points, plan.timing, plan.truncated, plan.last_waypoint, plan.message, alpha)


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
