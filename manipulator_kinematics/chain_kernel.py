"""The shared serial chain's FK, frames and FK + Jacobian, compiled (numba): the hot path of
:class:`manipulator_kinematics.serial_chain.SerialChain`, whose vectorised numpy code stays the
reference (a test compares the two over 10^4 random configurations of every machine's chain).

Why compiled: one numpy call costs about a microsecond whatever its size, and FK + Jacobian of
one configuration is tens of them (about 100 us); the same steps as scalar loops take one or two
microseconds (Pinocchio's FK + Jacobian: a few), and a batch runs several times faster than
numpy's (no temporaries). Kept in numba's on-disk cache (``cache=True``).

Same steps as the numpy path:

1. row variables v = C q + offset; a revolute row's theta = theta + v, a prismatic row's d = d + v;
2. the link transform A_i of standard D-H, Rz(theta) Tz(d) Tx(a) Rx(alpha), or of modified D-H,
   Rx(alpha) Tx(a) Rz(theta) Tz(d) (:meth:`SerialChain.link_transforms`);
3. frames by the cumulative product base A_1 ... A_i; the tool pose = the last frame times tool;
4. Jacobian column i = (z x (p_tool - o), z) for a revolute, (z, 0) for a prismatic row, z and o
   from frame i-1 (standard) or frame i (modified); J_q = J_v C.

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
def _times(F, A, out):
    """out = F A, homogeneous transforms with A given by its top three rows (A's bottom row is
    0 0 0 1, and so stays out's); the terms in matmul's order."""
    a, b, c = A
    for r in range(3):
        f0, f1, f2 = F[r, 0], F[r, 1], F[r, 2]
        out[r, 0] = f0 * a[0] + f1 * b[0] + f2 * c[0]
        out[r, 1] = f0 * a[1] + f1 * b[1] + f2 * c[1]
        out[r, 2] = f0 * a[2] + f1 * b[2] + f2 * c[2]
        out[r, 3] = f0 * a[3] + f1 * b[3] + f2 * c[3] + F[r, 3]
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, 0.0, 0.0, 1.0


@njit(cache=True, error_model="numpy", inline="always")
def _link(k, i, v):
    """The top three rows of A_i(v) (step 2), v the row variable with its offset (step 1)."""
    r = ROWS + ROW * i
    a, ca, sa, d, theta = k[r], k[r + 1], k[r + 2], k[r + 3], k[r + 4]
    if k[r + 6] != 0.0:  # prismatic
        d = d + v
    else:
        theta = theta + v
    ct, st = math.cos(theta), math.sin(theta)
    if k[2] != 0.0:  # modified D-H: Rx(alpha) Tx(a) Rz(theta) Tz(d)
        return ((ct, -st, 0.0, a), (st * ca, ct * ca, -sa, -sa * d), (st * sa, ct * sa, ca, ca * d))
    # standard D-H: Rz(theta) Tz(d) Tx(a) Rx(alpha)
    return ((ct, -st * ca, st * sa, a * ct), (st, ct * ca, -ct * sa, a * st), (0.0, sa, ca, d))


@njit(cache=True, error_model="numpy", inline="always")
def _walk(k, q, F):
    """F (n_rows + 1, 4, 4): base, base A_1, ..., base A_1 ... A_n (step 3) of q (n,)."""
    for r in range(4):
        for c in range(4):
            F[0, r, c] = k[BASE + 4 * r + c]
    start = 0
    if k[4] != 0.0:  # identity base: base A_1 = A_1 (the product's bits too)
        (F[1, 0, 0], F[1, 0, 1], F[1, 0, 2], F[1, 0, 3]), (F[1, 1, 0], F[1, 1, 1], F[1, 1, 2], F[1, 1, 3]), (
            F[1, 2, 0], F[1, 2, 1], F[1, 2, 2], F[1, 2, 3]) = _link(k, 0, _variable(k, q, 0))
        F[1, 3, 0], F[1, 3, 1], F[1, 3, 2], F[1, 3, 3] = 0.0, 0.0, 0.0, 1.0
        start = 1
    for i in range(start, int(k[0])):
        _times(F[i], _link(k, i, _variable(k, q, i)), F[i + 1])


@njit(cache=True, error_model="numpy", inline="always")
def _tool(k, F, pose):
    """pose = F tool (step 3)."""
    if k[5] != 0.0:  # identity tool
        pose[:] = F
        return
    t = TOOL
    _times(F, ((k[t], k[t + 1], k[t + 2], k[t + 3]), (k[t + 4], k[t + 5], k[t + 6], k[t + 7]),
               (k[t + 8], k[t + 9], k[t + 10], k[t + 11])), pose)


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
    _walk(k, q, out)


@njit(void(_IN1, _IN1, _OUT2), cache=True, error_model="numpy")
def fkine(k, q, pose):
    """The tool pose (4, 4) of q (n,)."""
    F = np.empty((int(k[0]) + 1, 4, 4))
    _walk(k, q, F)
    _tool(k, F[-1], pose)


@njit(void(_IN1, _IN1, _OUT2, _OUT2), cache=True, error_model="numpy")
def fkine_jacob0(k, q, pose, jacobian):
    """The tool pose (4, 4) and the Jacobian (6, n) of q (n,)."""
    F = np.empty((int(k[0]) + 1, 4, 4))
    _walk(k, q, F)
    _tool(k, F[-1], pose)
    _jacobian(k, F, pose, jacobian)


@njit(void(_IN1, _IN2, _OUT4), cache=True, error_model="numpy")
def frames_batch(k, q, out):
    """frames of every row of q (N, n) into out (N, n_rows + 1, 4, 4)."""
    for m in range(q.shape[0]):
        _walk(k, q[m], out[m])


@njit(void(_IN1, _IN2, _OUT3), cache=True, error_model="numpy")
def fkine_batch(k, q, pose):
    """fkine of every row of q (N, n) into pose (N, 4, 4)."""
    F = np.empty((int(k[0]) + 1, 4, 4))
    for m in range(q.shape[0]):
        _walk(k, q[m], F)
        _tool(k, F[-1], pose[m])


@njit(void(_IN1, _IN2, _OUT3, _OUT3), cache=True, error_model="numpy")
def fkine_jacob0_batch(k, q, pose, jacobian):
    """fkine_jacob0 of every row of q (N, n) into pose (N, 4, 4) and jacobian (N, 6, n)."""
    F = np.empty((int(k[0]) + 1, 4, 4))
    for m in range(q.shape[0]):
        _walk(k, q[m], F)
        _tool(k, F[-1], pose[m])
        _jacobian(k, F, pose[m], jacobian[m])
