"""The hydraulic family's forward kinematics for ONE state, compiled (numba): the single-call hot
path of :class:`manipulator_kinematics.hydraulic.model.HydraulicModel` (``state``, ``pose``,
``jc0``, ``cylinder_rates``, and ``monitored_motion``: the avoidance zones' points, every
velocity-IK command) for any machine file, whose vectorised numpy code stays the reference
(a test compares the two for every shipped machine; ``MK_COMPILED=0`` keeps the numpy path).

Why compiled: the numpy core runs some 300-600 small array operations per state whatever the
batch (a microsecond each); a node at 1 kHz calls it once per message. This module runs the same
steps as scalar loops: the machine's plan, packed once into a program
(:mod:`manipulator_kinematics.hydraulic.program`, layout :mod:`manipulator_kinematics.hydraulic.layout`),
is interpreted instruction by instruction on jets held in one work array: per slot its position,
velocity, acceleration and Jacobian d/dD (rows :data:`_P`, :data:`_V`, :data:`_A`, then
:data:`_J` + j), each a point (two components) or a scalar (the first). The formulas are those
of the numpy path: dyads (eqs. 1-2, implicit differentiation of the loop closures,
:mod:`manipulator_kinematics.hydraulic.dyads`), ``HydraulicModel._place``, ``_slide``,
``_Body.point``, ``_joints`` and ``_task`` (eq. 3; eqs. 7-8 and 10-11 through the jets), with
one difference in how a body's angle is held: as its cosine and sine (row :data:`_T`), made from
the placing pins' direction and the packed cos/sin of the body's own (no atan2, cos and sin per
placed body, a fifth of a state's compute), its value only where a joint angle needs it
(theta = atan2 of the child's turn relative to the parent, in (-pi, pi] as numpy's wrap). The
results agree with the numpy path to rounding (1e-12, test/test_hydraulic_kernel.py).

Each instruction writes every row of its slot that a call of its order reads (no slot is
cleared first), and a batch makes one work array for all its states. The instructions' helpers
are inlined into the interpreter (``inline="always"``: numba inlines them before LLVM sees them;
left as calls, with the work array and D, D_dot, D_ddot passed to each, the full state took a
quarter longer; docs/hydraulic_family.md, "Speed"). The interpreter is inlined into its callers
too (the single calls and their batch loops, and ``monitored`` since issue 34), a tenth of the
compute and issue 31's 2x target, for a cold compile several times longer (about 100 s of CPU
with five callers, was 22; the later callers add their share, not measured apart;
scripts/warm_kernels.py does it at set-up).

Each function returns False, writing nothing valid, for a state outside the stroke box (faces
included), not finite, of the wrong length, or where a dyad does not close: the caller then takes
the numpy path, which raises the error naming the actuator (or gives NaN where it always did).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from manipulator_kinematics.hydraulic.layout import FLOAT, INT, OP, POINT, SIGNATURE

# Rows of one slot of the work array: value, rate, acceleration, (cos, sin) of an angle (each
# body's, made once where it is placed: its points and slides turn by it), then d/dD_j at _J + j.
_P, _V, _A, _T, _J = 0, 1, 2, 3, 4
# How much a call computes: positions; with the Jacobians; with rates and accelerations too.
POSITION, JACOBIAN, MOTION = 0, 1, 2
#: A scalar jet: value, rate, acceleration (an actuator's, or a constant's).
Scalar = tuple[float, float, float]


@njit(cache=True)
def layout_signature() -> int:
    """The layout this module was compiled with (:func:`layout.check_compiled`)."""
    return SIGNATURE


@njit(cache=True, error_model="numpy", inline="always")
def _inside(code: np.ndarray, values: np.ndarray, D: np.ndarray) -> bool:
    """D of m values, each within its stroke box (the ``limit`` rows; NaN fails)."""
    if D.shape[0] != code[0, INT.act2]:
        return False
    for i in range(D.shape[0]):  # noqa: SIM110 (numba compiles no generator expressions)
        if not values[1 + i, FLOAT.x] <= D[i] <= values[1 + i, FLOAT.z]:
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _finite(x: np.ndarray, m: int) -> bool:
    """x of m finite values."""
    if x.shape[0] != m:
        return False
    for i in range(m):  # noqa: SIM110
        if not math.isfinite(x[i]):
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _fixed(w: np.ndarray, out: int, x: float, z: float, m: int, order: int) -> None:
    """A constant: value (x, z), every derivative zero; as an angle (the ground's), zero."""
    w[out, _P, 0], w[out, _P, 1] = x, z
    w[out, _T, 0], w[out, _T, 1] = 1.0, 0.0
    if order >= JACOBIAN:
        for j in range(m):
            w[out, _J + j, 0], w[out, _J + j, 1] = 0.0, 0.0
    if order >= MOTION:
        w[out, _V, 0], w[out, _V, 1], w[out, _A, 0], w[out, _A, 1] = 0.0, 0.0, 0.0, 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _actuator(w: np.ndarray, out: int, act: int, d: Scalar, m: int, order: int) -> None:
    """The scalar jet ``d`` of actuator ``act`` (``HydraulicModel._solve``'s ``actuator``)."""
    w[out, _P, 0] = d[0]
    if order >= JACOBIAN:
        for j in range(m):
            w[out, _J + j, 0] = 1.0 if j == act else 0.0
    if order >= MOTION:
        w[out, _V, 0], w[out, _A, 0] = d[1], d[2]


@njit(cache=True, error_model="numpy", inline="always")
def _dyad(
    w: np.ndarray,
    out: int,
    a: int,
    b: int,
    act_a: int,
    act_b: int,
    radius_a: Scalar,
    radius_b: Scalar,
    sign: float,
    m: int,
    order: int,
) -> bool:
    """X = circle(A, r_a) with circle(B, r_b) on the side ``sign`` (dyads.intersect), its Jacobian
    and rate (dyads.rates) and acceleration (dyads.second_rates); False where it does not close.
    Each radius an actuator's (index >= 0) or fixed, as a scalar jet."""
    ax, az, bx, bz = w[a, _P, 0], w[a, _P, 1], w[b, _P, 0], w[b, _P, 1]
    ra, ra_v, ra_a = radius_a
    rb, rb_v, rb_a = radius_b
    dx, dz = bx - ax, bz - az
    dist2 = dx * dx + dz * dz
    along = (ra * ra - rb * rb + dist2) / (2.0 * dist2)
    h2 = ra * ra / dist2 - along * along
    if not h2 > 0.0:
        return False
    height = sign * math.sqrt(h2)
    x, z = ax + along * dx + height * -dz, az + along * dz + height * dx
    w[out, _P, 0], w[out, _P, 1] = x, z
    if order < JACOBIAN:
        return True
    u0, u1, v0, v1 = x - ax, z - az, x - bx, z - bz
    det = u0 * v1 - u1 * v0
    for j in range(m):
        rhs_a = u0 * w[a, _J + j, 0] + u1 * w[a, _J + j, 1] + ra * (1.0 if j == act_a else 0.0)
        rhs_b = v0 * w[b, _J + j, 0] + v1 * w[b, _J + j, 1] + rb * (1.0 if j == act_b else 0.0)
        w[out, _J + j, 0] = (v1 * rhs_a - u1 * rhs_b) / det
        w[out, _J + j, 1] = (u0 * rhs_b - v0 * rhs_a) / det
    if order < MOTION:
        return True
    rhs_a = u0 * w[a, _V, 0] + u1 * w[a, _V, 1] + ra * ra_v
    rhs_b = v0 * w[b, _V, 0] + v1 * w[b, _V, 1] + rb * rb_v
    xv, zv = (v1 * rhs_a - u1 * rhs_b) / det, (u0 * rhs_b - v0 * rhs_a) / det
    w[out, _V, 0], w[out, _V, 1] = xv, zv
    e0, e1, f0, f1 = xv - w[a, _V, 0], zv - w[a, _V, 1], xv - w[b, _V, 0], zv - w[b, _V, 1]
    rhs_a = u0 * w[a, _A, 0] + u1 * w[a, _A, 1] + ra_v * ra_v + ra * ra_a - (e0 * e0 + e1 * e1)
    rhs_b = v0 * w[b, _A, 0] + v1 * w[b, _A, 1] + rb_v * rb_v + rb * rb_a - (f0 * f0 + f1 * f1)
    w[out, _A, 0], w[out, _A, 1] = (v1 * rhs_a - u1 * rhs_b) / det, (u0 * rhs_b - v0 * rhs_a) / det
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _place(
    w: np.ndarray,
    out: int,
    angle: int,
    one: int,
    two: int,
    lx: float,
    lz: float,
    cp: float,
    sp: float,
    m: int,
    order: int,
) -> None:
    """The body through two known pins (``HydraulicModel._place``): its angle jet into ``angle``
    (its cos and sin, not its value: (cp, sp) are those of the pins' direction in the body), its
    origin's into ``out``."""
    e0, e1 = w[two, _P, 0] - w[one, _P, 0], w[two, _P, 1] - w[one, _P, 1]
    n2 = e0 * e0 + e1 * e1
    e = math.sqrt(n2)  # cos, sin of phi = atan2(e1, e0) - atan2(sp, cp), by angle subtraction
    c, s = (e0 * cp + e1 * sp) / e, (e1 * cp - e0 * sp) / e
    w0, w1 = c * lx - s * lz, s * lx + c * lz
    w[angle, _T, 0], w[angle, _T, 1] = c, s
    w[out, _P, 0], w[out, _P, 1] = w[one, _P, 0] - w0, w[one, _P, 1] - w1
    if order < JACOBIAN:
        return
    for j in range(m):
        g = (e0 * (w[two, _J + j, 1] - w[one, _J + j, 1]) - e1 * (w[two, _J + j, 0] - w[one, _J + j, 0])) / n2
        w[angle, _J + j, 0] = g
        w[out, _J + j, 0] = w[one, _J + j, 0] - g * -w1
        w[out, _J + j, 1] = w[one, _J + j, 1] - g * w0
    if order < MOTION:
        return
    v0, v1 = w[two, _V, 0] - w[one, _V, 0], w[two, _V, 1] - w[one, _V, 1]
    a0, a1 = w[two, _A, 0] - w[one, _A, 0], w[two, _A, 1] - w[one, _A, 1]
    cross_v = e0 * v1 - e1 * v0
    fv = cross_v / n2
    fa = (e0 * a1 - e1 * a0) / n2 - 2.0 * (e0 * v0 + e1 * v1) * cross_v / (n2 * n2)
    w[angle, _V, 0], w[angle, _A, 0] = fv, fa
    w[out, _V, 0], w[out, _V, 1] = w[one, _V, 0] - fv * -w1, w[one, _V, 1] - fv * w0
    w[out, _A, 0] = w[one, _A, 0] - fa * -w1 + fv * fv * w0
    w[out, _A, 1] = w[one, _A, 1] - fa * w0 + fv * fv * w1


@njit(cache=True, error_model="numpy", inline="always")
def _point(w: np.ndarray, out: int, o: int, f: int, lx: float, lz: float, m: int, order: int) -> None:
    """The jet of the point (lx, lz) of the body with origin ``o`` and angle ``f`` (``_Body.point``)."""
    c, s = w[f, _T, 0], w[f, _T, 1]
    w0, w1 = c * lx - s * lz, s * lx + c * lz
    w[out, _P, 0], w[out, _P, 1] = w[o, _P, 0] + w0, w[o, _P, 1] + w1
    if order < JACOBIAN:
        return
    for j in range(m):
        w[out, _J + j, 0] = w[o, _J + j, 0] + w[f, _J + j, 0] * -w1
        w[out, _J + j, 1] = w[o, _J + j, 1] + w[f, _J + j, 0] * w0
    if order < MOTION:
        return
    fv, fa = w[f, _V, 0], w[f, _A, 0]
    w[out, _V, 0], w[out, _V, 1] = w[o, _V, 0] + fv * -w1, w[o, _V, 1] + fv * w0
    w[out, _A, 0] = w[o, _A, 0] + fa * -w1 - fv * fv * w0
    w[out, _A, 1] = w[o, _A, 1] + fa * w0 - fv * fv * w1


@njit(cache=True, error_model="numpy", inline="always")
def _slide(
    w: np.ndarray,
    out: int,
    o: int,
    f: int,
    act: int,
    px: float,
    pz: float,
    stroke: Scalar,
    m: int,
    order: int,
) -> None:
    """The prismatic child's origin: O_p + R(phi_p) (axis point + (s, 0)), s the scalar jet
    ``stroke`` of actuator ``act`` (``HydraulicModel._slide``)."""
    c, s = w[f, _T, 0], w[f, _T, 1]
    lx = px + stroke[0]
    w0, w1 = c * lx - s * pz, s * lx + c * pz
    w[out, _P, 0], w[out, _P, 1] = w[o, _P, 0] + w0, w[o, _P, 1] + w1
    if order < JACOBIAN:
        return
    for j in range(m):
        sj = 1.0 if j == act else 0.0
        w[out, _J + j, 0] = w[o, _J + j, 0] + w[f, _J + j, 0] * -w1 + sj * c
        w[out, _J + j, 1] = w[o, _J + j, 1] + w[f, _J + j, 0] * w0 + sj * s
    if order < MOTION:
        return
    fv, fa, sv, sa = w[f, _V, 0], w[f, _A, 0], stroke[1], stroke[2]
    w[out, _V, 0] = w[o, _V, 0] + fv * -w1 + sv * c
    w[out, _V, 1] = w[o, _V, 1] + fv * w0 + sv * s
    w[out, _A, 0] = w[o, _A, 0] + fa * -w1 - fv * fv * w0 + 2.0 * fv * sv * -s + sa * c
    w[out, _A, 1] = w[o, _A, 1] + fa * w0 - fv * fv * w1 + 2.0 * fv * sv * c + sa * s


@njit(cache=True, error_model="numpy", inline="always")
def _rows(m: int, order: int) -> int:
    """How many rows of a slot a scalar copy of a call of ``order`` reads: the value only, or
    every row (the rate and acceleration undefined but unread below MOTION)."""
    return 1 if order == POSITION else _J + m


@njit(cache=True, error_model="numpy", inline="always")
def _angle(w: np.ndarray, out: int, child: int, parent: int, m: int, order: int) -> None:
    """theta = phi_child - phi_parent in (-pi, pi] (the atan2 of the child's turn relative to the
    parent: numpy's wrap of the difference), its derivatives the plain differences."""
    cc, sc, cp, sp = w[child, _T, 0], w[child, _T, 1], w[parent, _T, 0], w[parent, _T, 1]
    w[out, _P, 0] = math.atan2(sc * cp - cc * sp, cc * cp + sc * sp)
    for row in range(1, _rows(m, order)):
        w[out, row, 0] = w[child, row, 0] - w[parent, row, 0]


@njit(cache=True, error_model="numpy", inline="always")
def _task(w: np.ndarray, out: int, tool: int, act: int, swing: Scalar, m: int, order: int) -> None:
    """x, y, z of Q (eq. 3) into slots out..out + 2: the boom-plane tool point (r, z) turned by the
    swing, actuator ``act``'s scalar jet (``HydraulicModel._task``); no swing (act < 0): x = r, y = 0."""
    rows = _rows(m, order)
    for row in range(rows):
        w[out + 2, row, 0] = w[tool, row, 1]
    if act < 0:
        for row in range(rows):
            w[out, row, 0], w[out + 1, row, 0] = w[tool, row, 0], 0.0
        return
    r = w[tool, _P, 0]
    c, s = math.cos(swing[0]), math.sin(swing[0])
    w[out, _P, 0], w[out + 1, _P, 0] = r * c, r * s
    if order >= JACOBIAN:
        for j in range(m):
            sj = 1.0 if j == act else 0.0
            w[out, _J + j, 0] = w[tool, _J + j, 0] * c - r * s * sj
            w[out + 1, _J + j, 0] = w[tool, _J + j, 0] * s + r * c * sj
    if order >= MOTION:
        rv, ra, sv, sa = w[tool, _V, 0], w[tool, _A, 0], swing[1], swing[2]
        w[out, _V, 0] = rv * c - r * s * sv
        w[out + 1, _V, 0] = rv * s + r * c * sv
        w[out, _A, 0] = ra * c - 2.0 * rv * s * sv - r * (c * sv * sv + s * sa)
        w[out + 1, _A, 0] = ra * s + 2.0 * rv * c * sv + r * (c * sa - s * sv * sv)


@njit(cache=True, error_model="numpy", inline="always")
def _work(code: np.ndarray, m: int) -> np.ndarray:
    """The work array of a call: a jet per slot (module docstring), left as allocated."""
    return np.empty((code[0, INT.out], _J + m, 2))


@njit(cache=True, error_model="numpy", inline="always")
def _run(
    code: np.ndarray,
    values: np.ndarray,
    D: np.ndarray,
    Dd: np.ndarray,
    Ddd: np.ndarray,
    order: int,
    w: np.ndarray,
) -> bool:
    """The program on one state into the work array ``w``: False where a dyad does not close."""
    m = D.shape[0]
    for row in range(1 + m, code.shape[0]):
        op, out = code[row, INT.op], code[row, INT.out]
        p, q, f, act = code[row, INT.p], code[row, INT.q], code[row, INT.angle], code[row, INT.act]
        x, z, length = values[row, FLOAT.x], values[row, FLOAT.z], values[row, FLOAT.length]
        # The scalar jet of D[act] + length, or the constant length (act < 0), read once here: the
        # helpers take scalars, none of them D, D_dot, D_ddot, nor the "no actuator" case.
        d = (D[act] + length, Dd[act], Ddd[act]) if act >= 0 else (length, 0.0, 0.0)
        if op == OP.dyad:
            act2, length2 = code[row, INT.act2], values[row, FLOAT.length2]
            d2 = (D[act2] + length2, Dd[act2], Ddd[act2]) if act2 >= 0 else (length2, 0.0, 0.0)
            if not _dyad(w, out, p, q, act, act2, d, d2, values[row, FLOAT.sign], m, order):
                return False
        elif op == OP.point:
            _point(w, out, p, f, x, z, m, order)
        elif op == OP.place:
            _place(w, out, f, p, q, x, z, values[row, FLOAT.cos], values[row, FLOAT.sin], m, order)
        elif op == OP.fixed:
            _fixed(w, out, x, z, m, order)
        elif op == OP.slide:
            _slide(w, out, p, f, act, x, z, d, m, order)
        elif op == OP.actuator:
            _actuator(w, out, act, d, m, order)
        elif op == OP.angle:
            _angle(w, out, p, q, m, order)
        elif op == OP.task:
            _task(w, out, p, act, d, m, order)
        elif op == OP.add:
            for k in range(_rows(m, order)):
                w[out, k, 0] += w[p, k, 0]
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _state(
    code: np.ndarray,
    values: np.ndarray,
    D: np.ndarray,
    D_dot: np.ndarray,
    D_ddot: np.ndarray,
    out: np.ndarray,
    w: np.ndarray,
) -> bool:
    """:func:`state` with the work array given (a batch makes one for all its states)."""
    m = D.shape[0]
    if not (_inside(code, values, D) and _finite(D_dot, m) and _finite(D_ddot, m)):
        return False
    if out.shape[0] != code[0, INT.act] + code[0, INT.q] or out.shape[1] != 3 + m:
        return False
    if not _run(code, values, D, D_dot, D_ddot, MOTION, w):
        return False
    first = code[0, INT.p]
    for i in range(out.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = w[first + i, _P, 0], w[first + i, _V, 0], w[first + i, _A, 0]
        for j in range(m):
            out[i, 3 + j] = w[first + i, _J + j, 0]
    return True


@njit(cache=True, error_model="numpy")
def state(
    code: np.ndarray,
    values: np.ndarray,
    D: np.ndarray,
    D_dot: np.ndarray,
    D_ddot: np.ndarray,
    out: np.ndarray,
) -> bool:
    """theta then Q, one row each: value, rate, acceleration, d/dD (eqs. 3, 7-8, 10-11), into
    ``out`` (n + nq, 3 + m) (``HydraulicState``'s table)."""
    return _state(code, values, D, D_dot, D_ddot, out, _work(code, D.shape[0]))


@njit(cache=True, error_model="numpy", inline="always")
def _pose(code: np.ndarray, values: np.ndarray, D: np.ndarray, out: np.ndarray, w: np.ndarray) -> bool:
    """:func:`pose` with the work array given."""
    if not _inside(code, values, D) or out.shape[0] != code[0, INT.q]:
        return False
    ok = _run(code, values, D, D, D, POSITION, w)
    first = code[0, INT.p] + code[0, INT.act]
    for i in range(out.shape[0]):
        out[i] = w[first + i, _P, 0]
    return ok


@njit(cache=True, error_model="numpy")
def pose(code: np.ndarray, values: np.ndarray, D: np.ndarray, out: np.ndarray) -> bool:
    """Q (eq. 3) into ``out`` (nq,)."""
    return _pose(code, values, D, out, _work(code, D.shape[0]))


@njit(cache=True, error_model="numpy", inline="always")
def _jc0(code: np.ndarray, values: np.ndarray, D: np.ndarray, out: np.ndarray, w: np.ndarray) -> bool:
    """:func:`jc0` with the work array given."""
    m = D.shape[0]
    if not _inside(code, values, D) or out.shape[0] != code[0, INT.q] or out.shape[1] != m:
        return False
    ok = _run(code, values, D, D, D, JACOBIAN, w)
    first = code[0, INT.p] + code[0, INT.act]
    for i in range(out.shape[0]):
        for j in range(m):
            out[i, j] = w[first + i, _J + j, 0]
    return ok


@njit(cache=True, error_model="numpy")
def jc0(code: np.ndarray, values: np.ndarray, D: np.ndarray, out: np.ndarray) -> bool:
    """JC0 = dQ/dD (eq. 8) into ``out`` (nq, m), rows in Q's order."""
    return _jc0(code, values, D, out, _work(code, D.shape[0]))


@njit(cache=True, error_model="numpy", inline="always")
def _rows_of(x: np.ndarray, n: int) -> bool:
    """x (n, m) or one row (1, m), for a batch of n states."""
    return x.shape[0] == n or x.shape[0] == 1


@njit(cache=True, error_model="numpy")
def states(
    code: np.ndarray,
    values: np.ndarray,
    D: np.ndarray,
    D_dot: np.ndarray,
    D_ddot: np.ndarray,
    out: np.ndarray,
) -> bool:
    """:func:`state` of every row of D (N, m) into ``out`` (N, n + nq, 3 + m), D_dot and D_ddot
    (N, m) or one row (1, m) for every state (the caller passes the arrays as given: their row
    counts are checked here); False for rows that do not match, or as soon as one state is
    refused (the caller's numpy path then says why)."""
    n = D.shape[0]
    rows = _rows_of(D_dot, n) and _rows_of(D_ddot, n) and out.shape[0] == n
    if not rows or D.shape[1] != code[0, INT.act2]:
        return False
    v, a = (1 if D_dot.shape[0] == n else 0), (1 if D_ddot.shape[0] == n else 0)
    w, i = _work(code, D.shape[1]), 0
    while i < n and _state(code, values, D[i], D_dot[v * i], D_ddot[a * i], out[i], w):
        i += 1
    return i == n


@njit(cache=True, error_model="numpy")
def poses(code: np.ndarray, values: np.ndarray, D: np.ndarray, out: np.ndarray) -> bool:
    """:func:`pose` of every row of D (N, m) into ``out`` (N, nq); False as soon as one is refused."""
    if out.shape[0] != D.shape[0] or D.shape[1] != code[0, INT.act2]:  # (an empty batch too)
        return False
    if D.shape[0] == 1:  # the single call's straight line: the loop costs 0.05 us, 6 % of one call
        return _pose(code, values, D[0], out[0], _work(code, D.shape[1]))
    w, i = _work(code, D.shape[1]), 0
    while i < D.shape[0] and _pose(code, values, D[i], out[i], w):
        i += 1
    return i == D.shape[0]


@njit(cache=True, error_model="numpy")
def jc0s(code: np.ndarray, values: np.ndarray, D: np.ndarray, out: np.ndarray) -> bool:
    """:func:`jc0` of every row of D (N, m) into ``out`` (N, nq, m); False as soon as one is refused."""
    if out.shape[0] != D.shape[0] or D.shape[1] != code[0, INT.act2]:
        return False
    if D.shape[0] == 1:  # the single call's straight line (poses)
        return _jc0(code, values, D[0], out[0], _work(code, D.shape[1]))
    w, i = _work(code, D.shape[1]), 0
    while i < D.shape[0] and _jc0(code, values, D[i], out[i], w):
        i += 1
    return i == D.shape[0]


@njit(cache=True, error_model="numpy")
def monitored(
    code: np.ndarray,
    values: np.ndarray,
    points: np.ndarray,
    half: float,
    swing: int,
    D: np.ndarray,
    D_dot: np.ndarray,
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
) -> bool:
    """The monitored points' positions, velocities and accelerations at the constant rates D_dot
    (``HydraulicModel.monitored_motion``) into ``p``, ``v``, ``a`` (P, 3), base frame: the
    monitored points' program (every pin, the tool outline's and the tail's points) run on the
    state, then per row of the point table (layout.POINT) its boom-plane jet (r, z) turned by the
    swing (column ``swing`` of D, -1: none), moved ``side`` x ``half`` across the boom plane."""
    m = D.shape[0]
    n = points.shape[0]
    if not (_inside(code, values, D) and _finite(D_dot, m)):
        return False
    for out in (p, v, a):
        if out.shape[0] != n or out.shape[1] != 3:
            return False
    w = _work(code, m)
    if not _run(code, values, D, D_dot, np.zeros(m), MOTION, w):
        return False
    t1, w1 = (D[swing], D_dot[swing]) if swing >= 0 else (0.0, 0.0)
    c, s = math.cos(t1), math.sin(t1)
    ww = w1 * w1
    for i in range(n):
        slot = points[i, POINT.slot]
        r, z = w[slot, _P, 0], w[slot, _P, 1]
        rv, zv = w[slot, _V, 0], w[slot, _V, 1]
        spin = w[slot, _A, 0] - r * ww  # radial: the boom plane's own and the centripetal
        # Across the boom plane by k: (-s, c, 0) k, which the swing turns.
        k = points[i, POINT.side] * half
        p[i, 0], p[i, 1], p[i, 2] = r * c - k * s, r * s + k * c, z
        v[i, 0] = rv * c - (r * s + k * c) * w1
        v[i, 1] = rv * s + (r * c - k * s) * w1
        v[i, 2] = zv
        a[i, 0] = spin * c - 2.0 * rv * s * w1 + k * s * ww
        a[i, 1] = spin * s + 2.0 * rv * c * w1 - k * c * ww
        a[i, 2] = w[slot, _A, 1]
    return True
