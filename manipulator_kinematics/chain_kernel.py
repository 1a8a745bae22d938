"""The shared serial chain's FK, frames and FK + Jacobian, compiled (numba): the hot path of
:class:`manipulator_kinematics.serial_chain.SerialChain`, whose vectorised numpy code stays the
reference (a test compares the two over 10^4 random configurations of every machine's chain).

Why compiled: one numpy call costs about a microsecond whatever its size, and FK + Jacobian of
one configuration is tens of them (about 100 us); the same steps as scalar loops take one or two
microseconds (Pinocchio's FK + Jacobian: a few), and a batch runs several times faster than
numpy's (no temporaries). Kept in numba's on-disk cache (``cache=True``).

Same steps as the numpy path:

1. row variables v = C q + offset; a revolute row's theta = theta + v, a prismatic row's d = d + v;
   the cos and sin of every theta (:func:`_joints`; a batch takes them for a block of
   configurations before walking them, :data:`BLOCK`);
2. the link transform A_i of standard D-H, Rz(theta) Tz(d) Tx(a) Rx(alpha), or of modified D-H,
   Rx(alpha) Tx(a) Rz(theta) Tz(d) (:meth:`SerialChain.link_transforms`);
3. frames by the cumulative product base A_1 ... A_i, each A_i applied to the running product
   factor by factor (:func:`_times_link`); the tool pose = the last frame times tool;
4. Jacobian column i = (z x (p_tool - o), z) for a revolute, (z, 0) for a prismatic row, z and o
   from frame i-1 (standard) or frame i (modified); J_q = J_v C.

FK alone is mostly libm's sincos (85 % of a batch's time for the machines' chains), so its batches
gain less over the code before issue #22 than frames or FK + Jacobian do. Taking the cos and sin
with numpy first would not help: numpy has no SIMD float64 cos/sin, and its cos and sin of a
column took 36 ns an angle against the kernel's sincos 26 ns (uniform random angles).

The chain's constants arrive as one float array, ``SerialChain._packed`` (layout:
:data:`manipulator_kinematics.serial_chain.BASE` and the constants next to it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import float64, njit, types, void

from manipulator_kinematics.serial_chain import BASE, ROW, ROWS, TOOL

# Explicit signatures: compiled (or loaded from the cache) once at import, and the inputs typed
# read-only, which writeable arrays pass as too, so no input makes numba compile inside a call.
_IN1, _IN2 = types.Array(float64, 1, "C", readonly=True), types.Array(float64, 2, "C", readonly=True)
_OUT2, _OUT3, _OUT4 = float64[:, ::1], float64[:, :, ::1], float64[:, :, :, ::1]


@njit(cache=True, error_model="numpy", inline="always")
def _variable(k, q, i):
    """v_i = (C q)_i + offset_i (step 1)."""
    if k[3] != 0.0:  # identity coupling
        v = q[i]
    else:
        n_rows, n = int(k[0]), int(k[1])
        c = ROWS + ROW * n_rows + n * i
        v = 0.0
        for j in range(n):
            v += k[c + j] * q[j]
    return v + k[ROWS + ROW * i + 5]


@njit(cache=True, error_model="numpy", inline="always")
def _times(F, A):
    """F A of homogeneous transforms given by their top three rows (the bottom row 0 0 0 1 stays
    the product's), the terms in matmul's order (the tool transform)."""
    a, b, c = A
    (f00, f01, f02, f03), (f10, f11, f12, f13), (f20, f21, f22, f23) = F
    return (
        (
            f00 * a[0] + f01 * b[0] + f02 * c[0],
            f00 * a[1] + f01 * b[1] + f02 * c[1],
            f00 * a[2] + f01 * b[2] + f02 * c[2],
            f00 * a[3] + f01 * b[3] + f02 * c[3] + f03,
        ),
        (
            f10 * a[0] + f11 * b[0] + f12 * c[0],
            f10 * a[1] + f11 * b[1] + f12 * c[1],
            f10 * a[2] + f11 * b[2] + f12 * c[2],
            f10 * a[3] + f11 * b[3] + f12 * c[3] + f13,
        ),
        (
            f20 * a[0] + f21 * b[0] + f22 * c[0],
            f20 * a[1] + f21 * b[1] + f22 * c[1],
            f20 * a[2] + f21 * b[2] + f22 * c[2],
            f20 * a[3] + f21 * b[3] + f22 * c[3] + f23,
        ),
    )


@njit(cache=True, error_model="numpy", inline="always")
def _constant(k, at):
    """The top three rows of the transform packed row-major at k[at:at + 16] (base or tool)."""
    return (
        (k[at], k[at + 1], k[at + 2], k[at + 3]),
        (k[at + 4], k[at + 5], k[at + 6], k[at + 7]),
        (k[at + 8], k[at + 9], k[at + 10], k[at + 11]),
    )


@njit(cache=True, error_model="numpy", inline="always")
def _store(T, out):
    """The transform T (top three rows) into out (4, 4)."""
    for r in range(3):
        out[r, 0], out[r, 1], out[r, 2], out[r, 3] = T[r]
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, 0.0, 0.0, 1.0


@njit(cache=True, error_model="numpy", inline="always")
def _row_times_link(row, ct, st, ca, sa, a, d, modified, tilted):
    """One row (x, y, z, p) of T times A_i, A_i applied factor by factor (steps 2 and 3)."""
    x, y, z, p = row
    if modified:  # Rx(alpha) Tx(a) Rz(theta) Tz(d)
        if tilted:
            y, z = ca * y + sa * z, ca * z - sa * y
        p = p + a * x
        x, y = ct * x + st * y, ct * y - st * x
        return x, y, z, p + d * z
    # standard D-H: Rz(theta) Tz(d) Tx(a) Rx(alpha)
    x, y = ct * x + st * y, ct * y - st * x
    p = p + d * z + a * x
    if tilted:
        y, z = ca * y + sa * z, ca * z - sa * y
    return x, y, z, p


@njit(cache=True, error_model="numpy", inline="always")
def _joints(k, q, P, j):
    """Step 1 and the link angles' cos and sin for q (n,): per row i, v_i (with its offset), cos
    theta_i and sin theta_i into P[0, j, i], P[1, j, i], P[2, j, i]. Every v_i first: a sincos
    waiting on its row's sum over C (the palletizer's coupling) cost about 15 % of FK alone."""
    for i in range(int(k[0])):
        P[0, j, i] = _variable(k, q, i)
    for i in range(int(k[0])):
        r = ROWS + ROW * i
        if k[r + 6] != 0.0:  # prismatic: theta constant, its cos and sin packed
            P[1, j, i], P[2, j, i] = k[r + 7], k[r + 8]
        else:
            theta = k[r + 4] + P[0, j, i]
            P[1, j, i], P[2, j, i] = math.cos(theta), math.sin(theta)


@njit(cache=True, error_model="numpy", inline="always")
def _times_link(k, T, i, v, ct, st):
    """T A_i (steps 2 and 3), T and the product by their top three rows; v the row variable with
    its offset, ct and st the cos and sin of the link angle (:func:`_joints`).

    A_i's factors are applied to T one by one (a rotation turns two of T's columns, a
    translation adds to its last): the product A_i spelled out, with the terms of A_i's zeros
    left out, and Rx(0) = I skipped (alpha = 0 rows, most of the pump boom's); the numpy path
    forms A_i and multiplies, so the two differ in the last bits (1e-12 in the test), while one
    configuration and a batch here give the same bits. Measured: FK alone of 10^3 6-23 % faster
    than A_i formed and multiplied as a 3x4 product."""
    r = ROWS + ROW * i
    a, ca, sa, d = k[r], k[r + 1], k[r + 2], k[r + 3]
    if k[r + 6] != 0.0:  # prismatic
        d = d + v
    modified, tilted = k[2] != 0.0, sa != 0.0 or ca != 1.0
    return (
        _row_times_link(T[0], ct, st, ca, sa, a, d, modified, tilted),
        _row_times_link(T[1], ct, st, ca, sa, a, d, modified, tilted),
        _row_times_link(T[2], ct, st, ca, sa, a, d, modified, tilted),
    )


@njit(cache=True, error_model="numpy", inline="always")
def _walk(k, P, j, F):
    """base A_1 ... A_n (step 3) of configuration j of P (:func:`_joints`), the top three rows;
    with F (n_rows + 1, 4, 4), not None, every frame on the way into it: base, base A_1, ...,
    base A_1 ... A_n."""
    T = _constant(k, BASE)
    if F is not None:
        _store(T, F[0])
    for i in range(int(k[0])):
        T = _times_link(k, T, i, P[0, j, i], P[1, j, i], P[2, j, i])
        if F is not None:
            _store(T, F[i + 1])
    return T


#: Configurations per pass of a batch: first the joints of a block (:func:`_joints`: libm's
#: sincos, whose branches on the angle's range the CPU mispredicts for random angles), then the
#: block's walks, which have no branch on the data. Measured at 10^5: FK alone 6-18 % faster
#: than both per configuration in turn; blocks of 16 to 256 alike.
BLOCK = 64


@njit(cache=True, error_model="numpy", inline="always")
def _check_length(k, q):
    """q (n,) of the chain's length: the single calls take q as given (SerialChain's hot path
    checks only that it is a 1-D array), so a wrong length is refused here, not read past."""
    if q.shape[0] != int(k[1]):
        raise ValueError("joint values of the wrong length")


@njit(cache=True, error_model="numpy", inline="always")
def _check_batch(k, q):
    """q (N, n) of the chain's length (:func:`_check_length`, for the batches)."""
    if q.shape[1] != int(k[1]):
        raise ValueError("joint values of the wrong length")


