"""The cost bound of a path plan, checked before any point is solved: one rule for every machine
that plans (numpy only; the pump boom's pours and the excavator's bucket paths).

A request is refused (ValueError with the reason) with more than :data:`MAX_WAYPOINTS` waypoints,
more than :data:`MAX_POINTS` samples at its step, a step, a tip speed or an acceleration outside
:data:`STEP_RANGE`, :data:`TIP_SPEED_RANGE` or :data:`ACCELERATION_RANGE`, or a duration beyond
:data:`MAX_DURATION` at its tip speed. So the work and the memory of one plan are bounded before
they start (issue 29: 10^6 points took the excavator's server 63.5 s and 1.85 GB, a speed of 1e300
was planned).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

#: Most waypoints of one plan.
MAX_WAYPOINTS = 1_000
#: Most points of one plan (1 km at a 0.1 m step): a request with a tiny step or far waypoints
#: cannot make the planner allocate without bound. The answer's conversion to a C message holds
#: Python's lock for all its points at once (0.63 s for 19,801 points on 2 loaded cores, 0.3 s
#: for half): at this size it holds up the server's other services less than 0.5 s.
MAX_POINTS = 10_000
#: Longest plan (s) at the asked tip speed (the timing can only make it longer): one day.
MAX_DURATION = 86_400.0
#: The interpolation step (m), the tip speed (m/s) and the bound of the tip's acceleration along
#: the path (m/s^2): below 1 mm, 1 mm/s or 1 mm/s^2 is a typo, not a plan; above 10 no machine here.
STEP_RANGE = (1e-3, 10.0)
TIP_SPEED_RANGE = (1e-3, 10.0)
ACCELERATION_RANGE = (1e-3, 10.0)


def check_plan(waypoints: ArrayLike, step: float, speed: float, acceleration: float) -> np.ndarray:
    """The waypoints (K, 3) as floats when a plan through them at ``step``, ``speed`` and
    ``acceleration`` is within the bounds (module docstring); else ValueError with the reason."""
    waypoints = np.asarray(waypoints, dtype=float)
    if waypoints.ndim != 2 or waypoints.shape[1] != 3 or not 1 <= len(waypoints) <= MAX_WAYPOINTS:
        raise ValueError(
            f"waypoints must have shape (K, 3) with 1 <= K <= {MAX_WAYPOINTS}, got {waypoints.shape}"
        )
    if not np.all(np.isfinite(waypoints)):
        raise ValueError("waypoints must be finite")
    bounds = (
        ("step", step, "m", STEP_RANGE),
        ("tip_speed", speed, "m/s", TIP_SPEED_RANGE),
        ("acceleration", acceleration, "m/s^2", ACCELERATION_RANGE),
    )
    for name, value, unit, (low, high) in bounds:
        if not low <= value <= high:  # NaN fails too
            raise ValueError(f"{name} {value:g} {unit} is outside [{low:g}, {high:g}] {unit}")
    with np.errstate(over="ignore", invalid="ignore"):
        lengths = np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
        count = float(np.sum(np.ceil(lengths / step))) + 1.0
        duration = float(np.sum(lengths)) / speed + speed / acceleration
    if not count <= MAX_POINTS:
        raise ValueError(
            f"the path would have {count:.3g} points at step {step:g} m; at most {MAX_POINTS} "
            "(a longer step, or fewer or closer waypoints)"
        )
    if not duration <= MAX_DURATION:
        raise ValueError(
            f"the path would take at least {duration:.3g} s at {speed:g} m/s; at most "
            f"{MAX_DURATION:g} s (a higher tip_speed, or a shorter path)"
        )
    return waypoints
