"""``plan_path`` kept out of avoidance zones (docs/zones.md): the path of
:func:`excavator_kinematics.core.path.plan_path`, its monitored points
(:class:`excavator_kinematics.core.monitored.MonitoredPoints`) checked at every sample by the
shared :func:`manipulator_kinematics.tool_path.clear_of_zones` (``step``
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
from manipulator_kinematics.tool_path import clear_of_zones
from manipulator_kinematics.zones import Zone


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
    return clear_of_zones(
        lambda through: plan_path(exc, through, step, tip_speed, acceleration, seed),
        np.asarray(waypoints, dtype=float).reshape(-1, 3),
        zones,
        points.names,
        points.positions,
        site,
    )


__all__ = ["plan_clear"]
