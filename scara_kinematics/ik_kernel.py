"""The SCARA's IK at a given heading for ONE target, compiled (numba): the single-call hot path of
:meth:`scara_kinematics.kinematics.Scara.ik` (modes ``phi`` and ``fixed_phi``), whose vectorised
numpy code (``Scara._solve_phi`` and :func:`manipulator_kinematics.model.select`) stays the
reference; a test compares the two over 10^4 random targets, failing statuses included.

Why compiled: one numpy call costs about a microsecond whatever its size, and the closed form with
its statuses and the selection rule is some sixty of them (about 60-80 us per call on 2 cores),
against a target of half Robotics Toolbox's C++ ``ik_LM`` on the same arm. Scalar code of the same
steps, compiled once and kept in numba's on-disk cache, takes about a microsecond.

Same steps as the numpy path, same equation numbers:

1. the wrist point w = p - l3 (cos phi, sin phi); sin theta1 = wy / l2 (eq. 12), reachable when
   |wy / l2| <= 1 (+ 1e-12); branch a theta1 = asin, branch b pi - asin kept in (-pi, pi];
2. x_l = wx - l1 - l2 cos theta1 (eq. 11), theta2 = phi - theta1 wrapped to [-pi, pi);
3. statuses as :func:`manipulator_kinematics.model.limit_status` (a candidate inside the limits
   widened by LIMIT_TOL is clipped to them), SINGULAR where |cos theta1| is below the threshold;
4. the selection as :func:`manipulator_kinematics.model.select` with weights (1 / l2, 1, 1).

The arm's constants arrive as one float array, ``Scara._packed``: l1, l2, l3, the limits widened
by LIMIT_TOL (lower 3, upper 3), the limits (lower 3, upper 3), the singularity threshold, the
seed weights (3).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from manipulator_kinematics.model import IKStatus
from manipulator_kinematics.select_kernel import select_one

# Globals are compile-time constants to numba.
_SUCCESS, _SINGULAR, _LIMITS = int(IKStatus.SUCCESS), int(IKStatus.SINGULAR), int(IKStatus.JOINT_LIMITS)
_UNREACHABLE = int(IKStatus.UNREACHABLE)


@njit(cache=True, error_model="numpy")
def _wrap(angle: float) -> float:
    """planar.wrap_angle: to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, error_model="numpy")
def solve_phi(k: np.ndarray, px: float, py: float, phi: float, seed: np.ndarray, seeded: bool, branch: int,
              tie_tolerance: float, q: np.ndarray, status: np.ndarray) -> tuple[int, bool]:
    """Both branches q (2, 3) and their statuses (2,) at heading phi, then (selected, tie)."""
    l1, l2, l3 = k[0], k[1], k[2]
    wx = px - l3 * math.cos(phi)
    wy = py - l3 * math.sin(phi)
    sin1 = wy / l2  # eq. (12)
    reachable = abs(sin1) <= 1.0 + 1e-12
    sin1 = min(max(sin1, -1.0), 1.0)
    theta1_a = math.asin(sin1)
    cos1_a = math.sqrt(1.0 - sin1 * sin1)
    singular = cos1_a < k[15]
    for b in range(2):
        theta1 = theta1_a if b == 0 else math.copysign(math.pi, theta1_a) - theta1_a
        cos1 = cos1_a if b == 0 else -cos1_a
        if not reachable:
            q[b, 0] = q[b, 1] = q[b, 2] = math.nan
            status[b] = _UNREACHABLE
            continue
        q[b, 0] = wx - l1 - l2 * cos1  # eq. (11)
        q[b, 1] = theta1
        q[b, 2] = _wrap(phi - theta1)
        exists, inside = True, True
        for j in range(3):
            exists = exists and math.isfinite(q[b, j])
            inside = inside and k[3 + j] <= q[b, j] <= k[6 + j]
        if not exists:
            status[b] = _UNREACHABLE
        elif inside:
            for j in range(3):
                q[b, j] = min(max(q[b, j], k[9 + j]), k[12 + j])
            status[b] = _SINGULAR if singular else _SUCCESS
        else:
            status[b] = _LIMITS
    # The shared rule (model.select): a requested branch alone, else the nearest to the seed, else the first.
    allowed = np.full(2, branch < 0)
    if branch >= 0:
        allowed[branch] = True
    return select_one(q, status, seed, seeded, allowed, k[16:19], tie_tolerance)
