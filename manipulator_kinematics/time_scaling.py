"""Time scaling of a sampled tool-tip path: the fastest timing within the speed and acceleration
limits, at rest at both ends (numpy only). Shared by every machine's ``plan_path``.

The tip follows a geometric path sampled at arc lengths 0 = s_0 < s_1 < ... < s_{N-1} = L (m) with
joint positions q_i (the machine's IK of the samples). :func:`time_scale` finds the tip speed
v(s) >= 0 that takes the path in the least time subject to

* the tip speed limit            v <= v_tip;
* per-joint speed limits         |qd_j| = |q'_j(s)| v <= vmax_j   (q' = dq/ds; inf = no limit);
* the path acceleration bound    |sdd| = |d(v^2)/ds| / 2 <= a     (tip acceleration along the path);
* rest at both ends              v(0) = v(L) = 0.

Discretisation (time-optimal path parameterisation as in TOPP-RA): x = v^2 is linear in s
between samples, so sdd is constant on each segment and the speed limits are enforced at the
samples. With q'_i the second-order finite
difference of the samples (``np.gradient``) and r_ij the largest of |q'_ij| and the chords
|q_{i+-1,j} - q_ij| / h next to it (a controller interpolating the positions follows the chords, and
v is monotone on a segment, so the chords keep the limit between samples too), each sample has a
cap c_i = min(v_tip, min_j vmax_j / r_ij)^2 (c_0 = c_{N-1} = 0: at rest). The fastest feasible
profile is the lower envelope x_i = min_k (c_k + 2 a |s_i - s_k|): the minimum of the forward
pass F_{i+1} = min(c_{i+1}, F_i + 2 a h_i) and the backward pass B_i = min(c_i, B_{i+1} + 2 a h_i)
(every feasible profile lies below both, and their minimum is feasible). Each pass is one
``np.minimum.accumulate``: with S_i = 2 a s_i, F_i = S_i + min_{k <= i} (c_k - S_k), the same
recurrence re-associated, exact in exact arithmetic. In floating point the sums round by about
eps * S_i, so the acceleration bound holds to a relative ~N eps (tested: 1e-9 at N = 10^5);
speeds are clipped to the caps, so the speed limits hold to a few ulps (tested: relative 1e-12).

Times: t_{i+1} = t_i + 2 h_i / (v_i + v_{i+1}) (constant sdd on the segment). Two samples are
one segment from rest to rest: accelerate at a, cruise at the cap if it is reached, brake at a.
Per sample: qd = q' v; sdd = mean of the adjacent segments' accelerations (|sdd| <= a);
qdd = q'' v^2 + q' sdd, q'' the three-point second difference (q''_0 = q''_1, q''_{N-1} = q''_{N-2}).
``active`` says which constraint sets the speed at each sample: :data:`TIP_SPEED`, joint j (>= 0)
at its limit (at the sample or on a chord next to it), or :data:`ACCELERATION` (on an acceleration
or braking curve; the ends at rest).

Why our own and not toppra (kept after ``benchmarks/bench_time_scaling.py``: pump boom pours, the
same samples as toppra's grid, the same limits, the tip bounds given to toppra as a virtual joint
q_s = s with speed limit v_tip and acceleration limit a, its constant-acceleration parametrizer):
the durations agree to 0.25 % (146.43 / 146.38 s at 290 samples, 497.85 / 496.64 s at 1,996,
498.01 / 498.15 s at 19,996), both keep every joint speed and the tip speed at or below the limit,
and ours computes in 0.24 / 1.5 / 10.4 ms against toppra's 10 / 166 / 1,047 ms (40-110x; medians
of 5 rounds, 2 shared cores). It also needs no new dependency (toppra 0.6.10 brings matplotlib)
and bounds the tip speed and the path acceleration directly, where toppra needs the virtual joint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.trajectory import JointTrajectory

#: ``active`` value: the tip speed limit sets the speed.
TIP_SPEED = -1
#: ``active`` value: the acceleration bound sets the speed (accelerating, braking, at rest).
ACCELERATION = -2
#: A sample this close (relative, in v^2) below its cap is at the cap.
CAP_RTOL = 1e-12


@dataclass(frozen=True)
class TimeScaling:
    """A timed path: ``t`` (N,) s; ``q``, ``qd``, ``qdd`` (N, n); ``s`` (N,) arc length (m),
    ``speed`` (N,) tip speed along the path (m/s), ``sdd`` (N,) its acceleration (m/s^2);
    ``active`` (N,) the constraint that sets the speed: :data:`TIP_SPEED`, a joint index, or
    :data:`ACCELERATION`."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    s: np.ndarray
    speed: np.ndarray
    sdd: np.ndarray
    active: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    @property
    def trajectory(self) -> JointTrajectory:
        return JointTrajectory(t=self.t, q=self.q, qd=self.qd, qdd=self.qdd)

    def limited_by(self, names: tuple[str, ...] | list[str]) -> dict[str, int]:
        """How many samples each constraint sets the speed at, by name (joint ``names``, then
        ``tip speed`` and ``acceleration``), only those that do: for a plan's message."""
        labels = {TIP_SPEED: "tip speed", ACCELERATION: "acceleration"} | dict(enumerate(names))
        codes, counts = np.unique(self.active, return_counts=True)
        return {labels[int(code)]: int(count) for code, count in zip(codes, counts)}


