"""The SCARA's IK for ONE target, compiled (numba), and its loop over a batch of target poses
(``solve_ik_batch``, issue #32): the single-call hot path of
:meth:`scara_kinematics.kinematics.Scara.ik` in every mode (``solve_phi``: modes ``phi`` and
``fixed_phi``; ``solve_position``: mode ``position``), whose vectorised numpy code
(``Scara._solve_phi``, ``Scara._position_ik`` with ``Scara._candidate_headings``, and
:func:`manipulator_kinematics.model.select`) stays the reference; a test compares the two over
10^4 random targets per mode, failing statuses included.

Why compiled: one numpy call costs about a microsecond whatever its size, and the closed form with
its statuses and the selection rule is some sixty of them (about 60-80 us per call on 2 cores;
mode ``position``, 17 headings, about 200-300 us), against a target of half Robotics Toolbox's C++
``ik_LM`` on the same arm. Scalar code of the same steps, compiled once and kept in numba's
on-disk cache, takes a microsecond (a few in mode ``position``).

Same steps as the numpy path, same equation numbers. At one heading (``_heading``):

1. the wrist point w = p - l3 (cos phi, sin phi); sin theta1 = wy / l2 (eq. 12), reachable when
   |wy / l2| <= 1 (+ 1e-12); branch a theta1 = asin, branch b pi - asin kept in (-pi, pi];
2. x_l = wx - l1 - l2 cos theta1 (eq. 11), theta2 = phi - theta1 wrapped to [-pi, pi);
3. statuses as :func:`manipulator_kinematics.model.limit_status` (a candidate inside the limits
   widened by LIMIT_TOL is clipped to them), SINGULAR where |cos theta1| is below the threshold;
4. the selection as :func:`manipulator_kinematics.model.select` with weights (1 / l2, 1, 1).

Mode ``position`` (the rule of the kinematics module's docstring): the 17 candidate headings of
``Scara._candidate_headings`` in its order (the preferred one; wy at the singularity band and the
shoulder limits, both arcsin solutions; the elbow at a limit, the shoulder on the rail line on
either side of the tool; the rail at a stroke end, the planar two-link IK
:func:`manipulator_kinematics.planar.two_link_ik` from that shoulder, both elbows), steps 1-3 at
each, the admissible one (a SUCCESS branch that may answer) nearest the preferred heading (the
first of those within HEADING_TIE of the nearest; none: the preferred one), step 4 there, and the
target's outcome: the best status over every heading, UNREACHABLE read as JOINT_LIMITS within the
band |py| <= l2 + l3 (+ LIMIT_TOL) that an unbounded rail would reach.

The arm's constants arrive as one float array, ``Scara._packed``: l1, l2, l3, the limits widened
by LIMIT_TOL (lower 3, upper 3), the limits (lower 3, upper 3), the singularity threshold, the
seed weights (3), then mode ``position``'s: the wrist heights (4), the shoulder-to-tool distances^2
(2) and turns (2) at the elbow limits (``Scara._constraint_constants``), the band l2 + l3 + LIMIT_TOL,
HEADING_TIE.
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
def _wrap(angle: float) -> float:
    """planar.wrap_angle: to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, error_model="numpy")
def _heading(k: np.ndarray, px: float, py: float, phi: float, q: np.ndarray, status: np.ndarray) -> None:
    """Steps 1-3: both branches q (2, 3) and their statuses (2,) at heading phi."""
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


@njit(cache=True, error_model="numpy")
def _allowed(branch: int) -> np.ndarray:
    """(2,) the branches that may answer: the requested one (branch >= 0), else both."""
    allowed = np.full(2, branch < 0)
    if branch >= 0:
        allowed[branch] = True
    return allowed


@njit(cache=True, error_model="numpy")
def solve_phi(
    k: np.ndarray,
    px: float,
    py: float,
    phi: float,
    seed: np.ndarray,
    seeded: bool,
    branch: int,
    tie_tolerance: float,
    q: np.ndarray,
    status: np.ndarray,
) -> tuple[int, bool]:
    """Both branches q (2, 3) and their statuses (2,) at heading phi, then (selected, tie)."""
    _heading(k, px, py, phi, q, status)
    # The shared rule (model.select): a requested branch alone, else the nearest to the seed, else the first.
    return select_one(q, status, seed, seeded, _allowed(branch), k[16:19], tie_tolerance)


@njit(cache=True, error_model="numpy")
def _candidate_headings(k: np.ndarray, px: float, py: float, preferred: float) -> np.ndarray:
    """(17,) Scara._candidate_headings: the preferred heading, then every heading where a constraint
    is active (NaN where it cannot be), each wrapped to [-pi, pi)."""
    l1, l2, l3 = k[0], k[1], k[2]
    headings = np.empty(17)
    headings[0] = _wrap(preferred)
    for i in range(4):  # wy = py - l3 sin phi at the singularity band and the shoulder limits
        wrist = math.asin((py - k[19 + i]) / l3) if abs((py - k[19 + i]) / l3) <= 1.0 else math.nan
        headings[1 + i] = _wrap(wrist)
        headings[5 + i] = _wrap(math.pi - wrist)
    for i in range(4):  # elbow at a limit: the shoulder at distance r from p on the rail line y = 0
        side = 1.0 if i < 2 else -1.0
        dx = math.sqrt(k[23 + i % 2] - py * py) if k[23 + i % 2] - py * py >= 0.0 else math.nan
        headings[9 + i] = _wrap(math.atan2(py, side * dx) + k[25 + i % 2])
    for end in range(2):  # rail at a stroke end: planar.two_link_ik (links l2, l3, tol 1e-12) from there
        x = px - l1 - k[9 + 3 * end]
        r = math.hypot(x, py)
        ok = abs(l2 - l3) - 1e-12 <= r <= l2 + l3 + 1e-12  # False for a NaN r
        cos2 = min(max((r * r - l2 * l2 - l3 * l3) / (2.0 * l2 * l3), -1.0), 1.0)
        t2 = math.acos(cos2) if ok else math.nan
        for elbow in range(2):
            theta2 = t2 if elbow == 0 else -t2
            theta1 = math.atan2(py, x) - math.atan2(l3 * math.sin(theta2), l2 + l3 * math.cos(theta2))
            headings[13 + 2 * end + elbow] = _wrap(theta1 + theta2)
    return headings


