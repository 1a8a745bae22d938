"""The excavator's pose IK for ONE target, compiled (numba), and its loop over a batch
(``solve_batch``, issue #32): the single-call hot path of
:mod:`excavator_kinematics.core.inverse`, whose vectorised numpy code stays the reference (a test
compares the two over 10^4 random targets, failing statuses included).

Why compiled: one numpy call costs about a microsecond whatever its size, and the closed form
with its statuses and the selection rule is over a hundred of them (measured 240-430 us per
call on 2 cores; the target is <= 20 us). Scalar loops of the same steps, compiled once and kept
in numba's on-disk cache (``cache=True``: ``__pycache__`` next to this file, or numba's user-wide
cache directory where that is not writable), take a few microseconds.

Same steps as the numpy path, same equation numbers:

1. swing theta1 = heading or heading + pi; the tip at the signed radius rho in the boom plane;
2. the bucket pin = tip - l4 (cos, sin) alpha; boom and arm = the planar 2R arm (l2, l3) from
   the boom foot pin, elbow up and down;
3. theta4 = alpha - theta2 - theta3 (eq. 3);
4. the cylinder lengths: eq. 1's second line for boom and arm, eq. 2 backwards for the bucket;
5. statuses as :func:`manipulator_kinematics.model.limit_status`, SINGULAR on the swing axis,
   INVALID for a target that is not finite; the selection as :func:`manipulator_kinematics.model.select`.

The machine's constants arrive as one float array, ``inverse.Constants.packed``, of the layout
:data:`excavator_kinematics.core.layouts.IK` (declared once, packed by name, read here by
offset): Constants' float fields, the limits widened by the status tolerance, the seed weights
and the strokes' ends.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from excavator_kinematics.core.layouts import IK
from manipulator_kinematics.model import IKStatus
from manipulator_kinematics.select_kernel import select_one

# Globals are compile-time constants to numba: the offsets into the packed constants (layouts.IK)
# and the statuses.
_K = IK.at
#: The layout this module reads; :func:`layout_signature` returns the one it was compiled with.
LAYOUT_SIGNATURE = IK.signature
_SUCCESS, _LIMITS, _UNREACHABLE = int(IKStatus.SUCCESS), int(IKStatus.JOINT_LIMITS), int(IKStatus.UNREACHABLE)
_SINGULAR, _INVALID = int(IKStatus.SINGULAR), int(IKStatus.INVALID)


@njit(cache=True, error_model="numpy")
def _triangle_length(theta: float, o: float, offset: float, aa_bb: float, two_ab: float) -> float:
    """Eq. 1's second line (inverse._triangle_length)."""
    t = o * math.tan(0.5 * (theta - offset))
    if not t > 0.0:
        return math.nan
    tt = t * t
    return math.sqrt(aa_bb - two_ab * (1.0 - tt) / (1.0 + tt))


