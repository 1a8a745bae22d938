"""The avoidance zones' per-command check of ceilings, floors, walls, boxes and swing sectors,
compiled (numba): the hot path of :meth:`manipulator_kinematics.zones.Monitor.check`, whose numpy
code stays the reference (test/test_zones.py compares the two on random points and zones).

Why compiled: the check runs once per velocity-IK command (100 Hz and up) and its numpy form is
a hundred small array operations of about a microsecond each; the same steps as scalar loops
over the P points and K zones take a few microseconds. TIN surfaces stay in numpy (matplotlib's
point location). Kept in numba's on-disk cache (``cache=True``).

Per point and zone, the same steps as the numpy path (:mod:`manipulator_kinematics.zones`):
the clearance c and its gradient g (planes: n . p + b and n; boxes: the signed distance less the
margin and its direction; sectors: the arc to the nearer edge less the margin and the swing
tangent), the approach speed u = -g . v and the scale: 1 where u <= 0, else
2 max(c, 0) / (b + sqrt(b^2 + 4 a max(c, 0))) with a = u T / 2, b = u dt, at most 1.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True)
def _scale(c: float, u: float, stop_time: float, period: float) -> float:
    if u <= 0.0:
        return 1.0
    room = max(c, 0.0)
    a, b = 0.5 * stop_time * u, period * u
    return min(2.0 * room / (b + math.sqrt(b * b + 4.0 * a * room)), 1.0)


@njit(cache=True)
def check(
    p: np.ndarray,
    v: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    centre: np.ndarray,
    half: np.ndarray,
    box_margin: np.ndarray,
    start: np.ndarray,
    width: np.ndarray,
    sector_margin: np.ndarray,
    stop_time: float,
    period: float,
    c: np.ndarray,
    s: np.ndarray,
) -> None:
    """Clearances ``c`` and scales ``s`` (P, H + B + S), columns: the H planes, B boxes, S sectors."""
    n_planes, n_boxes = offsets.shape[0], box_margin.shape[0]
    for i in range(p.shape[0]):
        x, y, z = p[i, 0], p[i, 1], p[i, 2]
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]
        for k in range(n_planes):
            n = normals[k]
            ck = n[0] * x + n[1] * y + n[2] * z + offsets[k]
            c[i, k] = ck
            s[i, k] = _scale(ck, -(n[0] * vx + n[1] * vy + n[2] * vz), stop_time, period)
        for k in range(n_boxes):
            col = n_planes + k
            d0, d1, d2 = x - centre[k, 0], y - centre[k, 1], z - centre[k, 2]
            q0, q1, q2 = abs(d0) - half[k, 0], abs(d1) - half[k, 1], abs(d2) - half[k, 2]
            o0, o1, o2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
            distance = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
            if distance > 0.0:
                g0 = o0 * np.sign(d0) / distance
                g1 = o1 * np.sign(d1) / distance
                g2 = o2 * np.sign(d2) / distance
                ck = distance - box_margin[k]
            else:  # inside: out through the nearest face (the first of equals, as numpy's argmax)
                g0 = g1 = g2 = 0.0
                if q0 >= q1 and q0 >= q2:
                    g0, deepest = np.sign(d0), q0
                elif q1 >= q2:
                    g1, deepest = np.sign(d1), q1
                else:
                    g2, deepest = np.sign(d2), q2
                ck = min(deepest, 0.0) - box_margin[k]
            c[i, col] = ck
            s[i, col] = _scale(ck, -(g0 * vx + g1 * vy + g2 * vz), stop_time, period)
        r = math.hypot(x, y)
        bearing = math.atan2(y, x)
        for k in range(start.shape[0]):
            col = n_planes + n_boxes + k
            if not r > 1e-9:
                c[i, col], s[i, col] = np.inf, 1.0
                continue
            into = (bearing - start[k]) % TWO_PI
            inside = into <= width[k]
            past_end, before_start = into - width[k], TWO_PI - into
            if inside:
                nearer_end = width[k] - into < into
                angle = -min(into, width[k] - into)
            else:
                nearer_end = past_end < before_start
                angle = min(past_end, before_start)
            ck = r * angle - sector_margin[k]
            sign = 1.0 if nearer_end else -1.0
            c[i, col] = ck
            u = -sign * (-math.sin(bearing) * vx + math.cos(bearing) * vy)
            s[i, col] = _scale(ck, u, stop_time, period)


@njit(cache=True)
def surface(
    p: np.ndarray,
    v: np.ndarray,
    triangle: np.ndarray,
    planes: np.ndarray,
    origin: np.ndarray,
    sign: float,
    margin: float,
    stop_time: float,
    period: float,
    c: np.ndarray,
    s: np.ndarray,
    col: int,
) -> None:
    """Column ``col`` of ``c`` and ``s`` for a TIN: the points' located triangles ``triangle``
    (P,) (-1 off the TIN: clearance inf, scale 1), their planes [a, b, c] about ``origin``;
    ``sign`` 1 for ``side: below`` (the clearance is the height above), -1 for ``above``."""
    for i in range(p.shape[0]):
        t = triangle[i]
        if t < 0:
            c[i, col], s[i, col] = np.inf, 1.0
            continue
        a, b = planes[t, 0], planes[t, 1]
        height = p[i, 2] - origin[2] - (a * (p[i, 0] - origin[0]) + b * (p[i, 1] - origin[1]) + planes[t, 2])
        ck = sign * height - margin
        c[i, col] = ck
        s[i, col] = _scale(ck, -sign * (v[i, 2] - a * v[i, 0] - b * v[i, 1]), stop_time, period)
