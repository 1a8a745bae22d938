"""Rate commands that keep their direction, and simulated actuators, for any family machine.
Numpy only; the family's velocity IK and simulator nodes wire them
(:mod:`manipulator_kinematics.nodes.hydraulic`).

The rule of the house (excavator_kinematics.core.rate_command, docs/excavator_nodes.md "The direction
rule at stroke ends"), for any number of actuators m and commanded task rows k: a command the
machine cannot follow is slowed or stopped in its own direction, never bent. The rates solve
JC0[rows] D_dot = Q_dot[rows] (paper eq. 9) in actuator-speed units (D_dot = S u, S =
diag(max_speed)): exactly where k = m; where k < m (the crane: x, y, z with four actuators) the
smallest ||u|| of the exact solutions, so every actuator shares the motion by its speed. Then ONE
factor in [0, 1] scales them all, the smallest of: near a singularity (cond above
``condition_threshold``) the size of the damped least-squares solution over the exact one's (0
where Q_dot is outside the range of JC0[rows]); the stroke ends (no actuator reaches its end
sooner than ``stroke_horizon``; within END_ZONE of it: stopped); the speed limits. So the commanded
rows move at ``scale`` x Q_dot[rows]; the rows not commanded (the loader's reach) follow as they must.
:func:`toward_line` gives the node's correction toward a constant target's line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manipulator_kinematics.param_files import ConfigError

__all__ = [
    "END_ZONE",
    "LINE_RESTART",
    "Plant",
    "RateCommand",
    "describe",
    "rate_command",
    "task_rates",
    "toward_line",
]

#: Within this distance of an end (m, rad) an actuator is at it (the stroke horizon's exponential
#: approach would never get there).
END_ZONE = 1e-4
#: Q_dot counts as outside the range of JC0[rows] when the least-squares rates miss it by more than
#: this part of |Q_dot|.
RANGE_TOLERANCE = 1e-6
SPEED, STROKE, SINGULAR = "speed limit", "stroke end", "singular"
TRACKING, SLOWED, STOPPED = "tracking", "slowed", "stopped"


@dataclass(frozen=True)
class RateCommand:
    """A rate command (m,) and how it was obtained."""

    d_dot: np.ndarray
    condition: float  # of JC0[rows] S
    damping: float  # lambda of the damped least squares whose size was used, 0 if none
    scale: float  # achieved commanded task rates = scale x target
    limit: str | None  # what set scale below 1: SPEED, STROKE or SINGULAR
    actuator: int | None  # the actuator that set it (SPEED, STROKE)


def _room(d: np.ndarray, d_dot: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Distance each actuator may still move in its rate's direction (0 near or beyond that end)."""
    room = np.where(d_dot > 0.0, upper - d, np.where(d_dot < 0.0, d - lower, np.inf))
    return np.where(room < END_ZONE, 0.0, room)


def rate_command(
    jc0_rows: np.ndarray,
    d: np.ndarray,
    q_dot: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    max_speed: np.ndarray,
    condition_threshold: float,
    stroke_horizon: float,
) -> RateCommand:
    """Safe D_dot (m,) for the commanded task rates ``q_dot`` (k,) at state ``d`` (module
    docstring); ValueError when a finite target is so large that the rates overflow."""
    A = jc0_rows * max_speed  # columns in actuator-speed units
    u_, sigma, vt = np.linalg.svd(A, full_matrices=False)
    condition = float(sigma[0] / sigma[-1]) if sigma[-1] > 0.0 else float("inf")
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        exact = np.linalg.pinv(A) @ q_dot
        x = exact * max_speed
    if not np.all(np.isfinite(x)):
        raise ValueError(f"target {q_dot.tolist()} too large: the rates overflow")
    size = float(np.linalg.norm(q_dot))
    damping, singular = 0.0, 1.0
    if condition > condition_threshold:
        damping = float(sigma[0] / condition_threshold * (1.0 - condition_threshold / condition))
        damped = vt.T @ (sigma / (sigma * sigma + damping * damping) * (u_.T @ q_dot))
        wanted = float(np.linalg.norm(exact))
        singular = min(1.0, float(np.linalg.norm(damped)) / wanted) if wanted > 0.0 else 1.0
    if size > 0.0 and np.linalg.norm(A @ exact - q_dot) > RANGE_TOLERANCE * size:
        singular = 0.0  # no rates give this direction here
    room = _room(d, x, lower, upper)
    with np.errstate(divide="ignore", invalid="ignore"):
        stroke_factors = np.where(x != 0.0, room / (np.abs(x) * stroke_horizon), np.inf)
        speed_factors = max_speed / np.abs(x)
    stroke = float(min(1.0, stroke_factors.min()))
    speed = float(min(1.0, speed_factors.min()))
    scale = min(singular, stroke, speed)
    limit, actuator = None, None
    if scale < 1.0:
        limit = SINGULAR if scale == singular else STROKE if scale == stroke else SPEED
        if limit != SINGULAR:
            actuator = int(np.argmin(stroke_factors if limit == STROKE else speed_factors))
    # The clip moves a rate by an ulp at most: the speed limits hold exactly, the direction to round-off.
    d_dot = np.clip(x * scale, -max_speed, max_speed)
    return RateCommand(d_dot, condition, damping, scale, limit, actuator)


