"""The avoidance zones' per-command check of ceilings, floors, walls, boxes, swing sectors and TIN
surfaces, compiled (numba): the hot path of :meth:`manipulator_kinematics.zones.Monitor.check`,
whose numpy code stays the reference (test/test_zones.py and test/test_site_zones.py compare the
two on random points and zones).

Why compiled: the check runs once per velocity-IK command (100 Hz and up) and its numpy form is
a hundred small array operations of about a microsecond each; the same steps as scalar loops
over the P points and K zones take a few microseconds, in one call (each call of a compiled
function costs a microsecond or more in argument checks). A TIN's triangles under the points are
located before it by matplotlib's trapezoid map. Kept in numba's on-disk cache (``cache=True``).

Per point and zone, the same steps as the numpy path (:mod:`manipulator_kinematics.zones`):
the point in the zone's frame (the site pose's R p + t for a site-frame zone), the clearance c
and its gradient g (planes: n . p + b and n; boxes: the signed distance less the margin and its
direction; sectors: the arc to the nearer edge less the margin and the swing tangent; TINs: the
height above or below the triangle's plane less the margin and (-a, -b, 1)), the approach speed
u = -g . v and acceleration w = -g . a, the scale (:func:`scale`); then each zone's nearest point
and the smallest scale. The zones arrive as one table of the layout
:mod:`manipulator_kinematics.zone_layout` (declared once, packed by ``Monitor``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from manipulator_kinematics.zone_layout import KIND, SIGNATURE, ZONE

TWO_PI = 2.0 * math.pi


@njit(cache=True)
def layout_signature() -> int:
    """The layout this module was compiled with (:func:`zone_layout.check_compiled`)."""
    return SIGNATURE


@njit(cache=True, error_model="numpy", inline="always")
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


@njit(cache=True, error_model="numpy", inline="always")
def _pair(
    zones: np.ndarray,
    k: int,
    planes: np.ndarray,
    located: np.ndarray,
    i: int,
    x: float,
    y: float,
    z: float,
    vx: float,
    vy: float,
    vz: float,
    ax: float,
    ay: float,
    az: float,
) -> tuple[float, float, float]:
    """(c, u, w) of point ``i`` at (x, y, z), its velocity and acceleration (the zone's frame)
    against zone ``k`` (row k of the zone table)."""
    zone = zones[k]
    kind = int(zone[ZONE.kind])
    if kind == KIND.plane:
        n0, n1, n2 = zone[ZONE.normal], zone[ZONE.normal + 1], zone[ZONE.normal + 2]
        return (
            n0 * x + n1 * y + n2 * z + zone[ZONE.offset],
            -(n0 * vx + n1 * vy + n2 * vz),
            -(n0 * ax + n1 * ay + n2 * az),
        )
    if kind == KIND.box:
        d0, d1, d2 = x - zone[ZONE.centre], y - zone[ZONE.centre + 1], z - zone[ZONE.centre + 2]
        q0, q1, q2 = abs(d0) - zone[ZONE.half], abs(d1) - zone[ZONE.half + 1], abs(d2) - zone[ZONE.half + 2]
        o0, o1, o2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
        distance = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
        if distance > 0.0:
            g0, g1, g2 = o0 * np.sign(d0) / distance, o1 * np.sign(d1) / distance, o2 * np.sign(d2) / distance
            c = distance - zone[ZONE.margin]
        else:  # inside: out through the nearest face (the first of equals, as numpy's argmax)
            g0 = g1 = g2 = 0.0
            if q0 >= q1 and q0 >= q2:
                g0, deepest = np.sign(d0), q0
            elif q1 >= q2:
                g1, deepest = np.sign(d1), q1
            else:
                g2, deepest = np.sign(d2), q2
            c = min(deepest, 0.0) - zone[ZONE.margin]
        return c, -(g0 * vx + g1 * vy + g2 * vz), -(g0 * ax + g1 * ay + g2 * az)
    if kind == KIND.sector:
        r = math.hypot(x, y)
        if not r > 1e-9:
            return np.inf, 0.0, 0.0
        bearing = math.atan2(y, x)
        width = zone[ZONE.width]
        into = (bearing - zone[ZONE.start]) % TWO_PI
        if into <= width:  # inside
            nearer_end = width - into < into
            angle = -min(into, width - into)
        else:
            past_end, before_start = into - width, TWO_PI - into
            nearer_end = past_end < before_start
            angle = min(past_end, before_start)
        sign = 1.0 if nearer_end else -1.0
        t0, t1 = -y / r, x / r  # the swing tangent (-sin, cos) of the bearing
        return r * angle - zone[ZONE.margin], -sign * (t0 * vx + t1 * vy), -sign * (t0 * ax + t1 * ay)
    t = located[int(zone[ZONE.tin]), i]  # a TIN
    if t < 0:
        return np.inf, 0.0, 0.0
    row = int(zone[ZONE.first]) + t
    ta, tb, sign = planes[row, 0], planes[row, 1], zone[ZONE.sign]
    local_x, local_y = x - zone[ZONE.origin], y - zone[ZONE.origin + 1]
    height = z - zone[ZONE.origin + 2] - (ta * local_x + tb * local_y + planes[row, 2])
    return (
        sign * height - zone[ZONE.margin],
        -sign * (vz - ta * vx - tb * vy),
        -sign * (az - ta * ax - tb * ay),
    )


@njit(cache=True, error_model="numpy")
def check(
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    zones: np.ndarray,
    planes: np.ndarray,
    located: np.ndarray,
    site: np.ndarray,
    has_site: bool,
    u_flight: np.ndarray,
    delay: float,
    stop_time: float,
    period: float,
    c: np.ndarray,
    u: np.ndarray,
    s: np.ndarray,
    nearest: np.ndarray,
    least: np.ndarray,
) -> int:
    """Clearances ``c``, approach speeds ``u`` and scales ``s`` (P, K) of points ``p`` with
    velocities ``v`` and accelerations ``a`` (P, 3, base frame) against the ``zones`` (K rows of
    the zone table, module docstring) with the TINs' ``planes`` and ``located`` triangles; the
    site pose ``site`` (4, 3: R's rows, then t) where ``has_site`` (without it a site-frame zone
    is at clearance -inf and scale 0: no pose, no motion); ``u_flight`` (P, K) the command in
    force's approach speeds for ``delay``. Each zone's nearest point (the first of equals) into
    ``nearest`` (K,) and its clearance into ``least``; returns the flat index of the smallest
    scale (the first of equals)."""
    n_zones = zones.shape[0]
    smallest, limiting = np.inf, 0
    for i in range(p.shape[0]):
        x, y, z = p[i, 0], p[i, 1], p[i, 2]
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]
        ax, ay, az = a[i, 0], a[i, 1], a[i, 2]
        if has_site:  # the site frame's p_site = R p + t
            sx = site[0, 0] * x + site[0, 1] * y + site[0, 2] * z + site[3, 0]
            sy = site[1, 0] * x + site[1, 1] * y + site[1, 2] * z + site[3, 1]
            sz = site[2, 0] * x + site[2, 1] * y + site[2, 2] * z + site[3, 2]
            svx = site[0, 0] * vx + site[0, 1] * vy + site[0, 2] * vz
            svy = site[1, 0] * vx + site[1, 1] * vy + site[1, 2] * vz
            svz = site[2, 0] * vx + site[2, 1] * vy + site[2, 2] * vz
            sax = site[0, 0] * ax + site[0, 1] * ay + site[0, 2] * az
            say = site[1, 0] * ax + site[1, 1] * ay + site[1, 2] * az
            saz = site[2, 0] * ax + site[2, 1] * ay + site[2, 2] * az
        else:
            sx = sy = sz = svx = svy = svz = sax = say = saz = 0.0
        for k in range(n_zones):
            if zones[k, ZONE.site] == 0.0:
                ck, uk, wk = _pair(zones, k, planes, located, i, x, y, z, vx, vy, vz, ax, ay, az)
                sk = scale(ck, uk, wk, u_flight[i, k], delay, stop_time, period)
            elif has_site:
                ck, uk, wk = _pair(zones, k, planes, located, i, sx, sy, sz, svx, svy, svz, sax, say, saz)
                sk = scale(ck, uk, wk, u_flight[i, k], delay, stop_time, period)
            else:
                ck, uk, sk = -np.inf, 0.0, 0.0
            c[i, k], u[i, k], s[i, k] = ck, uk, sk
            if sk < smallest:  # s is in [0, 1]: the first pair sets it
                smallest, limiting = sk, i * n_zones + k
    for k in range(n_zones):
        best = 0
        for i in range(1, p.shape[0]):
            if c[i, k] < c[best, k]:
                best = i
        nearest[k], least[k] = best, c[best, k]
    return limiting