@njit(cache=True, error_model="numpy")
def solve_position(
    k: np.ndarray,
    px: float,
    py: float,
    preferred: float,
    seed: np.ndarray,
    seeded: bool,
    branch: int,
    tie_tolerance: float,
    q: np.ndarray,
    status: np.ndarray,
) -> tuple[float, int, bool, int]:
    """Mode position: (phi, selected, tie, outcome), with both branches q (2, 3) and their statuses
    (2,) at the admissible heading phi nearest ``preferred`` (none admissible: the preferred one)."""
    allowed = _allowed(branch)
    headings = _candidate_headings(k, px, py, preferred)
    q_h, status_h, distance = np.empty((17, 2, 3)), np.empty((17, 2), dtype=np.int8), np.empty(17)
    nearest, outcome = math.inf, _INVALID
    for h in range(17):
        _heading(k, px, py, headings[h], q_h[h], status_h[h])
        admissible = False
        for b in range(2):
            if allowed[b]:
                outcome = min(outcome, status_h[h, b])
                admissible = admissible or status_h[h, b] == _SUCCESS
        distance[h] = abs(_wrap(headings[h] - preferred)) if admissible else math.inf
        nearest = min(nearest, distance[h])
    # The first as near as the nearest within Scara's HEADING_TIE; none admissible (all inf): the preferred.
    h = 0
    while not distance[h] <= nearest + k[28]:
        h += 1
    q[:] = q_h[h]
    status[:] = status_h[h]
    # With the rail unbounded every |py| <= l2 + l3 is reachable: if no candidate reached it, the
    # rail's stroke (a joint limit) is what stops it.
    if outcome == _UNREACHABLE and abs(py) <= k[27]:
        outcome = _LIMITS
    selected, tie = select_one(q, status, seed, seeded, allowed, k[16:19], tie_tolerance)
    return headings[h], selected, tie, outcome


@njit(cache=True, error_model="numpy")
def solve_ik_batch(
    k: np.ndarray,
    T: np.ndarray,
    seeds: np.ndarray,
    seeded: bool,
    branch: int,
    tie_tolerance: float,
    mode: int,
    oriented: bool,
    paper_phi: float,
    plane_tol: float,
    q: np.ndarray,
    status: np.ndarray,
    selected: np.ndarray,
    tie: np.ndarray,
) -> int:
    """``Scara.solve_ik`` of every target pose T (N, 4, 4), mode 0 ``fixed_phi``, 1 ``phi``, 2
    ``position``, seeds (N, 3) or (1, 3) for every target (read if ``seeded``), the steps of
    ``Scara._solve_ik_one`` and ``Scara._kernel_one``: both branches q (N, 2, 3) and their statuses
    (N, 2) as answered, selected (int8) and tie (N,). Returns -1, or the index of the first finite
    target of mode ``fixed_phi`` whose heading is not ``paper_phi`` (the caller refuses the
    request)."""
    last = seeds.shape[0] - 1
    found = np.empty(2, dtype=np.int8)
    for i in range(T.shape[0]):
        t = T[i]
        finite = True
        for r in range(4):
            for c in range(4):
                finite = finite and math.isfinite(t[r, c])
        x, y, z = t[0, 3], t[1, 3], t[2, 3]
        heading = math.atan2(t[1, 0], t[0, 0])
        if mode == 0 and oriented and finite and abs(_wrap(heading - paper_phi)) > plane_tol:
            return i
        seed = seeds[min(i, last)]
        if mode == 2:
            preferred = _wrap(seed[1] + seed[2]) if seeded else paper_phi
            _, chosen, near, _ = solve_position(
                k, x, y, preferred, seed, seeded, branch, tie_tolerance, q[i], found
            )
        else:
            phi = _wrap(heading) if mode == 1 else paper_phi
            chosen, near = solve_phi(k, x, y, phi, seed, seeded, branch, tie_tolerance, q[i], found)
        # solve_ik's refusals: a target off the plane or tilted (UNREACHABLE), one not finite (INVALID).
        refused = finite and (
            abs(z) > plane_tol or (oriented and math.acos(min(max(t[2, 2], -1.0), 1.0)) > plane_tol)
        )
        for b in range(2):
            status[i, b] = _INVALID if not finite else _UNREACHABLE if refused else found[b]
        if branch >= 0:  # the other branch is no solution of this request
            status[i, 1 - branch] = max(status[i, 1 - branch], _LIMITS)
        answered = finite and not refused
        selected[i] = chosen if answered else -1
        tie[i] = answered and near
    return -1