def time_scale(
    q: ArrayLike,
    s: ArrayLike,
    joint_speed: ArrayLike,
    tip_speed: float,
    acceleration: float,
) -> TimeScaling:
    """Time the path ``q`` (N, n) sampled at arc lengths ``s`` (N,) (module docstring).

    ``joint_speed`` (n,) per-joint speed limits (> 0, inf = none), ``tip_speed`` (m/s) and
    ``acceleration`` (m/s^2) finite and > 0. Raises ValueError for anything else, and when the
    path's derivative overflows (samples too close for their joint steps).
    """
    q = np.asarray(q, dtype=float)
    s = np.asarray(s, dtype=float)
    vmax = np.asarray(joint_speed, dtype=float)
    if q.ndim != 2 or len(q) == 0 or s.shape != (len(q),) or vmax.shape != (q.shape[1],):
        raise ValueError(f"need q (N, n), s (N,), joint_speed (n,); got {q.shape}, {s.shape}, {vmax.shape}")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(s))):
        raise ValueError("q and s must be finite")
    h = np.diff(s)
    if s[0] != 0.0 or not np.all(h > 0.0):
        raise ValueError("s must start at 0 and increase strictly")
    if not np.all(vmax > 0.0):  # NaN fails too
        raise ValueError(f"joint speed limits must be > 0 (inf = none), got {vmax.tolist()}")
    for name, value in (("tip_speed", tip_speed), ("acceleration", acceleration)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be finite and > 0, got {value}")
    n = len(q)
    if n == 1:
        zero = np.zeros_like(q)
        return TimeScaling(np.zeros(1), q, zero, zero, s, np.zeros(1), np.zeros(1), np.full(1, ACCELERATION))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        slope = np.diff(q, axis=0) / h[:, None]  # (N - 1, n) per segment
        dq = np.gradient(q, s, axis=0, edge_order=2) if n > 2 else np.vstack([slope, slope])
        # A joint's rate per metre at a sample: the central difference, or a chord next to it if
        # steeper (a controller interpolating the positions follows the chords; v is monotone on a
        # segment, so a chord within the limit at both ends is within it all along).
        chord = np.abs(slope)
        rate = np.maximum.reduce([np.abs(dq), np.vstack([chord[:1], chord]), np.vstack([chord, chord[-1:]])])
        # caps (N, 1 + n): the tip, then each joint (inf where a joint does not move).
        caps = np.hstack([np.full((n, 1), float(tip_speed)), vmax / rate])
    if not (np.all(np.isfinite(dq)) and np.all(caps > 0.0)):
        raise ValueError("the path's joint derivative overflows: samples too close for their joint steps")
    which = np.argmin(caps, axis=1)  # ties go to the tip (column 0)
    cap = caps[np.arange(n), which]
    if n == 2:
        return _rest_to_rest(q, s, dq, float(acceleration), float(cap.min()))

    c = cap * cap
    c[[0, -1]] = 0.0
    reach = 2.0 * acceleration * s  # S_i
    back = 2.0 * acceleration * (s[-1] - s)
    forward = reach + np.minimum.accumulate(c - reach)
    backward = back + np.minimum.accumulate((c - back)[::-1])[::-1]
    x = np.minimum(np.minimum(forward, backward), c)
    # At a cap: also an acceleration curve that meets it at a sample, within the sums' rounding.
    capped = x >= c * (1.0 - CAP_RTOL)
    speed = np.where(capped, cap, np.minimum(np.sqrt(x), cap))  # never above a cap by rounding
    speed[[0, -1]] = 0.0
    active = np.where(capped, which - 1, ACCELERATION)
    active[[0, -1]] = ACCELERATION

    v2 = speed * speed
    segment = (v2[1:] - v2[:-1]) / (2.0 * h)  # constant sdd on each segment
    sdd = np.concatenate([segment[:1], 0.5 * (segment[:-1] + segment[1:]), segment[-1:]])
    t = np.concatenate([[0.0], np.cumsum(2.0 * h / (speed[:-1] + speed[1:]))])
    curvature = 2.0 * np.diff(slope, axis=0) / (h[:-1] + h[1:])[:, None]  # q'' at samples 1..N-2
    ddq = np.vstack([curvature[:1], curvature, curvature[-1:]])
    qd = dq * speed[:, None]
    qdd = ddq * v2[:, None] + dq * sdd[:, None]
    return TimeScaling(t=t, q=q, qd=qd, qdd=qdd, s=s, speed=speed, sdd=sdd, active=active)


def _rest_to_rest(q: np.ndarray, s: np.ndarray, dq: np.ndarray, a: float, cap: float) -> TimeScaling:
    """One segment from rest to rest: accelerate at ``a`` to min(cap, sqrt(a L)), brake at ``a``."""
    length = float(s[-1])
    peak = min(cap, math.sqrt(a * length))
    t = np.array([0.0, length / peak + peak / a])
    sdd = np.array([a, -a])
    zero = np.zeros_like(q)
    return TimeScaling(
        t=t,
        q=q,
        qd=zero,
        qdd=dq * sdd[:, None],
        s=s,
        speed=np.zeros(2),
        sdd=sdd,
        active=np.full(2, ACCELERATION),
    )
