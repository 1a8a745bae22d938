"""The excavator's forward kinematics for ONE state, compiled (numba), and its loops over a
batch (``states``, ``poses``, issue #32): the single-call hot path of
:class:`excavator_kinematics.core.kinematics.Excavator` (``state``, ``pose``, ``jc0``), whose
vectorised numpy code stays the reference (a test compares the two over 10^4 random states, out
of stroke included).

Why compiled: one numpy call costs about a microsecond whatever its size, and the full state is
some 150 of them; a node at 1 kHz calls it once per message. Scalar code of the same steps,
compiled once and kept in numba's on-disk cache (``cache=True``), takes well under one.

Same steps and equation numbers as the numpy path (``Excavator._linkages``, ``_chain_terms``,
``_state_columns``):

1. boom and arm triangles, eq. 1: cos gamma = c0 - c1 d^2, theta = offset + o gamma, k = dtheta/dd
   (eq. 7's K) and dk = d2theta/dd2 (K1), cos/sin theta by angle addition;
2. the bucket six-bar, eq. 2: the cylinder four-bar (side-link triangle, eq. 1's form) gives the
   rod pin R, the bucket four-bar the H-link pin H and theta4 with its ratios g1, g2;
3. eq. 4's coefficients a_i, b_i, the tip Q (eq. 3), Qdot = JC0 Ddot (eqs. 5, 7, 8) and Qddot
   (eqs. 10-11).

The machine's constants arrive as one float array, ``Excavator.packed``, of the layout
:data:`excavator_kinematics.core.layouts.STATE` (declared once, packed by name, read here by
offset). Each function returns False, writing nothing
valid, for a state outside the limits (with the stroke tolerance), not finite, or whose linkage
cannot close: the caller then takes the numpy path, which raises the error naming the cause.
"""

from __future__ import annotations

import math
import zlib

import numpy as np
from numba import njit

from excavator_kinematics.core.layouts import FOUR_BAR, STATE, TRIANGLE

# Offsets into the packed constants (Excavator.packed), the triangles' and the four-bar's within
# theirs: compile-time constants to numba (layouts.py).
_K, _T, _F = STATE.at, TRIANGLE.at, FOUR_BAR.at
#: The layouts this module reads; :func:`layout_signature` returns the one it was compiled with.
LAYOUT_SIGNATURE = zlib.crc32(repr((STATE.signature, TRIANGLE.signature, FOUR_BAR.signature)).encode())
# What _linkages returns where a linkage cannot close: refused, the rest never read.
_NOTHING = (False, *(0.0,) * 15)


@njit(cache=True, error_model="numpy")
def _closes(k: np.ndarray, at: int, d: float) -> tuple[bool, float, float, float, float, float]:
    """Eq. 1 for the triangle at ``k[at:]`` (layouts.TriangleConstants): (closes, theta,
    dtheta/dd, d2theta/dd2, radius cos theta, radius sin theta)."""
    c0, c1, ab, o = k[at + _T.c0], k[at + _T.c1], k[at + _T.ab], k[at + _T.o]
    cd, sd, offset = k[at + _T.cos_offset], k[at + _T.sin_offset], k[at + _T.offset]
    c = c0 - c1 * d * d
    if not -1.0 < c < 1.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0
    s = o * math.sqrt(1.0 - c * c)  # sin(o gamma)
    kd = d / (ab * s)
    return True, offset + o * math.acos(c), kd, kd / d - kd * kd * c / s, cd * c - sd * s, sd * c + cd * s


