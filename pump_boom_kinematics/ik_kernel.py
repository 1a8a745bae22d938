"""The pump boom's region IK for ONE pour point, compiled (numba), and its loop over a batch
(``region_ik_batch``, issue #32): the single-call hot path of
:meth:`pump_boom_kinematics.kinematics.PumpBoom.region_ik_point` (and of ``solve_ik`` on one
target), whose vectorised numpy code (:meth:`~pump_boom_kinematics.kinematics.PumpBoom.region_ik`)
stays the reference (a test compares the two over the table, its bands and around it, every
failure included).

Why compiled: one numpy call costs about a microsecond whatever its size, and the region IK is
over a hundred of them (360-370 us per point on 2 cores); a controller solves one point per
cycle. Scalar code of the same steps, compiled once and kept in numba's on-disk cache
(``cache=True``), takes about a microsecond.

Same steps and the same order of checks as the numpy path (paper 001, section 2):

1. theta1 = atan2(y, x) (eq. 3), with a seed the turn nearest the seed's slew angle inside the
   slew limits; on the slew axis the seed's (else 0);
2. NOT_FINITE, BEYOND_REACH (farther from the root pin than the stretched boom), BEHIND_ROOT;
3. the region table at (r, z) (:meth:`pump_boom_kinematics.regions.RegionTable.blend`): the
   square holding the point (closed squares: the four cells within EDGE, above/right first),
   NOT_IN_TABLE if none; its own triple where the band window lies inside the square, else the
   window mean summed over the cells of its family under the window (RegionTable._window_mean);
4. theta5, theta6 from the planar 2R of sections 4-5 in closed form (eq. 4, elbow-over branch),
   TWO_LINK where it does not reach;
5. JOINT_LIMITS outside the limits by more than LIMIT_TOL (joints within it moved onto the
   limit), ENVELOPE where a section joint is below the root-tip chord (Fig. 4).

The machine and the table arrive as numpy arrays, ``RegionTable.lookup`` and
``PumpBoom._packed``: the constants (root pin r, z; lengths l1..l5; reach; LIMIT_TOL;
ENVELOPE_TOL; the lower (6) and upper (6) limits; the grid origin r, z; the lookup cell; the
lookup arrays' lower cell column, row; half the band in cells; EDGE in cells), the cell owners
(n_u, n_v) (-1: none) and per square its bounds in cells (low u, low v, high u, high v), its
triple and its family (m, 8).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Failure codes (kinematics.Failure; globals are compile-time constants to numba).
_NONE, _NOT_FINITE, _BEYOND_REACH, _BEHIND_ROOT, _NOT_IN_TABLE, _TWO_LINK, _JOINT_LIMITS, _ENVELOPE = range(8)
_TWO_LINK_TOL = 1e-9  # m: kinematics.complete's two_link_ik tolerance
_REACH_TOL = 1e-9  # m: region_ik's reach check


@njit(cache=True, error_model="numpy")
def _window_mean(
    owner: np.ndarray, squares: np.ndarray, square: int, u: float, v: float, half: float, q: np.ndarray
) -> None:
    """RegionTable._window_mean of one point in cells into q[1:4] (the same weights, the squares
    of the point's family only; numpy's matrix product adds them in its own order: the same to
    round-off); the square's own triple where every square of its family under the window holds it."""
    n_u, n_v = owner.shape
    span = math.ceil(2.0 * half) + 1
    first_u, first_v = math.floor(u - half), math.floor(v - half)
    total = np.zeros(4)
    same = True
    for i in range(span):
        a = first_u + i
        along_u = max(min(u + half, a + 1.0) - max(u - half, float(a)), 0.0) if 0 <= a < n_u else 0.0
        for j in range(span):
            b = first_v + j
            along_v = max(min(v + half, b + 1.0) - max(v - half, float(b)), 0.0) if 0 <= b < n_v else 0.0
            weight = along_u * along_v
            k = owner[a, b] if weight > 0.0 else -1
            if k >= 0 and squares[k, 7] == squares[square, 7]:  # of the point's family
                for c in range(3):
                    total[c] += weight * squares[k, 4 + c]
                    same = same and squares[k, 4 + c] == squares[square, 4 + c]
                total[3] += weight
    for c in range(3):
        q[1 + c] = squares[square, 4 + c] if same else total[c] / total[3]


@njit(cache=True, error_model="numpy")
def _owner(owner: np.ndarray, u: float, v: float, edge: float) -> int:
    """RegionTable.owner of one finite point in cells: the square of the first covered cell of
    the four within ``edge``, above/right first; -1 if none."""
    n_u, n_v = owner.shape
    for b in (math.floor(v + edge), math.floor(v - edge)):
        for a in (math.floor(u + edge), math.floor(u - edge)):
            if 0 <= a < n_u and 0 <= b < n_v and owner[a, b] >= 0:
                return owner[a, b]
    return -1


@njit(cache=True, error_model="numpy")
def _envelope_margin(k: np.ndarray, q: np.ndarray) -> float:
    """PumpBoom.envelope_margin of one joint state: the smallest signed distance of P_1..P_4 to
    the left of the chord root -> tip; -inf for a tip behind the root pin."""
    phi = q[1]
    r, z = 0.0, 0.0
    joints = np.empty((4, 2))
    for i in range(5):
        if i > 0:
            phi += q[i + 1] - math.pi
        r += k[2 + i] * math.cos(phi)
        z += k[2 + i] * math.sin(phi)
        if i < 4:
            joints[i, 0], joints[i, 1] = r, z
    if r < -k[9]:
        return -math.inf
    cross = math.inf
    for i in range(4):
        cross = min(cross, r * joints[i, 1] - z * joints[i, 0])
    return cross / math.hypot(r, z)