@njit(cache=True, error_model="numpy", inline="always")
def _scratch(k, count):
    """P for :func:`_joints`: (3, count, n_rows)."""
    return np.empty((3, count, int(k[0])))


@njit(cache=True, error_model="numpy", inline="always")
def _block(k, q, start, P):
    """The joints of configurations start... of q (N, n) into P (:func:`_joints`), as many as
    P holds; returns the end of the block."""
    stop = min(start + P.shape[1], q.shape[0])
    for m in range(start, stop):
        _joints(k, q[m], P, m - start)
    return stop


@njit(cache=True, error_model="numpy", inline="always")
def _tool(k, T):
    """T tool (step 3), T the last frame's top three rows."""
    if k[4] != 0.0:  # identity tool
        return T
    return _times(T, _constant(k, TOOL))


@njit(cache=True, error_model="numpy", inline="always")
def _jacobian(k, F, pose, jacobian):
    """jacobian (6, n) from the frames F and the tool pose (step 4)."""
    n_rows, n = int(k[0]), int(k[1])
    px, py, pz = pose[0, 3], pose[1, 3], pose[2, 3]
    identity = k[3] != 0.0
    if not identity:
        jacobian[:] = 0.0
    shift = 1 if k[2] != 0.0 else 0  # the joint's axis: frame i (modified) or i - 1 (standard)
    for i in range(n_rows):
        axis = F[i + shift]
        zx, zy, zz = axis[0, 2], axis[1, 2], axis[2, 2]
        if k[ROWS + ROW * i + 6] != 0.0:  # prismatic: (z, 0)
            column = (zx, zy, zz, 0.0, 0.0, 0.0)
        else:  # revolute: (z x (p - o), z)
            dx, dy, dz = px - axis[0, 3], py - axis[1, 3], pz - axis[2, 3]
            column = (zy * dz - zz * dy, zz * dx - zx * dz, zx * dy - zy * dx, zx, zy, zz)
        if identity:
            for r in range(6):
                jacobian[r, i] = column[r]
        else:  # J_q = J_v C: row i of C spreads column i over the independent joints
            c = ROWS + ROW * n_rows + n * i
            for j in range(n):
                for r in range(6):
                    jacobian[r, j] += column[r] * k[c + j]