@njit(cache=True, error_model="numpy")
def candidates(
    k: np.ndarray,
    x: float,
    y: float,
    z: float,
    alpha: np.ndarray,
    heading: float,
    D: np.ndarray,
    reach: np.ndarray,
) -> None:
    """D (4, 4) and reach (4,) of one target, candidate b at bucket angle alpha[b], in
    inverse.BRANCHES order (inverse.open_chain_columns, inverse.linkage_length_columns)."""
    l0, l1, l2, l3, l4 = k[_K.l0], k[_K.l1], k[_K.l2], k[_K.l3], k[_K.l4]
    l2l2_l3l3, two_l2l3, reach_max, reach_min = (
        k[_K.l2l2_l3l3],
        k[_K.two_l2l3],
        k[_K.reach_max],
        k[_K.reach_min],
    )
    boom_o, boom_offset, boom_aa_bb, boom_two_ab = (
        k[_K.boom_o],
        k[_K.boom_offset],
        k[_K.boom_aa_bb],
        k[_K.boom_two_ab],
    )
    arm_o, arm_offset, arm_aa_bb, arm_two_ab = (
        k[_K.arm_o],
        k[_K.arm_offset],
        k[_K.arm_aa_bb],
        k[_K.arm_two_ab],
    )
    h_phase, h_radius = k[_K.h_phase], k[_K.h_radius]
    pin_x, pin_y = k[_K.pin_from_pivot_x], k[_K.pin_from_pivot_y]
    base_x, base_y = k[_K.base_from_pivot_x], k[_K.base_from_pivot_y]
    side, side_hh, two_side, side_o, h_o = k[_K.side], k[_K.side_hh], k[_K.two_side], k[_K.side_o], k[_K.h_o]
    stroke_lo, stroke_hi = k[_K.stroke_lo], k[_K.stroke_hi]
    rho = x * math.cos(heading) + y * math.sin(heading)
    behind = heading + math.pi
    behind = (behind + math.pi) % (2.0 * math.pi) - math.pi
    for b in range(4):
        swing_sign = 1.0 if b < 2 else -1.0
        elbow_sign = 1.0 if b % 2 == 0 else -1.0
        D[b, 0] = heading if b < 2 else behind
        # Step 2: the bucket pin relative to the boom foot pin; the planar 2R arm to it.
        pin_r = swing_sign * rho - l4 * math.cos(alpha[b]) - l1
        pin_z = z - l4 * math.sin(alpha[b]) - l0
        r = math.hypot(pin_r, pin_z)
        if not math.isfinite(r):  # reach codes of manipulator_kinematics.planar.Reach
            reach[b] = 3
        elif r > reach_max:
            reach[b] = 1
        elif r < reach_min:
            reach[b] = 2
        else:
            reach[b] = 0
        if reach[b] != 0:
            D[b, 1:] = math.nan
            continue
        cos_elbow = min(max((r * r - l2l2_l3l3) / two_l2l3, -1.0), 1.0)
        elbow = math.acos(cos_elbow)
        beta = math.atan2(l3 * math.sqrt(1.0 - cos_elbow * cos_elbow), l2 + l3 * cos_elbow)
        theta2 = math.atan2(pin_z, pin_r) + elbow_sign * beta
        theta3 = -elbow_sign * elbow
        theta4 = alpha[b] - theta2 - theta3  # step 3, eq. 3
        # Step 4: eq. 1 for boom and arm; eq. 2 backwards for the bucket.
        D[b, 1] = _triangle_length(theta2, boom_o, boom_offset, boom_aa_bb, boom_two_ab)
        D[b, 2] = _triangle_length(theta3, arm_o, arm_offset, arm_aa_bb, arm_two_ab)
        psi = theta4 + h_phase
        hx, hy = h_radius * math.cos(psi), h_radius * math.sin(psi)  # H - bucket pin
        tx, ty = pin_x + hx, pin_y + hy  # H - pivot
        ff = tx * tx + ty * ty
        f = math.sqrt(ff)
        c = (ff + side_hh) / (two_side * f)
        d4 = math.nan
        if -1.0 <= c <= 1.0:  # else the side link and the H-link cannot meet
            s = math.sqrt(1.0 - c * c)
            u = side / f
            uc, us = u * c, u * s
            for turn in (-1.0, 1.0):
                rx, ry = uc * tx - turn * us * ty, uc * ty + turn * us * tx  # R - pivot
                on_side = (base_x * ry - base_y * rx) * side_o > 0.0
                ex, ey = rx - pin_x, ry - pin_y  # R - bucket pin
                on_four_bar = (ex * hy - ey * hx) * h_o > 0.0
                bx, by = rx - base_x, ry - base_y
                length = math.sqrt(bx * bx + by * by)
                in_stroke = stroke_lo <= length <= stroke_hi
                if on_side and on_four_bar and (math.isnan(d4) or in_stroke):
                    d4 = length
        D[b, 3] = d4


@njit(cache=True, error_model="numpy")
def judge(
    k: np.ndarray, x: float, y: float, finite: bool, swing_axis: float, D: np.ndarray, status: np.ndarray
) -> None:
    """Step 5's statuses (inverse.status)."""
    lower, upper = k[_K.lower : _K.lower + 4], k[_K.upper : _K.upper + 4]
    for b in range(4):
        exists, inside = True, True
        for j in range(4):
            v = D[b, j]
            if not math.isfinite(v):
                exists = False
            if not (v >= lower[j] and v <= upper[j]):
                inside = False
        status[b] = (_SUCCESS if inside else _LIMITS) if exists else _UNREACHABLE
        if status[b] == _SUCCESS and math.hypot(x, y) <= swing_axis:
            status[b] = _SINGULAR
        if not finite:
            status[b] = _INVALID


@njit(cache=True, error_model="numpy")
def pick(
    k: np.ndarray,
    D: np.ndarray,
    status: np.ndarray,
    seed: np.ndarray,
    seeded: bool,
    branch: int,
    tie_tolerance: float,
) -> tuple[int, bool]:
    """manipulator_kinematics.model.select for one target (the shared select_one): (selected, tie)."""
    allowed = np.full(4, branch < 0)
    if branch >= 0:
        allowed[branch] = True
    return select_one(D, status, seed, seeded, allowed, k[_K.weights : _K.weights + 4], tie_tolerance)


@njit(cache=True, error_model="numpy")
def solve_batch(
    k: np.ndarray,
    Q: np.ndarray,
    seeds: np.ndarray,
    seeded: bool,
    branch: int,
    swing_axis: float,
    tie_tolerance: float,
    D: np.ndarray,
    reach: np.ndarray,
    status: np.ndarray,
    selected: np.ndarray,
    tie: np.ndarray,
) -> None:
    """:func:`candidates`, :func:`judge` and :func:`pick` of every target Q (N, 4) = [x, y, z,
    alpha], seeds (N, 4) or (1, 4) for every target (read if ``seeded``): D (N, 4, 4), reach and
    status (N, 4), selected and tie (N,) (inverse.solve_pose's batch)."""
    alpha = np.empty(4)
    allowed = np.full(4, branch < 0)
    if branch >= 0:
        allowed[branch] = True
    last = seeds.shape[0] - 1
    for i in range(Q.shape[0]):
        x, y, z, angle = Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3]
        alpha[:] = angle
        finite = math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and math.isfinite(angle)
        candidates(k, x, y, z, alpha, math.atan2(y, x), D[i], reach[i])
        judge(k, x, y, finite, swing_axis, D[i], status[i])
        selected[i], tie[i] = select_one(
            D[i],
            status[i],
            seeds[min(i, last)],
            seeded,
            allowed,
            k[_K.weights : _K.weights + 4],
            tie_tolerance,
        )