@njit(cache=True, error_model="numpy")
def region_ik(
    k: np.ndarray,
    owner: np.ndarray,
    squares: np.ndarray,
    x: float,
    y: float,
    z: float,
    seed_slew: float,
    seeded: bool,
    q: np.ndarray,
) -> tuple[int, bool]:
    """Region IK of the pour point (x, y, z) (module docstring): the failure code and whether a
    transition band set the triple; q (6,) the joints (the limits applied within LIMIT_TOL) where
    the failure is 0, else as far as the steps got (NaN beyond)."""
    for i in range(6):
        q[i] = math.nan
    root_r, root_z, reach, limit_tol = k[0], k[1], k[7], k[8]
    lower, upper = k[10:16], k[16:22]
    # Step 1: theta1 (eq. 3) with the seed's turn.
    r = math.hypot(x, y)
    heading = math.atan2(y, x)
    if not seeded:
        theta1 = heading if r > 0.0 else 0.0
    elif r > 0.0:
        theta1 = heading + 2.0 * math.pi * np.rint((seed_slew - heading) / (2.0 * math.pi))
        if theta1 > upper[0]:
            theta1 -= 2.0 * math.pi
        elif theta1 < lower[0]:
            theta1 += 2.0 * math.pi
    else:
        theta1 = seed_slew
    q[0] = theta1
    # Step 2: the point.
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return _NOT_FINITE, False
    if math.hypot(r - root_r, z - root_z) > reach + _REACH_TOL:
        return _BEYOND_REACH, False
    if r < root_r:
        return _BEHIND_ROOT, False
    # Step 3: the region table, blended in the transition bands.
    cell, half, edge = k[24], k[27], k[28]
    u = (r - k[22]) / cell - k[25]
    v = (z - k[23]) / cell - k[26]
    square = _owner(owner, u, v, edge)
    if square < 0:
        return _NOT_IN_TABLE, False
    low_u, low_v, high_u, high_v = squares[square, :4]
    blended = False
    if u - half >= low_u and u + half <= high_u and v - half >= low_v and v + half <= high_v:
        for i in range(3):
            q[1 + i] = squares[square, 4 + i]
    else:
        _window_mean(owner, squares, square, u, v, half, q)
        for i in range(3):
            blended = blended or q[1 + i] != squares[square, 4 + i]
    # Step 4: sections 4-5 as the planar 2R from the end P_3 of section 3 (eq. 4).
    l1, l2, l3, l4, l5 = k[2], k[3], k[4], k[5], k[6]
    phi1 = q[1]
    phi2 = q[1] + q[2] - math.pi
    phi3 = q[1] + q[2] + q[3] - 2.0 * math.pi
    dr = r - (root_r + l1 * math.cos(phi1) + l2 * math.cos(phi2) + l3 * math.cos(phi3))
    dz = z - (root_z + l1 * math.sin(phi1) + l2 * math.sin(phi2) + l3 * math.sin(phi3))
    d = math.hypot(dr, dz)
    if d > l4 + l5 + _TWO_LINK_TOL or d < abs(l4 - l5) - _TWO_LINK_TOL:
        return _TWO_LINK, blended
    # The elbow-over branch (section 5 bends down from section 4).
    bend = -math.acos(min(max((d * d - l4 * l4 - l5 * l5) / (2.0 * l4 * l5), -1.0), 1.0))
    phi4 = math.atan2(dz, dr) - math.atan2(l5 * math.sin(bend), l4 + l5 * math.cos(bend))
    q[4] = ((phi4 - phi3) + math.pi) % (2.0 * math.pi) - math.pi + math.pi
    q[5] = bend + math.pi
    # Step 5: the limits (within LIMIT_TOL moved onto them), then the positive envelope.
    for i in range(6):
        if not (q[i] >= lower[i] - limit_tol and q[i] <= upper[i] + limit_tol):
            return _JOINT_LIMITS, blended
    for i in range(6):
        q[i] = min(max(q[i], lower[i]), upper[i])
    if _envelope_margin(k, q) < -k[9]:
        return _ENVELOPE, blended
    return _NONE, blended


@njit(cache=True, error_model="numpy")
def region_ik_batch(
    k: np.ndarray,
    owner: np.ndarray,
    squares: np.ndarray,
    points: np.ndarray,
    seeds: np.ndarray,
    seeded: bool,
    status_of: np.ndarray,
    q: np.ndarray,
    status: np.ndarray,
    selected: np.ndarray,
) -> None:
    """:func:`region_ik` of every pour point (N, 3), the slew angle of seeds (N, 6) or (1, 6) for
    every point (read if ``seeded``): ``PumpBoom.solve_ik``'s one candidate q (N, 1, 6), NaN where
    the point fails, its status (N, 1) (``status_of`` the IKStatus of each failure code) and the
    selection (N,), 0 or -1."""
    last = seeds.shape[0] - 1
    for i in range(points.shape[0]):
        failure, _ = region_ik(
            k,
            owner,
            squares,
            points[i, 0],
            points[i, 1],
            points[i, 2],
            seeds[min(i, last), 0],
            seeded,
            q[i, 0],
        )
        if failure:
            q[i, 0, :] = math.nan
        status[i, 0] = status_of[failure]
        selected[i] = -1 if failure else 0