@njit(void(_IN1, _IN1, _OUT3), cache=True, error_model="numpy")
def frames(k, q, out):
    """The frames out (n_rows + 1, 4, 4) of q (n,)."""
    _check_length(k, q)
    P = _scratch(k, 1)
    _joints(k, q, P, 0)
    _walk(k, P, 0, out)


# Inlined into the batches too: a call of a compiled function from another costs about 0.04 us,
# 5 % of a single call (issue #32: a batch of one no dearer than one call).
@njit(void(_IN1, _IN1, _OUT2), cache=True, error_model="numpy", inline="always")
def fkine(k, q, pose):
    """The tool pose (4, 4) of q (n,)."""
    _check_length(k, q)
    P = _scratch(k, 1)
    _joints(k, q, P, 0)
    _store(_tool(k, _walk(k, P, 0, None)), pose)


@njit(void(_IN1, _IN1, _OUT2, _OUT2), cache=True, error_model="numpy", inline="always")
def fkine_jacob0(k, q, pose, jacobian):
    """The tool pose (4, 4) and the Jacobian (6, n) of q (n,)."""
    _check_length(k, q)
    P, F = _scratch(k, 1), np.empty((int(k[0]) + 1, 4, 4))
    _joints(k, q, P, 0)
    _store(_tool(k, _walk(k, P, 0, F)), pose)
    _jacobian(k, F, pose, jacobian)


