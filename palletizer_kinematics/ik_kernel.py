"""The palletizer's IK for ONE target, compiled (numba): the single-call hot path of
:meth:`palletizer_kinematics.kinematics.Palletizer.solve_ik`, whose vectorised numpy code
(``_solve_block``) stays the reference (a test compares the two over 10^4 random targets,
failing statuses included).

Why compiled: one numpy call costs about a microsecond whatever its size, and the closed form
with its statuses and the selection rule is over a hundred of them (the numpy path costs a few
hundred microseconds per target on 2 cores). Scalar loops of the same steps, compiled once and
kept in numba's on-disk cache (``cache=True``), take a few microseconds.

Same steps as the numpy path, same equation numbers:

1. the target: finite, its rotation part a rotation, the tool z axis straight down within the
   tilt tolerance; the flange yaw atan2(ny, nx) (or the seed's A1 - A6, or 0);
2. eq. (3) theta1 (front, back = +180 deg), eq. (5) c3 of the wrist point, eq. (6) theta3 (elbow
   up, down), eqs. (7)-(8) theta2, eq. (4) theta5 on both flange turns;
3. the axis angles, eqs. (9)-(11), A1..A3 wrapped to (-pi, pi] as atan2;
4. statuses as :func:`manipulator_kinematics.model.limit_status` on the axis angles, SINGULAR
   within the thresholds, UNREACHABLE out of reach or tilted, INVALID for junk; the selection as
   :func:`manipulator_kinematics.model.select`, over the home elbow branch first, then over all.

The machine's constants arrive as one float array, ``Palletizer._packed``: a1, a2, a3, a4, d1,
d6; the axis limits widened by the status tolerance (4 lower, 4 upper); singular_elbow,
singular_radius, cos(tilt_tolerance), 1.0 for the double variant (0.0 single); the rotation,
bottom-row and reach tolerances and the selection's tie tolerance.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from manipulator_kinematics.model import IKStatus
from manipulator_kinematics.select_kernel import select_one

# Globals are compile-time constants to numba.
_SUCCESS, _SINGULAR, _LIMITS = int(IKStatus.SUCCESS), int(IKStatus.SINGULAR), int(IKStatus.JOINT_LIMITS)
_UNREACHABLE, _INVALID = int(IKStatus.UNREACHABLE), int(IKStatus.INVALID)
_HOME_COUNT = 2  # the home elbow branch's candidates (either flange turn) lead the branch order


@njit(cache=True, error_model="numpy")
def _principal(angle: float) -> float:
    """kinematics._principal: wrapped to (-pi, pi], the range of atan2."""
    return math.pi - (math.pi - angle) % (2.0 * math.pi)


@njit(cache=True, error_model="numpy")
def _is_pose(k: np.ndarray, pose: np.ndarray) -> bool:
    """kinematics._is_pose of the 16 row-major entries."""
    for i in range(3):
        for j in range(3):
            dot = pose[i] * pose[j] + pose[4 + i] * pose[4 + j] + pose[8 + i] * pose[8 + j]
            if not abs(dot - (1.0 if i == j else 0.0)) < k[18]:
                return False
    det = (
        pose[0] * (pose[5] * pose[10] - pose[6] * pose[9])
        - pose[1] * (pose[4] * pose[10] - pose[6] * pose[8])
        + pose[2] * (pose[4] * pose[9] - pose[5] * pose[8])
    )
    bottom = abs(pose[12]) + abs(pose[13]) + abs(pose[14]) + abs(pose[15] - 1.0)
    return det > 0.0 and bottom < k[19]


@njit(cache=True, error_model="numpy")
def solve(
    k: np.ndarray,
    pose: np.ndarray,
    seed: np.ndarray,
    seeded: bool,
    allowed: np.ndarray,
    oriented: bool,
    axis_mode: bool,
    q: np.ndarray,
    status: np.ndarray,
    extra: np.ndarray,
) -> tuple[int, bool, bool]:
    """Every candidate of one target pose (16,), row-major: q (8, 4) in the mode's angles (NaN
    where UNREACHABLE or INVALID), status (8,), extra = [cos(tilt), c3 front, c3 back]; returns
    (selected, tie, the home elbow branch was selected). ``seed`` (4,) in the mode's angles,
    used if ``seeded``; ``allowed`` (8,) the candidates a requested branch leaves."""
    a1, a2, a3, a4, d1, d6 = k[0], k[1], k[2], k[3], k[4], k[5]
    singular_elbow, singular_radius, lean_min, double = k[14], k[15], k[16], k[17] != 0.0
    reach_tol, tie_tolerance = k[20], k[21]
    # Step 1: the target.
    finite = True
    for i in range(16):
        if not math.isfinite(pose[i]):
            finite = False
    lean = -pose[10]
    if oriented:
        invalid = not (finite and _is_pose(k, pose))
        blocked = invalid or lean < lean_min
        yaw = math.atan2(pose[4], pose[0])  # eq. (4)'s atan2(ny, nx)
    else:
        invalid = blocked = not finite
        yaw = seed[0] - seed[3] if seeded else 0.0
    extra[0] = lean
    px, py, pz = pose[3], pose[7], pose[11]
    # Step 2, eq. (3): on axis 1 (r = 0) theta1 is free: 0 by rule.
    r = math.hypot(px, py)
    front = 0.0 if r == 0.0 else math.atan2(py, px)
    l2 = d1 - d6 - pz  # eq. (7)'s right-hand side
    for arm in range(2):
        theta1 = front if arm == 0 else front - math.copysign(math.pi, front)
        X = (r if arm == 0 else -r) - a1 - a4  # the wrist point from axis 2
        c3 = (X * X + l2 * l2 - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)  # eq. (5)
        extra[1 + arm] = c3
        reach = abs(c3) <= 1.0 + reach_tol
        cos3 = min(max(c3, -1.0), 1.0)
        sin3 = math.sqrt(1.0 - cos3 * cos3)
        singular = sin3 < singular_elbow or r < singular_radius
        inner = _principal(theta1 - yaw)  # eq. (4)
        for elbow in range(2):
            s3 = sin3 if elbow == 0 else -sin3
            theta3 = math.atan2(s3, cos3)  # eq. (6)
            a, b = a3 * s3, a3 * cos3 + a2  # eqs. (7)-(8)
            theta2 = math.atan2(b * l2 - a * X, a * l2 + b * X)  # atan2(b, a) + atan2(-X, l2)
            # Step 3, eqs. (9)-(11): A = M (theta - theta_home).
            A2 = theta2 + 0.5 * math.pi
            A3 = A2 + (theta3 - 0.5 * math.pi) if double else theta3 - 0.5 * math.pi
            axis1, axis2, axis3 = theta1, _principal(A2), _principal(A3)
            for turn in range(2):
                c = 4 * arm + 2 * elbow + turn
                if turn == 0:
                    theta5 = inner
                else:
                    theta5 = inner + 2.0 * math.pi if inner < 0.0 else inner - 2.0 * math.pi
                # Step 4: the statuses.
                if invalid:
                    status[c] = _INVALID
                elif blocked or not reach:
                    status[c] = _UNREACHABLE
                else:
                    inside = (
                        k[6] <= axis1 <= k[10]
                        and k[7] <= axis2 <= k[11]
                        and k[8] <= axis3 <= k[12]
                        and k[9] <= theta5 <= k[13]
                    )
                    status[c] = (_SINGULAR if singular else _SUCCESS) if inside else _LIMITS
                if status[c] >= _UNREACHABLE:
                    q[c, 0] = q[c, 1] = q[c, 2] = q[c, 3] = math.nan
                elif axis_mode:
                    q[c, 0], q[c, 1], q[c, 2], q[c, 3] = axis1, axis2, axis3, theta5
                else:
                    # The D-H angles of the wrapped axis angles (dh_from_axis), not atan2's: they
                    # differ by whole turns, so the pose is the same and the axes are the ones
                    # checked against the limits (issue 29: A3 -4.67 for 1.61).
                    dh3 = (axis3 - axis2 if double else axis3) + 0.5 * math.pi
                    q[c, 0], q[c, 1], q[c, 2], q[c, 3] = theta1, axis2 - 0.5 * math.pi, dh3, theta5
    weights, home = np.ones(4), allowed.copy()
    home[_HOME_COUNT:] = False
    selected, tie = select_one(q, status, seed, seeded, home, weights, tie_tolerance)
    if selected >= 0:
        return selected, tie, True
    selected, tie = select_one(q, status, seed, seeded, allowed, weights, tie_tolerance)
    return selected, tie, False


@njit(cache=True, error_model="numpy")
def solve_batch(
    k: np.ndarray,
    poses: np.ndarray,
    seeds: np.ndarray,
    seeded: bool,
    allowed: np.ndarray,
    oriented: bool,
    axis_mode: bool,
    q: np.ndarray,
    status: np.ndarray,
    extra: np.ndarray,
    selected: np.ndarray,
    tie: np.ndarray,
    home: np.ndarray,
) -> None:
    """:func:`solve` for every row of poses (N, 16) with seeds (N, 4), or (1, 4) for all (read if
    ``seeded``): q (N, 8, 4), status (N, 8), extra (N, 3), selected, tie and home (N,)."""
    last = seeds.shape[0] - 1
    for i in range(poses.shape[0]):
        selected[i], tie[i], home[i] = solve(
            k, poses[i], seeds[min(i, last)], seeded, allowed, oriented, axis_mode, q[i], status[i], extra[i]
        )