@njit(cache=True, error_model="numpy")
def _linkages(k: np.ndarray, d2: float, d3: float, d4: float) -> tuple:
    """Eqs. 1-2: (closes, theta2..4, k2..4, dk2..4, cos/sin theta2..4) as
    ``kinematics.Excavator._linkages``."""
    ok2, t2, k2, dk2, c2, s2 = _closes(k, _K.boom, d2)
    ok3, t3, k3, dk3, c3, s3 = _closes(k, _K.arm, d3)
    ok4, _, phi_d, phi_dd, rx, ry = _closes(k, _K.side, d4)  # the side link (Fig. 7b)
    if not (ok2 and ok3 and ok4):
        return _NOTHING
    ex, ey = k[_K.pivot_from_bucket_pin] + rx, k[_K.pivot_from_bucket_pin + 1] + ry  # R - bucket pin
    h = _K.four_bar
    b, bb, o, b2_a2, two_b = k[h + _F.b], k[h + _F.bb], k[h + _F.o], k[h + _F.bb_aa], k[h + _F.two_b]
    cp, sp = k[h + _F.cos_phase], k[h + _F.sin_phase]
    e2 = ex * ex + ey * ey
    e = math.sqrt(e2)
    ch = (e2 + b2_a2) / (two_b * e)
    if not -1.0 < ch < 1.0:
        return _NOTHING
    sh = o * math.sqrt(1.0 - ch * ch)
    f = b / e
    fc, fs = f * ch, f * sh
    ox, oy = fc * ex - fs * ey, fc * ey + fs * ex  # H - bucket pin
    t4 = math.atan2(ey, ex) + o * math.acos(ch) - k[h + _F.phase]
    c4, s4 = ox * cp + oy * sp, oy * cp - ox * sp
    cx, cy = ox - ex, oy - ey  # H - R
    den = fs * e2
    g1 = (cy * rx - cx * ry) / den
    wx, wy = g1 * ox - rx, g1 * oy - ry
    g2 = (g1 * g1 * (bb - fc * e2) - (cx * rx + cy * ry) - (wx * wx + wy * wy)) / den
    return (
        True,
        t2,
        t3,
        t4,
        k2,
        k3,
        g1 * phi_d,
        dk2,
        dk3,
        g2 * phi_d * phi_d + g1 * phi_dd,
        c2,
        s2,
        c3,
        s3,
        c4,
        s4,
    )


@njit(cache=True, error_model="numpy")
def _chain_terms(
    k: np.ndarray, c2: float, s2: float, c3: float, s3: float, c4: float, s4: float
) -> tuple[float, float, float, float, float, float]:
    """Eq. 4's a1..a3, b1..b3 (``kinematics.Excavator._chain_terms``)."""
    l2, l3, l4 = k[_K.l2], k[_K.l3], k[_K.l4]
    c23, s23 = c2 * c3 - s2 * s3, s2 * c3 + c2 * s3
    c234, s234 = c23 * c4 - s23 * s4, s23 * c4 + c23 * s4
    a3, b3 = l4 * s234, l4 * c234
    a2, b2 = l3 * s23 + a3, l3 * c23 + b3
    return l2 * s2 + a2, a2, a3, l2 * c2 + b2, b2, b3


@njit(cache=True, error_model="numpy")
def _inside(k: np.ndarray, D: np.ndarray) -> bool:
    """D of four values within the limits widened by the stroke tolerance (NaN fails)."""
    if D.shape[0] != 4:
        return False
    for i in range(4):  # noqa: SIM110 (numba compiles no generator expressions)
        if not k[_K.lower + i] <= D[i] <= k[_K.upper + i]:
            return False
    return True


@njit(cache=True, error_model="numpy")
def _chain(k: np.ndarray, D: np.ndarray) -> tuple:
    """(valid, theta2..4, k2..4, dk2..4, a1..a3, b1..b3) of D: valid when D is inside the
    limits and its linkages close (eqs. 1-2, 4, 7)."""
    ok, t2, t3, t4, k2, k3, k4, dk2, dk3, dk4, c2, s2, c3, s3, c4, s4 = (
        _linkages(k, D[1], D[2], D[3]) if _inside(k, D) else _NOTHING
    )
    a1, a2, a3, b1, b2, b3 = _chain_terms(k, c2, s2, c3, s3, c4, s4)
    return ok, t2, t3, t4, k2, k3, k4, dk2, dk3, dk4, a1, a2, a3, b1, b2, b3


@njit(cache=True, error_model="numpy")
def pose(k: np.ndarray, D: np.ndarray, out: np.ndarray) -> bool:
    """Q = [x, y, z, alpha] (eqs. 1-3) into ``out`` (4,)."""
    ok, t2, t3, t4, _, _, _, _, _, _, a1, _, _, b1, _, _ = _chain(k, D)
    rho = k[_K.l1] + b1
    out[0], out[1], out[2], out[3] = rho * math.cos(D[0]), rho * math.sin(D[0]), k[_K.l0] + a1, t2 + t3 + t4
    return ok


