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
tangent), the approach speed u = -g . v and acceleration w = -g . a (:func:`geometry`,
:func:`surface`), then the scale (:func:`scales`, :func:`scale`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True)
def scale(
    c: float, u: float, w: float, u_flight: float, delay: float, stop_time: float, period: float
) -> float:
    """The largest s in [0, 1] for one pair (:func:`manipulator_kinematics.zones.scale_for`)."""
    room = c - max(u_flight, 0.0) * delay
    if room <= 0.0:
        return 1.0 if u <= 0.0 else 0.0
    disc = u * u + 2.0 * w * room
    if (w <= 0.0 and u <= 0.0) or disc < 0.0:
        return 1.0
    reach = 2.0 * room / (u + math.sqrt(disc))
    return min(2.0 * reach / (period + math.sqrt(period * period + 2.0 * stop_time * reach)), 1.0)


@njit(cache=True)
def scales(
    c: np.ndarray,
    u: np.ndarray,
    w: np.ndarray,
    u_flight: np.ndarray,
    delay: float,
    stop_time: float,
    period: float,
    s: np.ndarray,
) -> None:
    """Scales ``s`` (P, K) of every pair (:func:`scale`)."""
    for i in range(c.shape[0]):
        for k in range(c.shape[1]):
            s[i, k] = scale(c[i, k], u[i, k], w[i, k], u_flight[i, k], delay, stop_time, period)


@njit(cache=True)
def geometry(
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    centre: np.ndarray,
    half: np.ndarray,
    box_margin: np.ndarray,
    start: np.ndarray,
    width: np.ndarray,
    sector_margin: np.ndarray,
    c: np.ndarray,
    u: np.ndarray,
    w: np.ndarray,
) -> None:
    """Clearances ``c``, approach speeds ``u`` and accelerations ``w`` (P, H + B + S), columns:
    the H planes, B boxes, S sectors."""
    n_planes, n_boxes = offsets.shape[0], box_margin.shape[0]
    for i in range(p.shape[0]):
        x, y, z = p[i, 0], p[i, 1], p[i, 2]
        for k in range(n_planes):
            n = normals[k]
            c[i, k] = n[0] * x + n[1] * y + n[2] * z + offsets[k]
            u[i, k] = -(n[0] * v[i, 0] + n[1] * v[i, 1] + n[2] * v[i, 2])
            w[i, k] = -(n[0] * a[i, 0] + n[1] * a[i, 1] + n[2] * a[i, 2])
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
            u[i, col] = -(g0 * v[i, 0] + g1 * v[i, 1] + g2 * v[i, 2])
            w[i, col] = -(g0 * a[i, 0] + g1 * a[i, 1] + g2 * a[i, 2])
        r = math.hypot(x, y)
        bearing = math.atan2(y, x)
        for k in range(start.shape[0]):
            col = n_planes + n_boxes + k
            if not r > 1e-9:
                c[i, col], u[i, col], w[i, col] = np.inf, 0.0, 0.0
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
            sign = 1.0 if nearer_end else -1.0
            t0, t1 = -math.sin(bearing), math.cos(bearing)
            c[i, col] = r * angle - sector_margin[k]
            u[i, col] = -sign * (t0 * v[i, 0] + t1 * v[i, 1])
            w[i, col] = -sign * (t0 * a[i, 0] + t1 * a[i, 1])


@njit(cache=True)
def surface(
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    triangle: np.ndarray,
    planes: np.ndarray,
    origin: np.ndarray,
    sign: float,
    margin: float,
    c: np.ndarray,
    u: np.ndarray,
    w: np.ndarray,
    col: int,
) -> None:
    """Column ``col`` of ``c``, ``u`` and ``w`` for a TIN: the points' located triangles
    ``triangle`` (P,) (-1 off the TIN: clearance inf, not approached), their planes [a, b, c]
    about ``origin``; ``sign`` 1 for ``side: below`` (the clearance is the height above), -1 for
    ``above``."""
    for i in range(p.shape[0]):
        t = triangle[i]
        if t < 0:
            c[i, col], u[i, col], w[i, col] = np.inf, 0.0, 0.0
            continue
        ta, tb = planes[t, 0], planes[t, 1]
        height = (
            p[i, 2] - origin[2] - (ta * (p[i, 0] - origin[0]) + tb * (p[i, 1] - origin[1]) + planes[t, 2])
        )
        c[i, col] = sign * height - margin
        u[i, col] = -sign * (v[i, 2] - ta * v[i, 0] - tb * v[i, 1])
        w[i, col] = -sign * (a[i, 2] - ta * a[i, 0] - tb * a[i, 1])
