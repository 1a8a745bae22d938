"""Safe actuator rate commands for a bucket velocity: inverse velocity kinematics (paper eq. 9)
that keeps the commanded direction. Numpy only, no ROS; the velocity IK node wires it.

The rule (docs/excavator_nodes.md, "The direction rule at stroke ends"): a command the machine
cannot follow is slowed or stopped in its own direction, never bent into another one. So the
ideal rates D_dot = JC0^-1 Q_dot are scaled as a whole by ONE factor in [0, 1], the smallest of:

1. Near a singularity (cond(JC0) above ``condition_threshold``): the factor that brings the exact
   solution down to the size of the damped least-squares one (:func:`damped_inverse`: lambda^2
   added to every sigma^2 with lambda = (sigma_max / threshold) (1 - threshold / cond), zero at
   the threshold). Damped least squares alone bends the bucket's direction (it shrinks each
   singular direction by its own gain); its size is used, its direction is not. Where JC0 cannot
   give Q_dot's direction at all (Q_dot outside its range) the factor is 0.
2. Stroke ends and swing limit: no actuator may reach its end sooner than ``stroke_horizon`` s
   (min over the actuators moving outwards of room / (|d_dot| horizon)), so all actuators slow
   together, the tip slows along its line and stops there; within END_ZONE of an end the room is
   0: stopped. An actuator beyond an end may move back, never further out.
3. Speed limits: every actuator within its maximum speed. The limits hold exactly, not to an ulp:
   |D_dot_i| <= max_rates_i in floating point (the product is clipped, see :func:`scale_to_speed`).

The achieved bucket rate JC0 D_dot is then that factor times Q_dot (to round-off).
:func:`toward_line` gives the node's correction toward a constant target's line (added to Q_dot).

Optional secondary task (``bucket_angle_gives_way``): where a stroke end sets the factor, the tip's
linear velocity keeps its direction and the bucket angle rate gives way. Every D_dot = c x + tau n
(x the full solution, n the null vector of JC0's three linear rows) moves the tip at c times the
target velocity; the largest c within the speed and stroke bounds is a two-variable linear
program (scipy's HiGHS), and among its solutions the one nearest tau = 0 (the bucket angle rate
as commanded) is taken; below GIVE_WAY_MIN_SCALE of the target speed it does not give way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# At the top, not where the secondary task first needs it: importing scipy.optimize takes 0.5-1.6 s,
# and a node that stalls that long the first time a stroke end limits leaves the machine coasting
# on its last command (measured: the tip 30 cm off its line across processes).
from scipy.optimize import linprog

from excavator_kinematics.core.machine_file import Limits

#: Within this distance of an end (m for a cylinder, rad for the swing) an actuator is at it: the
#: exponential approach of the stroke horizon would otherwise take forever to get there.
END_ZONE = 1e-4
#: The secondary task gives way only while it keeps the tip at this part of the target speed or
#: more. Below it the actuators would run at full speed to creep the tip on (near the edge of the
#: working range the linear task is nearly singular once an actuator is at its end), and the bucket
#: turning at full speed about a creeping tip bends the path within each control period
#: (measured: 3 cm of drift in 15 s at 0.001 of a 2 m/s target); the bucket stops instead.
GIVE_WAY_MIN_SCALE = 0.05
#: Q_dot counts as outside the range of a singular JC0 when the least-squares solution misses it
#: by more than this part of |Q_dot|.
RANGE_TOLERANCE = 1e-6

# What set the factor (RateCommand.limit).
SPEED, STROKE, SINGULAR = "speed limit", "stroke end", "singular"


@dataclass(frozen=True)
class RateCommand:
    """A rate command and how it was obtained."""

    d_dot: np.ndarray  # (4,) [theta1_dot, d2_dot, d3_dot, d4_dot] to command
    condition: float  # condition number of JC0 at the state
    damping: float  # lambda of the damped least squares, 0 where the inverse is exact
    clamped: np.ndarray  # (4,) bool: actuator whose stroke end slows the command
    speed_scale: float  # factor the speed limits alone need, 1 = none
    scale: float  # the one factor applied to the target: achieved tip velocity = scale x target
    limit: str | None  # what set ``scale`` when below 1: SPEED, STROKE or SINGULAR
    actuator: int | None  # index in D of the actuator that set it (SPEED, STROKE)
    gives_way: bool = False  # the bucket angle rate gave way (secondary task)


def damped_inverse(
    jc0: np.ndarray, q_dot: np.ndarray, condition_threshold: float
) -> tuple[np.ndarray, float, float]:
    """D_dot solving JC0 D_dot = Q_dot (eq. 9), damped above ``condition_threshold``.

    Returns (D_dot, condition number, lambda).
    """
    u, sigma, vt = np.linalg.svd(jc0)
    condition = float(sigma[0] / sigma[-1]) if sigma[-1] > 0.0 else float("inf")
    damping = 0.0
    if condition > condition_threshold:
        damping = float(sigma[0] / condition_threshold * (1.0 - condition_threshold / condition))
    gains = sigma / (sigma * sigma + damping * damping)
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported by rate_command
        return vt.T @ (gains * (u.T @ q_dot)), condition, damping


def stroke_room(d: np.ndarray, d_dot: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Distance (>= 0) each actuator may still move in the direction of its rate; 0 within END_ZONE
    of that end or beyond it, inf for an unlimited axis or a rate of 0."""
    with np.errstate(invalid="ignore"):  # inf - inf of an unlimited axis
        room = np.where(d_dot > 0.0, upper - d, np.where(d_dot < 0.0, d - lower, np.inf))
    room = np.where(np.isnan(room), np.inf, room)
    return np.where(room < END_ZONE, 0.0, room)