def task_rates(D: np.ndarray, twist: np.ndarray, swing: bool, has_angle: bool) -> np.ndarray:
    """Q_dot (nq,) of a tool twist [v, omega] (6,) at state D: the linear velocity and, with a tool
    angle, alpha_dot = omega . (sin theta1, -cos theta1, 0) (machine.py: omega of Rz(theta1)
    Ry(-alpha))."""
    rows = list(twist[:3])
    if has_angle:
        t1 = D[0] if swing else 0.0
        rows.append(twist[3] * np.sin(t1) - twist[4] * np.cos(t1))
    return np.array(rows)


#: Farther than this from its line (m, or rad for the tool angle) the tool did not drift: it was
#: moved (or the state jumped); a new line begins there instead of a correction.
LINE_RESTART = 0.05


def toward_line(
    start: np.ndarray, q_dot: np.ndarray, Q: np.ndarray, rows: list[int], gain: float
) -> np.ndarray | None:
    """Task rates (nq,) that bring the tool at Q back onto the commanded line Q0 + t q_dot (t >= 0,
    ``start`` = Q0) on the commanded ``rows``: ``gain`` (1/s) times the way back, the across-line
    part of the linear rows' offset and the tool angle's offset from the angle the target gives at
    this progress (excavator_kinematics.core.rate_command.toward_line, for any rows). None when the way
    back is longer than LINE_RESTART (begin a new line at Q). No linear rate: no line, no correction.

    Each command is tangent to the line at its state and the machine moves a control period on it:
    the small offsets add up along a path; added to the target, this returns the tool to its line."""
    correction = np.zeros_like(Q)
    linear = [r for r in rows if r < 3]
    v = q_dot[linear]
    speed = float(np.linalg.norm(v))
    if speed == 0.0:
        return correction
    u = v / speed
    offset = Q[linear] - start[linear]
    progress = float(offset @ u)
    across = offset - progress * u
    angle = Q[3] - (start[3] + q_dot[3] * max(progress, 0.0) / speed) if 3 in rows else 0.0
    if not (np.linalg.norm(across) <= LINE_RESTART and abs(angle) <= LINE_RESTART):
        return None
    correction[linear] = -gain * across
    if 3 in rows:
        correction[3] = -gain * angle
    return correction


def describe(command: RateCommand, actuators: tuple[str, ...]) -> tuple[str, str]:
    """(state, sentence) of a command for the status output and the log."""
    name = actuators[command.actuator] if command.actuator is not None else ""
    if command.scale >= 1.0:
        return TRACKING, TRACKING
    if command.scale > 0.0:
        why = {
            SPEED: f"speed limit of {name}",
            STROKE: f"stroke end of {name} ahead",
            SINGULAR: "JC0 near singular",
        }
        return SLOWED, f"{SLOWED}: {why[command.limit]}"
    if command.limit == SINGULAR:
        return STOPPED, f"{STOPPED}: JC0 singular: the target direction is not achievable here"
    return STOPPED, f"{STOPPED}: {name} at its stroke end, the target direction cannot be continued"


class Plant:
    """Simulated actuators D (m,) and D_dot: each saturates at its speed, follows the command with
    a first-order lag ``time_constant`` (0 = ideal; integrated exactly over a held step) and stops
    at its stroke end (excavator_kinematics.core.plant, for any machine of the family)."""

    def __init__(
        self,
        lower: np.ndarray,
        upper: np.ndarray,
        max_speed: np.ndarray,
        d0: np.ndarray,
        time_constant: float,
    ) -> None:
        self.lower, self.upper, self.max_speed = (
            np.asarray(a, dtype=float) for a in (lower, upper, max_speed)
        )
        d0 = np.asarray(d0, dtype=float)
        if d0.shape != self.lower.shape or not np.all(np.isfinite(d0)):
            raise ConfigError(f"start state must be {self.lower.size} finite numbers, got {d0.tolist()}")
        if np.any(d0 < self.lower) or np.any(d0 > self.upper):
            raise ConfigError(
                f"start state {d0.tolist()} outside the strokes "
                f"[{self.lower.tolist()}, {self.upper.tolist()}]"
            )
        if not time_constant >= 0.0:
            raise ConfigError(f"time_constant must be >= 0, got {time_constant}")
        self.time_constant = float(time_constant)
        self.d = d0.copy()
        self.d_dot = np.zeros_like(d0)

    def step(self, command: np.ndarray, dt: float) -> None:
        """Advance by ``dt`` s holding the rates ``command``; ValueError if not finite."""
        command = np.asarray(command, dtype=float)
        if command.shape != self.d.shape or not np.all(np.isfinite(command)) or not np.isfinite(dt):
            raise ValueError(
                f"plant step needs {self.d.size} finite rates and a finite dt, got {command!r}, {dt!r}"
            )
        if dt <= 0.0:
            return
        target = np.clip(command, -self.max_speed, self.max_speed)
        if self.time_constant > 0.0:
            decay = np.exp(-dt / self.time_constant)
            travel = target * dt + (self.d_dot - target) * self.time_constant * (1.0 - decay)
            d_dot = target + (self.d_dot - target) * decay
        else:
            travel, d_dot = target * dt, target
        d = self.d + travel
        stopped = (d <= self.lower) & (d_dot <= 0.0) | (d >= self.upper) & (d_dot >= 0.0)
        self.d = np.clip(d, self.lower, self.upper)
        self.d_dot = np.where(stopped, 0.0, np.clip(d_dot, -self.max_speed, self.max_speed))
