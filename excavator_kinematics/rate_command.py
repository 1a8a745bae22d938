"""Safe actuator rate commands for a bucket velocity: inverse velocity kinematics (paper eq. 9)
with damped least squares near singularities, stroke-end clamping and uniform speed scaling.

Numpy only, no ROS; the velocity IK node wires it. The order of the safety steps matters:

1. D_dot = JC0^+ Q_dot (eq. 9). JC0 is inverted through its SVD; while its condition number
   sigma_max / sigma_min stays at or below ``condition_threshold`` the inverse is exact, above it
   damped least squares adds lambda^2 to every sigma^2 with
   lambda = (sigma_max / condition_threshold) * (1 - condition_threshold / condition),
   which is zero at the threshold (no jump) and tends to sigma_max / condition_threshold, so the
   largest gain 1 / (2 lambda) stays of the order of the gain at the threshold. JC0 mixes units
   (rows m/s and rad/s, columns rad/s and m/s), so its condition number is the one of the SI
   matrix as the core returns it.
2. Stroke ends: an actuator may not be commanded past its end, and it is slowed so that holding the
   command for ``stroke_horizon`` seconds would just reach the end (exponential approach). Per
   actuator, because a stroke end stops that actuator only.
3. Speed limits: the whole vector is scaled by one factor so that every actuator is within its
   maximum speed and the bucket keeps its direction (scaling after the clamp, so an actuator that
   the clamp already stopped does not slow the others down). The limits hold exactly, not to
   an ulp: |D_dot_i| <= max_rates_i in floating point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from excavator_kinematics.parameters import Limits


@dataclass(frozen=True)
class RateCommand:
    """A rate command and how it was obtained."""

    d_dot: np.ndarray  # (4,) [theta1_dot, d2_dot, d3_dot, d4_dot] to command
    condition: float  # condition number of JC0 at the state
    damping: float  # lambda of the damped least squares, 0 where the inverse is exact
    clamped: np.ndarray  # (4,) bool: actuator slowed or stopped by its stroke end
    speed_scale: float  # factor applied for the speed limits, 1 = none


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


def clamp_to_stroke(
    d: np.ndarray, d_dot: np.ndarray, lower: np.ndarray, upper: np.ndarray, horizon: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rates that do not drive past a stroke end within ``horizon`` s; (rates, clamped mask).

    An actuator already beyond an end may move back inside but never further out.
    """
    with np.errstate(invalid="ignore"):  # inf - inf of an unlimited axis
        most = np.maximum((upper - d) / horizon, 0.0)
        least = np.minimum((lower - d) / horizon, 0.0)
    most = np.where(np.isfinite(upper), most, np.inf)
    least = np.where(np.isfinite(lower), least, -np.inf)
    clamped_rates = np.clip(d_dot, least, most)
    return clamped_rates, clamped_rates != d_dot


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


def rate_command(
    jc0: np.ndarray,
    d: np.ndarray,
    q_dot: np.ndarray,
    limits: Limits,
    condition_threshold: float,
    stroke_horizon: float,
) -> RateCommand:
    """Safe D_dot for the bucket rates Q_dot at state D (see the module docstring for the steps).

    Raises ValueError when a (finite) target is so large that eq. 9 overflows.
    """
    d_dot, condition, damping = damped_inverse(jc0, q_dot, condition_threshold)
    if not np.all(np.isfinite(d_dot)):  # a finite but absurd target (1e308 m/s) overflows in eq. 9
        raise ValueError(f"target {np.asarray(q_dot).tolist()} too large: the rates overflow")
    d_dot, clamped = clamp_to_stroke(d, d_dot, limits.d_min, limits.d_max, stroke_horizon)
    d_dot, scale = scale_to_speed(d_dot, limits.max_rates)
    return RateCommand(d_dot, condition, damping, clamped, scale)