def stroke_scale(
    d: np.ndarray, d_dot: np.ndarray, lower: np.ndarray, upper: np.ndarray, horizon: float
) -> tuple[float, np.ndarray]:
    """The factor in [0, 1] after which no actuator reaches its end within ``horizon`` s, and the
    mask of the actuators that need one below 1."""
    room = stroke_room(d, d_dot, lower, upper)
    with np.errstate(divide="ignore", invalid="ignore"):
        factors = np.where(d_dot != 0.0, room / (np.abs(d_dot) * horizon), np.inf)
    factors = np.where(np.isnan(factors), 0.0, factors)  # inf room / inf rate: cannot happen finitely
    return float(min(1.0, factors.min())), factors < 1.0


def scale_to_speed(d_dot: np.ndarray, max_speed: np.ndarray) -> tuple[np.ndarray, float]:
    """Uniformly scaled rates within ``max_speed`` (direction kept) and the factor used.

    The limit holds exactly: ``d_dot * (1 / ratio)`` rounds up to an ulp above ``max_speed`` for
    the fastest actuator (1 in 25 random commands), so the product is clipped to the limits
    afterwards; that moves a rate by at most an ulp, the direction is kept to round-off.
    """
    ratio = float(np.max(np.abs(d_dot) / max_speed))
    if not ratio > 1.0:
        return d_dot, 1.0
    scale = 1.0 / ratio
    return np.clip(d_dot * scale, -max_speed, max_speed), scale


def ideal_rates(
    jc0: np.ndarray, q_dot: np.ndarray, condition_threshold: float
) -> tuple[np.ndarray, float, float, float]:
    """(D_dot with JC0 D_dot = Q_dot, condition, lambda, factor near a singularity) (item 1)."""
    d_dot, condition, damping = damped_inverse(jc0, q_dot, condition_threshold)
    if damping == 0.0:
        return d_dot, condition, damping, 1.0
    exact = np.linalg.lstsq(jc0, q_dot, rcond=None)[0]
    size = float(np.linalg.norm(q_dot))
    if not (np.all(np.isfinite(exact)) and np.linalg.norm(jc0 @ exact - q_dot) <= RANGE_TOLERANCE * size):
        return np.zeros(4), condition, damping, 0.0  # no rates give this direction here
    wanted = float(np.linalg.norm(exact))
    factor = min(1.0, float(np.linalg.norm(d_dot)) / wanted) if wanted > 0.0 else 1.0
    return exact, condition, damping, factor


def _linear_task(
    jc0: np.ndarray, x: np.ndarray, d: np.ndarray, limits: Limits, horizon: float, ceiling: float
) -> tuple[float, np.ndarray] | None:
    """The secondary task: (c, D_dot = c x + tau n) with the largest tip speed factor c <= ceiling
    within the speed limits and the stroke horizon, tau nearest 0; None if it finds none."""
    n = np.linalg.svd(jc0[:3])[2][-1]  # JC0[:3] n = 0: the tip stands, only the bucket turns
    max_rates = limits.max_rates
    upper = np.minimum(max_rates, stroke_room(d, np.ones(4), limits.d_min, limits.d_max) / horizon)
    lower = -np.minimum(max_rates, stroke_room(d, -np.ones(4), limits.d_min, limits.d_max) / horizon)
    basis = np.column_stack((x, n))  # D_dot = basis @ [c, tau]
    result = linprog(
        [-1.0, 0.0],
        A_ub=np.vstack((basis, -basis)),
        b_ub=np.r_[upper, -lower],
        bounds=[(0.0, ceiling), (None, None)],
        method="highs",
    )
    if result.status != 0:
        return None
    c = float(result.x[0]) * (1.0 - 1e-9)  # strictly inside, so the tau interval below is not empty
    with np.errstate(divide="ignore", invalid="ignore"):
        ends = np.stack(((lower - c * x) / n, (upper - c * x) / n))
    moving = np.abs(n) > 1e-12
    low = float(np.max(np.min(ends, axis=0)[moving], initial=-np.inf))
    high = float(np.min(np.max(ends, axis=0)[moving], initial=np.inf))
    if not low <= high:
        return None
    return c, np.clip(c * x + np.clip(0.0, low, high) * n, lower, upper)