@njit(void(_IN1, _IN2, _OUT4), cache=True, error_model="numpy")
def frames_batch(k, q, out):
    """frames of every row of q (N, n) into out (N, n_rows + 1, 4, 4)."""
    _check_batch(k, q)
    P, start = _scratch(k, min(BLOCK, q.shape[0])), 0
    while start < q.shape[0]:
        stop = _block(k, q, start, P)
        for m in range(start, stop):
            _walk(k, P, m - start, out[m])
        start = stop


@njit(void(_IN1, _IN2, _OUT3), cache=True, error_model="numpy")
def fkine_batch(k, q, pose):
    """fkine of every row of q (N, n) into pose (N, 4, 4)."""
    if q.shape[0] == 1:  # the single call's straight line: the blocks cost 6 % of a batch of one
        fkine(k, q[0], pose[0])
        return
    _check_batch(k, q)
    P, start = _scratch(k, min(BLOCK, q.shape[0])), 0
    while start < q.shape[0]:
        stop = _block(k, q, start, P)
        for m in range(start, stop):
            _store(_tool(k, _walk(k, P, m - start, None)), pose[m])
        start = stop


@njit(void(_IN1, _IN2, _OUT3, _OUT3), cache=True, error_model="numpy")
def fkine_jacob0_batch(k, q, pose, jacobian):
    """fkine_jacob0 of every row of q (N, n) into pose (N, 4, 4) and jacobian (N, 6, n)."""
    if q.shape[0] == 1:  # the single call's straight line (fkine_batch)
        fkine_jacob0(k, q[0], pose[0], jacobian[0])
        return
    _check_batch(k, q)
    P, F, start = _scratch(k, min(BLOCK, q.shape[0])), np.empty((int(k[0]) + 1, 4, 4)), 0
    while start < q.shape[0]:
        stop = _block(k, q, start, P)
        for m in range(start, stop):
            _store(_tool(k, _walk(k, P, m - start, F)), pose[m])
            _jacobian(k, F, pose[m], jacobian[m])
        start = stop