@njit(cache=True, error_model="numpy")
def _margins(k: np.ndarray, D: np.ndarray, margin: np.ndarray) -> None:
    """inverse.stroke_margins of the four candidates D (4, 4)."""
    for b in range(4):
        worst = math.inf
        for j in range(3):
            d, lo, hi = D[b, j + 1], k[_K.stroke_min + j], k[_K.stroke_max + j]
            worst = min(worst, min(d - lo, hi - d) / (hi - lo))
            if math.isnan(d):
                worst = -math.inf
                break
        margin[b] = worst


@njit(cache=True, error_model="numpy")
def widest_margin_angles(
    k: np.ndarray, x: float, y: float, z: float, grid_size: int, peaks: int, golden: float, steps: int
) -> np.ndarray:
    """inverse.widest_margin_angles for one position: (4,) per branch the bucket angle of the
    largest stroke margin; the same grid, peaks and golden-section steps."""
    D, reach, row = np.empty((4, 4)), np.empty(4, dtype=np.int8), np.empty(4)
    heading = math.atan2(y, x)
    step = 2.0 * math.pi / grid_size
    grid = np.arange(grid_size) * step - math.pi
    margin = np.empty((grid_size, 4))
    for g in range(grid_size):
        candidates(k, x, y, z, np.full(4, grid[g]), heading, D, reach)
        _margins(k, D, row)
        margin[g] = row
    step = grid[1] - grid[0]
    result = np.full(4, -math.pi)
    best, value = np.empty((peaks, 4)), np.empty((peaks, 4))
    for b in range(4):
        # The best local maxima of the grid (circular), ties in grid order (a stable sort).
        key = np.empty(grid_size)
        for g in range(grid_size):
            m = margin[g, b]
            peak = m >= margin[g - 1, b] and m >= margin[(g + 1) % grid_size, b]
            key[g] = -m if peak else math.inf
        taken = np.zeros(grid_size, dtype=np.bool_)
        for p in range(peaks):
            first = -1
            for g in range(grid_size):
                if not taken[g] and (first < 0 or key[g] < key[first]):
                    first = g
            taken[first] = True
            best[p, b], value[p, b] = grid[first], margin[first, b]
    for p in range(peaks):
        # Golden-section search on [peak - step, peak + step], the four branches side by side.
        low, high = best[p] - step, best[p] + step
        inner_low, inner_high = high - golden * (high - low), low + golden * (high - low)
        value_low, value_high = np.empty(4), np.empty(4)
        candidates(k, x, y, z, inner_low, heading, D, reach)
        _margins(k, D, value_low)
        candidates(k, x, y, z, inner_high, heading, D, reach)
        _margins(k, D, value_high)
        left = np.empty(4, dtype=np.bool_)
        new = np.empty(4)
        for _ in range(steps):
            for b in range(4):
                left[b] = value_low[b] >= value_high[b]
                if left[b]:  # the maximum is in [low, inner_high]
                    high[b] = inner_high[b]
                    inner_high[b], value_high[b] = inner_low[b], value_low[b]
                    new[b] = high[b] - golden * (high[b] - low[b])
                else:
                    low[b] = inner_low[b]
                    inner_low[b], value_low[b] = inner_high[b], value_high[b]
                    new[b] = low[b] + golden * (high[b] - low[b])
            candidates(k, x, y, z, new, heading, D, reach)
            _margins(k, D, row)
            for b in range(4):
                if left[b]:
                    inner_low[b], value_low[b] = new[b], row[b]
                else:
                    inner_high[b], value_high[b] = new[b], row[b]
        for b in range(4):
            if value_low[b] >= value_high[b]:
                refined, refined_value = inner_low[b], value_low[b]
            else:
                refined, refined_value = inner_high[b], value_high[b]
            if refined_value > value[p, b]:  # never worse than the grid point
                best[p, b], value[p, b] = refined, refined_value
    for b in range(4):
        if np.isfinite(margin[:, b]).any():
            winner = 0
            for p in range(1, peaks):
                if value[p, b] > value[winner, b]:
                    winner = p
            result[b] = best[winner, b]
    return result


@njit(cache=True)
def layout_signature() -> int:
    """The :data:`LAYOUT_SIGNATURE` this module was compiled with (numba freezes globals; its cache
    is keyed on this file alone, so a changed layouts.py shows here as another number)."""
    return LAYOUT_SIGNATURE