@njit(cache=True, error_model="numpy")
def jc0(k: np.ndarray, D: np.ndarray, out: np.ndarray) -> bool:
    """JC0 = J0 K (eq. 8) into ``out`` (4, 4)."""
    ok, _, _, _, k2, k3, k4, _, _, _, a1, a2, a3, b1, b2, b3 = _chain(k, D)
    _jc0(k[_K.l1] + b1, math.cos(D[0]), math.sin(D[0]), a1, a2, a3, b1, b2, b3, k2, k3, k4, out, 0)
    return ok


@njit(cache=True, error_model="numpy")
def _jc0(
    rho: float,
    c1: float,
    s1: float,
    a1: float,
    a2: float,
    a3: float,
    b1: float,
    b2: float,
    b3: float,
    k2: float,
    k3: float,
    k4: float,
    out: np.ndarray,
    row: int,
) -> None:
    """JC0 = J0 K (eqs. 5, 7, 8) into out[row:row + 4]; column 1 is theta1 itself (k1 = 1)."""
    r2, r3, r4 = a1 * k2, a2 * k3, a3 * k4
    _put(out, row, -s1 * rho, -c1 * r2, -c1 * r3, -c1 * r4)
    _put(out, row + 1, c1 * rho, -s1 * r2, -s1 * r3, -s1 * r4)
    _put(out, row + 2, 0.0, b1 * k2, b2 * k3, b3 * k4)
    _put(out, row + 3, 0.0, k2, k3, k4)


@njit(cache=True, error_model="numpy")
def _put(out: np.ndarray, row: int, a: float, b: float, c: float, d: float) -> None:
    out[row, 0], out[row, 1], out[row, 2], out[row, 3] = a, b, c, d


# Inlined into states too: a call of a compiled function from another costs about 0.07 us, a
# tenth of the single call (issue #32: a batch of one no dearer than one call).
@njit(cache=True, error_model="numpy", inline="always")
def state(k: np.ndarray, D: np.ndarray, D_dot: np.ndarray, D_ddot: np.ndarray, out: np.ndarray) -> bool:
    """The BucketState table into ``out`` (10, 4): theta, theta_dot, theta_ddot, Q, Q_dot, Q_ddot,
    then JC0's rows (eqs. 1-11, as ``kinematics.Excavator._state_columns``)."""
    if not (D_dot.shape[0] == 4 and D_ddot.shape[0] == 4):
        return False
    for i in range(4):
        if not (math.isfinite(D_dot[i]) and math.isfinite(D_ddot[i])):
            return False
    ok, t2, t3, t4, k2, k3, k4, dk2, dk3, dk4, a1, a2, a3, b1, b2, b3 = _chain(k, D)
    if not ok:
        return False
    t1, w1, e1 = D[0], D_dot[0], D_ddot[0]
    v2, v3, v4, f2, f3, f4 = D_dot[1], D_dot[2], D_dot[3], D_ddot[1], D_ddot[2], D_ddot[3]
    rho, c1, s1 = k[_K.l1] + b1, math.cos(t1), math.sin(t1)
    # thetadot = K Ddot (eq. 7); thetaddot = K Dddot + K1 Ddot^2.
    w2, w3, w4 = k2 * v2, k3 * v3, k4 * v4
    e2, e3, e4 = k2 * f2 + dk2 * v2 * v2, k3 * f3 + dk3 * v3 * v3, k4 * f4 + dk4 * v4 * v4
    # Eqs. 8 and 10 in the boom plane, each link's centripetal term from eq. 4's coefficients.
    o23 = w2 + w3
    alpha_dot = o23 + w4
    q2, q23, q234 = w2 * w2, o23 * o23, alpha_dot * alpha_dot
    rho_dot, z_dot = -(a1 * w2 + a2 * w3 + a3 * w4), b1 * w2 + b2 * w3 + b3 * w4
    rho_ddot = -(a1 * e2 + a2 * e3 + a3 * e4 + (b1 - b2) * q2 + (b2 - b3) * q23 + b3 * q234)
    z_ddot = b1 * e2 + b2 * e3 + b3 * e4 - ((a1 - a2) * q2 + (a2 - a3) * q23 + a3 * q234)
    # x, y = rho (cos, sin) theta1, turned by the swing.
    x, y = rho * c1, rho * s1
    radial = rho_ddot - rho * w1 * w1
    tangential = 2.0 * rho_dot * w1 + rho * e1
    _put(out, 0, t1, t2, t3, t4)
    _put(out, 1, w1, w2, w3, w4)
    _put(out, 2, e1, e2, e3, e4)
    _put(out, 3, x, y, k[_K.l0] + a1, t2 + t3 + t4)
    _put(out, 4, rho_dot * c1 - y * w1, rho_dot * s1 + x * w1, z_dot, alpha_dot)
    _put(out, 5, c1 * radial - s1 * tangential, s1 * radial + c1 * tangential, z_ddot, e2 + e3 + e4)
    _jc0(rho, c1, s1, a1, a2, a3, b1, b2, b3, k2, k3, k4, out, 6)
    return True


