"""The shared selection rule (:func:`manipulator_kinematics.model.select`) for ONE target, compiled
(numba): what every machine's single-target IK kernel calls, so that the rule is written twice in
the package, once as numpy (the reference) and once here, not once per machine.

Same answers as the numpy rule, edge cases included: a NaN distance (a NaN seed) selects the
first candidate with one (``np.argmin``'s NaN) and reports no tie; when every distance is inf (a
seed at infinity) the first valid candidate is selected.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from manipulator_kinematics.model import IKStatus

_SUCCESS = int(IKStatus.SUCCESS)  # globals are compile-time constants to numba


@njit(cache=True, error_model="numpy")
def select_one(
    q: np.ndarray,
    status: np.ndarray,
    seed: np.ndarray,
    seeded: bool,
    allowed: np.ndarray,
    weights: np.ndarray,
    tie_tolerance: float,
) -> tuple[int, bool]:
    """(selected, tie) of candidates q (m, n) with statuses (m,): of the SUCCESS candidates that
    ``allowed`` (m,) leaves, the first if not ``seeded``, else the nearest to ``seed`` (n,) in the
    ``weights`` (n,) scaled squared distance, ties within ``tie_tolerance`` reported."""
    m, n = q.shape
    first, chosen, first_nan = -1, -1, -1
    best = math.inf
    cost = np.full(m, math.inf)
    for b in range(m):
        if status[b] != _SUCCESS or not allowed[b]:
            continue
        if first < 0:
            first = b
            if not seeded:
                return b, False
        total = 0.0
        for j in range(n):
            d = (q[b, j] - seed[j]) * weights[j]
            total += d * d
        cost[b] = total
        if math.isnan(total):
            if first_nan < 0:
                first_nan = b
        elif total < best:
            chosen, best = b, total
    if first < 0:
        return -1, False
    if first_nan >= 0:
        return first_nan, False
    if chosen < 0:
        chosen = first
    near = 0
    for b in range(m):
        if status[b] == _SUCCESS and allowed[b] and cost[b] <= best * (1.0 + tie_tolerance) + tie_tolerance:
            near += 1
    return chosen, near > 1