def rate_command(
    jc0: np.ndarray,
    d: np.ndarray,
    q_dot: np.ndarray,
    limits: Limits,
    condition_threshold: float,
    stroke_horizon: float,
    bucket_angle_gives_way: bool = False,
) -> RateCommand:
    """Safe D_dot for the bucket rates Q_dot at state D (see the module docstring for the steps).

    Raises ValueError when a (finite) target is so large that eq. 9 overflows.
    """
    x, condition, damping, singular = ideal_rates(jc0, q_dot, condition_threshold)
    if not np.all(np.isfinite(x)):  # a finite but absurd target (1e308 m/s) overflows in eq. 9
        raise ValueError(f"target {np.asarray(q_dot).tolist()} too large: the rates overflow")
    stroke, clamped = stroke_scale(d, x, limits.d_min, limits.d_max, stroke_horizon)
    with np.errstate(over="ignore", divide="ignore"):
        speed_factors = limits.max_rates / np.abs(x)
    speed = float(min(1.0, speed_factors.min()))
    scale = min(singular, stroke, speed)
    limit, actuator = None, None
    if scale < 1.0:
        limit = SINGULAR if scale == singular else STROKE if scale == stroke else SPEED
        if limit == STROKE:
            room = stroke_room(d, x, limits.d_min, limits.d_max)
            actuator = int(np.argmin(np.where(x != 0.0, room / np.abs(x), np.inf)))
        elif limit == SPEED:
            actuator = int(np.argmin(speed_factors))
    if limit == STROKE and bucket_angle_gives_way:
        task = _linear_task(jc0, x, d, limits, stroke_horizon, min(singular, speed, 1.0))
        if task is not None and task[0] > scale and task[0] >= GIVE_WAY_MIN_SCALE:
            c, d_dot = task
            gives_way = not np.allclose(d_dot, c * x, rtol=0.0, atol=1e-12)
            return RateCommand(
                np.clip(d_dot, -limits.max_rates, limits.max_rates),
                condition,
                damping,
                clamped,
                speed,
                c,
                limit if c < 1.0 else None,
                actuator,
                gives_way,
            )
    d_dot = np.clip(x * scale, -limits.max_rates, limits.max_rates) if scale < 1.0 else x
    return RateCommand(d_dot, condition, damping, clamped, speed, scale, limit, actuator)


#: Farther than this from its line (m, or rad for the bucket angle) the bucket did not drift: it
#: was moved (or the state jumped); the correction toward the line is not for that, a new line begins.
LINE_RESTART = 0.05


def toward_line(
    start: np.ndarray, q_dot: np.ndarray, Q: np.ndarray, gain: float, hold_angle: bool = True
) -> np.ndarray | None:
    """Bucket rates (4,) that bring the bucket at Q back onto the commanded line: ``gain`` (1/s)
    times the way back from Q to the line Q0 + t q_dot (t >= 0) that ``start`` = Q0 began; None
    when the way back is longer than LINE_RESTART (begin a new line at Q instead).

    Each command is tangent to the line at the state it is computed for; the machine then moves
    for a control period (longer when a process stalls) on rates that are constant in D, not in
    Q, and the small offsets add up along the path (up to 12 mm in one process, 3 to 9 cm across
    processes on a machine at load 7). Added to the target, this returns the tip to its line:
    the across-line part of the tip's offset, and unless ``hold_angle`` is false (the bucket angle
    gives way) the bucket angle's offset from the angle the target gives at this progress. A
    target without linear velocity has no line: no correction.
    """
    v = q_dot[:3]
    speed = float(np.linalg.norm(v))
    if speed == 0.0:
        return np.zeros(4)
    u = v / speed
    offset = Q[:3] - start[:3]
    progress = float(offset @ u)
    across = offset - progress * u
    angle = Q[3] - (start[3] + q_dot[3] * max(progress, 0.0) / speed) if hold_angle else 0.0
    if not (np.linalg.norm(across) <= LINE_RESTART and abs(angle) <= LINE_RESTART):
        return None
    return -gain * np.r_[across, angle]


#: States of a command (the status output): followed as commanded, slowed in its direction, stopped.
TRACKING, SLOWED, STOPPED = "tracking", "slowed", "stopped"


def describe(command: RateCommand, actuators: tuple[str, ...]) -> tuple[str, str]:
    """(state, sentence) of a command for the status output and the log, e.g. ("stopped",
    "stopped: arm_cylinder at its stroke end, the target direction cannot be continued")."""
    name = actuators[command.actuator] if command.actuator is not None else ""
    way = ", the bucket angle gives way" if command.gives_way else ""
    if command.scale >= 1.0:
        return TRACKING, TRACKING + (f": {name} near its stroke end{way}" if way else "")
    if command.scale > 0.0:
        why = {
            SPEED: f"speed limit of {name}",
            STROKE: f"stroke end of {name} ahead",
            SINGULAR: "JC0 near singular",
        }[command.limit]
        return SLOWED, f"{SLOWED}: {why}{way}"
    why = (
        "JC0 singular: the target direction is not achievable here"
        if command.limit == SINGULAR
        else f"{name} at its stroke end, the target direction cannot be continued"
    )
    return STOPPED, f"{STOPPED}: {why}"