@njit(cache=True, error_model="numpy")
def states(k: np.ndarray, D: np.ndarray, D_dot: np.ndarray, D_ddot: np.ndarray, out: np.ndarray) -> bool:
    """:func:`state` of every row of a batch D (N, 4) with rates and accelerations (N, 4), or (1,
    4) for all rows, into ``out`` (10, N, 4): BucketState's rows, so nothing is copied or
    transposed after; False (from the first state refused on) for rates of another shape or a
    state refused (the caller's numpy path then says why)."""
    n = D.shape[0]
    if n == 1 and D_dot.shape[0] == 1 and D_ddot.shape[0] == 1:
        # The single state's straight line (state checks the row lengths): the checks and the
        # loop below cost 0.05-0.1 us, 7 % of a batch of one (issue #32).
        return state(k, D[0], D_dot[0], D_ddot[0], out[:, 0])
    if D.shape[1] != 4 or D_dot.shape[0] not in (1, n) or D_ddot.shape[0] not in (1, n):
        return False
    last_rate, last_acceleration = D_dot.shape[0] - 1, D_ddot.shape[0] - 1
    for i in range(n):
        if not state(k, D[i], D_dot[min(i, last_rate)], D_ddot[min(i, last_acceleration)], out[:, i]):
            return False
    return True


@njit(cache=True, error_model="numpy")
def poses(k: np.ndarray, D: np.ndarray, out: np.ndarray) -> bool:
    """:func:`pose` of every row of a batch D (N, 4) into ``out`` (N, 4); False as soon as one
    state is refused (the caller's numpy path then says why)."""
    i = 0
    while i < D.shape[0] and pose(k, D[i], out[i]):
        i += 1
    return i == D.shape[0]


@njit(cache=True, error_model="numpy")
def bucket_quaternion(theta1: float, alpha: float, out: np.ndarray) -> None:
    """kinematics.bucket_quaternion of one swing angle and bucket angle into ``out`` (4,)."""
    cy, sy = math.cos(0.5 * theta1), math.sin(0.5 * theta1)
    cp, sp = math.cos(0.5 * alpha), -math.sin(0.5 * alpha)
    out[0], out[1], out[2], out[3] = -sy * sp, cy * sp, sy * cp, cy * cp


@njit(cache=True, error_model="numpy")
def bucket_angular_velocity(theta1: float, theta1_dot: float, alpha_dot: float, out: np.ndarray) -> None:
    """kinematics.bucket_angular_velocity of one state into ``out`` (3,)."""
    out[0], out[1], out[2] = alpha_dot * math.sin(theta1), -alpha_dot * math.cos(theta1), theta1_dot


@njit(cache=True, error_model="numpy")
def bucket_angular_acceleration(
    theta1: float, w: float, w_dot: float, a_dot: float, a_ddot: float, out: np.ndarray
) -> None:
    """kinematics.bucket_angular_acceleration of one state into ``out`` (3,)."""
    c, s = math.cos(theta1), math.sin(theta1)
    out[0], out[1], out[2] = a_ddot * s + a_dot * w * c, -a_ddot * c + a_dot * w * s, w_dot


@njit(cache=True)
def layout_signature() -> int:
    """The :data:`LAYOUT_SIGNATURE` this module was compiled with (numba freezes globals; its cache
    is keyed on this file alone, so a changed layouts.py shows here as another number)."""
    return LAYOUT_SIGNATURE
