"""The tool changer's closed-form IK for ONE target, compiled (numba): the single-call hot path of
:meth:`tool_changer_kinematics.kinematics.ToolChanger.solve_ik`, whose vectorised numpy code stays
the reference (a test compares the two over 10^4 random targets, failing statuses included).

Why compiled: one numpy call costs about a microsecond whatever its size, and the closed form with
its statuses and the selection rule is over a hundred of them; scalar loops of the same steps,
compiled once and kept in numba's on-disk cache (``cache=True``), take a few microseconds.

Same steps as the numpy path (``ToolChanger._closed_form`` and ``_solve``), same equations:

1. wrist centre w = p - d6 a, theta1 = atan2(wy, wx) or that + pi (element (3,4));
2. theta5 from a in frame 1 (element (3,3)), phi = theta2 + theta3 + theta4 from the direction of x4;
3. theta6 from n in frame 5 (element (3,2));
4. the J3 origin as the tip of the planar 2R arm (a2, a3), theta4 = phi - theta2 - theta3 (eq. 7);
5. statuses as :func:`manipulator_kinematics.model.limit_status` with the machine's SINGULAR and
   INVALID rules; the selection as :func:`manipulator_kinematics.model.select`.

The machine's constants arrive as one float array, ``ToolChanger._packed``: a1..a4, d1, d5, d6 (7),
the J2-J3 reach (2), wrist and axis singularity thresholds (2), the wrapping offsets and bottoms
(6 + 6), the limits widened by the status tolerance (6 + 6), offsets of J1 and J6 (2), then
AXIS_RULE, WRIST_RULE, ROTATION_TOL, BOTTOM_TOL and TIE_TOLERANCE.
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


@njit(cache=True, error_model="numpy")
def _rigid(T: np.ndarray, rotation_tol: float, bottom_tol: float) -> bool:
    """kinematics.rigid_transform of one T (4, 4)."""
    for i in range(4):
        for j in range(4):
            if not math.isfinite(T[i, j]):
                return False
    for i in range(3):
        for j in range(3):
            dot = T[0, i] * T[0, j] + T[1, i] * T[1, j] + T[2, i] * T[2, j]
            if not abs(dot - (1.0 if i == j else 0.0)) < rotation_tol:
                return False
    det = (
        T[0, 0] * (T[1, 1] * T[2, 2] - T[2, 1] * T[1, 2])
        + T[1, 0] * (T[2, 1] * T[0, 2] - T[0, 1] * T[2, 2])
        + T[2, 0] * (T[0, 1] * T[1, 2] - T[1, 1] * T[0, 2])
    )
    bottom = abs(T[3, 0]) + abs(T[3, 1]) + abs(T[3, 2]) + abs(T[3, 3] - 1.0)
    return det > 0.0 and bottom < bottom_tol


@njit(cache=True, error_model="numpy")
def solve(
    k: np.ndarray,
    T: np.ndarray,
    seed: np.ndarray,
    seeded: bool,
    branch: int,
    q: np.ndarray,
    status: np.ndarray,
    s5_out: np.ndarray,
    reach: np.ndarray,
) -> tuple[int, bool, bool, float]:
    """Candidates q (8, 6), statuses (8,), |sin theta5| (8,), NaN where no solution, and the J3
    origin's distance from J2 (8,) of one flange pose ``T`` (4, 4), filled in place; returns
    (selected, tie, not a pose, rho). ``seed`` (6,) is used only if ``seeded``; ``branch`` -1 = any."""
    a1, a2, a3, a4, d1, d5, d6 = k[0], k[1], k[2], k[3], k[4], k[5], k[6]
    reach_lo, reach_hi, wrist_singularity, axis_singularity = k[7], k[8], k[9], k[10]
    wrap_offset, wrap_bottom, lower, upper = k[11:17], k[17:23], k[23:29], k[29:35]
    axis_rule, wrist_rule, rotation_tol, bottom_tol, tie_tolerance = k[37], k[38], k[39], k[40], k[41]
    invalid = not _rigid(T, rotation_tol, bottom_tol)
    rule1 = k[35] + (seed[0] if seeded else 0.0)  # the degenerate rules: the seed's theta1, theta6
    rule6 = k[36] + (seed[5] if seeded else 0.0)
    nx, ny, nz = T[0, 0], T[1, 0], T[2, 0]
    ax, ay, az = T[0, 2], T[1, 2], T[2, 2]
    # 1. Wrist centre and theta1 (front shoulder); on the J1 axis the seed's theta1.
    wx, wy, wz = T[0, 3] - d6 * ax, T[1, 3] - d6 * ay, T[2, 3] - d6 * az
    rho = math.sqrt(wx * wx + wy * wy)
    safe = 1.0 if rho == 0.0 else rho
    if rho < axis_rule:
        c1, s1 = math.cos(rule1), math.sin(rule1)
    else:
        c1, s1 = wx / safe, wy / safe
    # a, n and w in frame 1 of the front shoulder; the back shoulder flips x1 and z1.
    ax1, az1 = ax * c1 + ay * s1, ax * s1 - ay * c1
    nx1, nz1 = nx * c1 + ny * s1, nx * s1 - ny * c1
    w1, wy1 = wx * c1 + wy * s1, wz - d1
    # 2. |sin theta5| and, at the wrist singularity, psi = atan2(n.y1, n.x1) and the seed's theta6.
    s5 = math.sqrt(ax1 * ax1 + az * az)
    safe5 = 1.0 if s5 == 0.0 else s5
    degenerate = s5 < wrist_rule
    norm = math.sqrt(nx1 * nx1 + nz * nz)
    norm = 1.0 if norm == 0.0 else norm
    c6, s6 = math.cos(rule6), math.sin(rule6)
    y = np.empty(6)
    x = np.empty(6)
    for b in range(8):  # kinematics.BRANCHES order: index = 4 shoulder + 2 elbow + wrist
        shoulder = 1.0 if b < 4 else -1.0
        elbow = -1.0 if b % 4 < 2 else 1.0
        wrist = 1.0 if b % 2 == 0 else -1.0
        ax1_k, az1_k, nx1_k, nz1_k = shoulder * ax1, shoulder * az1, shoulder * nx1, shoulder * nz1
        sin5 = wrist * s5
        cphi, sphi = -wrist * ax1_k / safe5, -wrist * az / safe5
        exists = True
        if degenerate:
            cpsi, spsi = shoulder * nx1 / norm, nz / norm
            if az1_k >= 0.0:
                cphi, sphi = cpsi * c6 + spsi * s6, spsi * c6 - cpsi * s6
            else:
                cphi, sphi = spsi * s6 - cpsi * c6, -spsi * c6 - cpsi * s6
            exists = wrist > 0.0
        # 3. theta6 from n in frame 5.
        y6 = cphi * nz - sphi * nx1_k
        x6 = az1_k * (cphi * nx1_k + sphi * nz) + sin5 * nz1_k
        # 4. The J3 origin: the planar 2R arm (a2, a3); theta4 = phi - theta2 - theta3 (eq. 7).
        o3x = shoulder * w1 - a1 - a4 * cphi - d5 * sphi
        o3y = wy1 - a4 * sphi + d5 * cphi
        r = math.sqrt(o3x * o3x + o3y * o3y)
        reach[b] = r
        exists = exists and r >= reach_lo and r <= reach_hi
        s5_out[b] = s5 if exists else math.nan
        c3 = min(max((r * r - a2 * a2 - a3 * a3) / (2.0 * a2 * a3), -1.0), 1.0)
        s3 = elbow * math.sqrt(1.0 - c3 * c3)
        k1, k2 = a2 + a3 * c3, a3 * s3
        y2, x2 = o3y * k1 - o3x * k2, o3x * k1 + o3y * k2
        y23, x23 = y2 * c3 + x2 * s3, x2 * c3 - y2 * s3
        y[0], y[1], y[2], y[3], y[4], y[5] = shoulder * s1, y2, s3, sphi * x23 - cphi * y23, sin5, y6
        x[0], x[1], x[2], x[3], x[4], x[5] = shoulder * c1, x2, c3, cphi * x23 + sphi * y23, az1_k, x6
        # 5. Joint values as their representatives inside the limits; the status.
        inside = True
        for j in range(6):
            value = math.atan2(y[j], x[j]) - wrap_offset[j] if exists else math.nan
            if value <= wrap_bottom[j]:
                value += 2.0 * math.pi
            q[b, j] = value
            if not math.isfinite(value):
                exists = False
            if not (value >= lower[j] and value <= upper[j]):
                inside = False
        if invalid:
            status[b] = _INVALID
        elif not exists:
            status[b] = _UNREACHABLE
        elif not inside:
            status[b] = _LIMITS
        elif s5 < wrist_singularity or rho < axis_singularity:
            status[b] = _SINGULAR
        else:
            status[b] = _SUCCESS
    allowed = np.full(8, branch < 0)
    if branch >= 0:
        allowed[branch] = True
    selected, tie = select_one(q, status, seed, seeded, allowed, np.ones(6), tie_tolerance)
    if invalid:
        q[:, :] = math.nan
    return selected, tie, invalid, rho


@njit(cache=True, error_model="numpy")
def solve_batch(
    k: np.ndarray,
    T: np.ndarray,
    seeds: np.ndarray,
    seeded: bool,
    branch: int,
    q: np.ndarray,
    status: np.ndarray,
    s5_out: np.ndarray,
    reach: np.ndarray,
    selected: np.ndarray,
    tie: np.ndarray,
    invalid: np.ndarray,
    rho: np.ndarray,
) -> None:
    """:func:`solve` for every flange pose T (N, 4, 4) with seeds (N, 6), or (1, 6) for all (read
    if ``seeded``): q (N, 8, 6), status, s5_out and reach (N, 8), selected, tie, invalid and rho (N,)."""
    last = seeds.shape[0] - 1
    for i in range(T.shape[0]):
        selected[i], tie[i], invalid[i], rho[i] = solve(
            k, T[i], seeds[min(i, last)], seeded, branch, q[i], status[i], s5_out[i], reach[i]
        )
