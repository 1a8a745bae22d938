"""``plan_path`` kept out of avoidance zones (docs/zones.md): the path of
:func:`excavator_kinematics.core.path.plan_path`, its monitored points
(:class:`excavator_kinematics.core.monitored.MonitoredPoints`) checked at every sample (``step``
apart along the tip's path); where a point would enter a zone the path ends at the sample before,
planned again through the waypoints reached so it comes to rest there, with the reason. A path
whose first sample is already inside a zone is refused (no trajectory): the velocity IK moves a
machine out of a zone, a plan does not start in one. Numpy only.

Between samples a point moves by about ``step`` at the tip's scale: the zones' margins are what
covers that (a margin of at least the step keeps the machine out of the zone itself).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.core.path import BucketPlan, plan_path
from manipulator_kinematics.zone_guard import first_entry
from manipulator_kinematics.zones import Zone


def _show(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ") m"


def plan_clear(
    exc: Excavator,
    points: MonitoredPoints,
    zones: Sequence[Zone],
    waypoints: ArrayLike,
    step: float,
    tip_speed: float,
    acceleration: float,
    seed: ArrayLike | None = None,
    site: tuple[np.ndarray, np.ndarray] | None = None,
) -> BucketPlan:
    """:func:`plan_path` ended before the first zone a monitored point would enter (module
    docstring); the plan as it is when none would. ``site`` = (R, t), base_link in the site frame
    (p_site = R p + t), places site-frame zones (ValueError when one is given without it)."""
    waypoints = np.asarray(waypoints, dtype=float).reshape(-1, 3)
    plan = plan_path(exc, waypoints, step, tip_speed, acceleration, seed)
    if plan.timing is None or not zones:
        return plan
    hit = first_entry(zones, points.names, points.positions(plan.timing.q), site)
    if hit is None:
        return plan
    k, zone, point = hit
    where = f"{point} enters zone {zone} (zones.{zone}) at {_show(plan.points[k])} of the tip's path"
    if k == 0:
        return BucketPlan(
            plan.points[:0], plan.alpha, None, True, -1, f"the path starts inside a zone: {where}"
        )
    end = plan.points[k - 1]
    # The waypoints passed in full before the sample: their arc lengths along the path.
    reached = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))))
    last = int(np.searchsorted(reached, plan.timing.s[k - 1] + 1e-9, side="right")) - 1
    short = plan_path(exc, np.vstack((waypoints[: last + 1], end)), step, tip_speed, acceleration, seed)
    message = f"{where}; the path ends before it at {_show(end)}, after waypoint {last}: {short.message}"
    return BucketPlan(short.points, short.alpha, short.timing, True, last, message)


__all__ = ["plan_clear"]
