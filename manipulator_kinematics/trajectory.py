"""Trajectories shared by the machines (numpy only, no rclpy).

* :func:`quintic`: a quintic polynomial joint trajectory with zero boundary accelerations and
  given (default zero) boundary velocities, the same polynomial as Robotics Toolbox's ``jtraj``
  (the tool changer's paper uses it with zero velocities, tf = 30 s).
* :func:`straight_line`: points along a straight Cartesian segment at a given step, as the
  pump-boom paper interpolates its pours: N = ceil(L / step), p_i = p0 + i (p1 - p0) / N.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class JointTrajectory:
    """Samples of a joint trajectory: ``t`` (M,) in s; ``q``, ``qd``, ``qdd`` (M, n)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


def quintic(
    q0: ArrayLike,
    qf: ArrayLike,
    t: ArrayLike,
    duration: float | None = None,
    qd0: ArrayLike | None = None,
    qdf: ArrayLike | None = None,
) -> JointTrajectory:
    """Quintic q(t) from ``q0`` at t = 0 to ``qf`` at t = ``duration`` (default: max(t)).

    With tau = t / T and Delta = qf - q0 (jtraj's coefficients):
        q(tau) = A tau^5 + B tau^4 + C tau^3 + qd0 T tau + q0,
        A = 6 Delta - 3 (qd0 + qdf) T,  B = -15 Delta + (8 qd0 + 7 qdf) T,  C = 10 Delta - (6 qd0 + 4 qdf) T,
    so q, qd match the boundary values and qdd(0) = qdd(T) = 0. With zero boundary velocities the
    velocity peaks at T / 2 with 15/8 Delta / T and the acceleration peaks at
    tau = 1/2 -+ sqrt(3)/6 with 10 sqrt(3)/3 Delta / T^2.

    ``t`` is any 1-D array of times in [0, T]; joint arrays have n entries. Times outside [0, T]
    raise ValueError (the polynomial is not a hold).
    """
    q0 = np.atleast_1d(np.asarray(q0, dtype=float))
    qf = np.atleast_1d(np.asarray(qf, dtype=float))
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if q0.shape != qf.shape or q0.ndim != 1:
        raise ValueError(f"q0 and qf must be 1-D of equal length, got {q0.shape} and {qf.shape}")
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)):
        raise ValueError("t must be a non-empty 1-D array of finite times")
    T = float(np.max(t)) if duration is None else float(duration)
    if not T > 0.0:
        raise ValueError(f"duration must be > 0, got {T}")
    if np.any(t < 0.0) or np.any(t > T):
        raise ValueError(f"times must lie in [0, {T}] s")
    v0 = np.zeros_like(q0) if qd0 is None else np.broadcast_to(np.asarray(qd0, dtype=float), q0.shape)
    v1 = np.zeros_like(q0) if qdf is None else np.broadcast_to(np.asarray(qdf, dtype=float), q0.shape)
    delta = qf - q0
    a = 6.0 * delta - 3.0 * (v0 + v1) * T
    b = -15.0 * delta + (8.0 * v0 + 7.0 * v1) * T
    c = 10.0 * delta - (6.0 * v0 + 4.0 * v1) * T
    e = v0 * T
    tau = (t / T)[:, None]
    q = (((a * tau + b) * tau + c) * tau * tau + e) * tau + q0
    qd = ((((5.0 * a * tau + 4.0 * b) * tau + 3.0 * c) * tau * tau) + e) / T
    qdd = ((20.0 * a * tau + 12.0 * b) * tau + 6.0 * c) * tau / (T * T)
    return JointTrajectory(t=t, q=q, qd=qd, qdd=qdd)


def straight_line(p0: ArrayLike, p1: ArrayLike, step: float) -> np.ndarray:
    """Points (N + 1, d) from ``p0`` to ``p1`` inclusive, N = ceil(L / step), equally spaced.

    The spacing L / N is at most ``step``; a length within round-off of a whole number of steps
    takes that number (1.1 m at 0.1 m gives 11 steps, not 12). p0 == p1 gives the single point.
    """
    p0 = np.asarray(p0, dtype=float)
    p1 = np.asarray(p1, dtype=float)
    if p0.shape != p1.shape or p0.ndim != 1:
        raise ValueError(f"p0 and p1 must be 1-D of equal length, got {p0.shape} and {p1.shape}")
    if not (np.isfinite(step) and step > 0.0):
        raise ValueError(f"step must be > 0, got {step}")
    if not (np.all(np.isfinite(p0)) and np.all(np.isfinite(p1))):
        raise ValueError("end points must be finite")
    length = float(np.linalg.norm(p1 - p0))
    steps = int(np.ceil(length / step * (1.0 - 1e-12)))
    if steps == 0:
        return p0[None, :].copy()
    i = np.arange(steps + 1)[:, None]
    return p0 + i * (p1 - p0) / steps
