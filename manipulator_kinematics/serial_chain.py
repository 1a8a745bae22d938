"""Serial kinematic chains from Denavit-Hartenberg tables (numpy only, no rclpy).

One :class:`SerialChain` serves every machine of the package: standard (distal) or modified
(Craig, proximal) D-H rows, revolute or prismatic joints, a constant offset per joint, optional
base and tool transforms. Forward kinematics gives 4x4 homogeneous transforms; the geometric
Jacobian is 6 x n with the linear rows first, in the world frame (the frame the base transform is
given in), like Robotics Toolbox for Python's ``fkine``/``jacob0``.

Every function takes joint values of shape (..., n): one configuration (n,) or any batch
(N, n), (N, M, n); outputs carry the same leading shape. There is no Python loop over
configurations: a batch runs the chain's straight-line code (:class:`SerialChain`) on arrays.

Row semantics (the Robotics Toolbox's ``RevoluteDH``/``PrismaticDH`` and ``...MDH``):

* standard D-H, row i:  A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i); joint i moves about or
  along z_{i-1};
* modified D-H, row i:  A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i) (the row holds
  a_{i-1} and alpha_{i-1} in its ``a`` and ``alpha``); joint i moves about or along z_i;
* revolute joint: theta_i = v_i + offset_i with d_i constant; prismatic joint: d_i = v_i +
  offset_i with theta_i constant. ``offset`` carries a paper's zero convention: the pump boom's
  unfolding angle theta_k (180 deg = straight on) is the row variable with offset -180 deg.

Coupled (passive) joints: the row variables v (n_rows) are a linear function v = C q of the
independent joint values q (n), given as the ``coupling`` matrix C (n_rows x n; identity by
default). The palletizer's passive flange joint theta4 = -(theta2 + theta3) is the row
``[0, -1, -1, 0]`` of C. FK and Jacobian are then functions of q: J_q = J_v C.
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import chain
from typing import Any

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class DHRow:
    """One joint of a D-H table; lengths in metres, angles in radians.

    A revolute row's ``theta`` and a prismatic row's ``d`` are the joint variable, so they must
    stay 0: put a constant part in ``offset`` (the value of theta or d at q = 0).
    """

    a: float = 0.0
    alpha: float = 0.0
    d: float = 0.0
    theta: float = 0.0
    prismatic: bool = False
    offset: float = 0.0

    def __post_init__(self) -> None:
        if not self.prismatic and self.theta != 0.0:
            raise ValueError("theta of a revolute row is its joint variable: give the constant as offset")
        if self.prismatic and self.d != 0.0:
            raise ValueError("d of a prismatic row is its joint variable: give the constant as offset")
        values = (self.a, self.alpha, self.d, self.theta, self.offset)
        if not all(np.isfinite(v) for v in values):
            raise ValueError(f"D-H row has a non-finite value: {self}")


def revolute(a: float = 0.0, alpha: float = 0.0, d: float = 0.0, offset: float = 0.0) -> DHRow:
    """A revolute row: theta = q + offset."""
    return DHRow(a=a, alpha=alpha, d=d, offset=offset)


def prismatic(a: float = 0.0, alpha: float = 0.0, theta: float = 0.0, offset: float = 0.0) -> DHRow:
    """A prismatic row: d = q + offset."""
    return DHRow(a=a, alpha=alpha, theta=theta, prismatic=True, offset=offset)


def transl(x: float, y: float, z: float) -> np.ndarray:
    """4x4 pure translation."""
    matrix = np.eye(4)
    matrix[:3, 3] = (x, y, z)
    return matrix


def trotx(angle: float) -> np.ndarray:
    """4x4 rotation about x."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0, 0.0], [0.0, c, -s, 0.0], [0.0, s, c, 0.0], [0.0, 0.0, 0.0, 1.0]])


def troty(angle: float) -> np.ndarray:
    """4x4 rotation about y."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s, 0.0], [0.0, 1.0, 0.0, 0.0], [-s, 0.0, c, 0.0], [0.0, 0.0, 0.0, 1.0]])


def trotz(angle: float) -> np.ndarray:
    """4x4 rotation about z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


class SerialChain:
    """Forward kinematics and geometric Jacobian of a D-H chain, vectorised over configurations.

    No 4x4 products at run time: when a chain is built, its walk (Rz(theta) Tz(d) turns the x and
    y axes and moves the origin along z, Tx(a) Rx(alpha) moves it along x and turns y and z, then
    the tool and the Jacobian's cross products) is traced once on symbolic parts (:class:`_Tracer`)
    into straight-line Python with the constants folded: terms multiplied by an exact 0 vanish
    (alpha and constant angles that are multiples of 90 deg are snapped), so a 90 deg twist is a
    swap of axes. That one function runs on Python floats for one configuration (numpy's per-call
    overhead would dominate 6x6 work) and on (N,) arrays for a batch, with cos and sin taken once
    for the whole (n_rows, N) array: the same arithmetic in both, so without coupling (whose
    matrix product may sum in another order) one configuration and a batch agree to the bit.
    """

    def __init__(
        self,
        rows: Sequence[DHRow],
        *,
        modified: bool = False,
        base: ArrayLike | None = None,
        tool: ArrayLike | None = None,
        coupling: ArrayLike | None = None,
    ) -> None:
        if not rows:
            raise ValueError("a serial chain needs at least one D-H row")
        self.rows = tuple(rows)
        self.coupling = np.eye(len(rows)) if coupling is None else np.array(coupling, dtype=float)
        if (self.coupling.ndim != 2 or self.coupling.shape[0] != len(rows)
                or not np.all(np.isfinite(self.coupling))):
            raise ValueError(f"coupling must be a finite ({len(rows)}, n) matrix, got {self.coupling.shape}")
        self._identity = self.coupling.shape == (len(rows), len(rows)) and bool(
            np.array_equal(self.coupling, np.eye(len(rows))))
        self.modified = bool(modified)
        self.base = _homogeneous(base, "base")
        self.tool = _homogeneous(tool, "tool")
        self._a = np.array([r.a for r in rows], dtype=float)
        self._alpha = np.array([r.alpha for r in rows], dtype=float)
        self._d = np.array([r.d for r in rows], dtype=float)
        self._theta = np.array([r.theta for r in rows], dtype=float)
        self._offset = np.array([r.offset for r in rows], dtype=float)
        self._prismatic = np.array([r.prismatic for r in rows], dtype=bool)
        self._programs: dict[int, tuple[Callable, list[tuple[int, ...]]]] = {}  # traced on first use

    @property
    def n(self) -> int:
        """Number of independent joints (the length of q)."""
        return self.coupling.shape[1]

    @property
    def n_rows(self) -> int:
        """Number of D-H rows (joints, passive ones included)."""
        return len(self.rows)

    @property
    def prismatic(self) -> np.ndarray:
        """(n_rows,) True where the row's joint is prismatic."""
        return self._prismatic.copy()

    def row_variables(self, q: ArrayLike) -> np.ndarray:
        """v = C q (..., n_rows): the joint variable of every row, offsets not added."""
        q = self._joint_array(q)
        return q if self._identity else q @ self.coupling.T

    def link_transforms(self, q: ArrayLike) -> np.ndarray:
        """A_i(v_i) of every row, shape (..., n_rows, 4, 4), in the chain's D-H convention."""
        variable = self.row_variables(q) + self._offset
        theta = self._theta + np.where(self._prismatic, 0.0, variable)
        d = self._d + np.where(self._prismatic, variable, 0.0)
        ct, st = np.cos(theta), np.sin(theta)
        ca = np.broadcast_to(np.cos(self._alpha), theta.shape)
        sa = np.broadcast_to(np.sin(self._alpha), theta.shape)
        a = np.broadcast_to(self._a, theta.shape)
        zero, one = np.zeros_like(theta), np.ones_like(theta)
        if self.modified:
            rows = (
                (ct, -st, zero, a),
                (st * ca, ct * ca, -sa, -sa * d),
                (st * sa, ct * sa, ca, ca * d),
                (zero, zero, zero, one),
            )
        else:
            rows = (
                (ct, -st * ca, st * sa, a * ct),
                (st, ct * ca, -ct * sa, a * st),
                (zero, sa, ca, d),
                (zero, zero, zero, one),
            )
        return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)

    def fkine(self, q: ArrayLike, all_frames: bool = False) -> np.ndarray:
        """Tool pose base A_1 ... A_n tool, shape (..., 4, 4).

        With ``all_frames`` the link frames instead, shape (..., n_rows + 1, 4, 4): index 0 is the base
        frame, index i the frame of link i (base A_1 ... A_i; the tool transform not applied).
        """
        if all_frames:
            return self._run(q, _FRAMES)[0]
        return self._run(q, _POSE)[0]

    def jacob0(self, q: ArrayLike) -> np.ndarray:
        """Geometric Jacobian in the world frame, shape (..., 6, n): rows vx, vy, vz, wx, wy, wz.

        Column i of the rows' Jacobian is (z x (p_tool - o), z) for a revolute and (z, 0) for a
        prismatic row, where z and o are the joint's axis direction and a point on it: frame i-1
        in standard D-H, frame i in modified D-H (after Rz(theta_i) Tz(d_i), which leave z_i in
        place); coupled joints multiply it by C.
        """
        return self._coupled(self._run(q, _JACOBIAN)[0])

    def fkine_jacob0(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(fkine(q), jacob0(q))`` from one walk along the chain: tool pose (..., 4, 4) and
        Jacobian (..., 6, n), for callers that need both (velocity FK, an IK iteration)."""
        pose, jacobian = self._run(q, _POSE | _JACOBIAN)
        return pose, self._coupled(jacobian)

    def _run(self, q: ArrayLike, what: int) -> list[np.ndarray]:
        """The traced program ``what`` on q (..., n); its outputs as arrays of shape (..., *dims)."""
        q = self._joint_array(q)
        traced = self._programs.get(what)
        if traced is None:
            traced = self._programs[what] = self._trace(what)
        program, dims = traced
        if q.ndim == 1:
            v = (q if self._identity else self.coupling @ q) + self._offset
            return evaluate_parts(program, (np.cos(v), np.sin(v), v), dims)
        flat = q.reshape(-1, self.n).T
        # (n_rows, N) in C order: each row's values one contiguous array for the program.
        v = np.add(flat if self._identity else self.coupling @ flat, self._offset[:, None], order="C")
        out = evaluate_parts(program, (np.cos(v), np.sin(v), v), dims)
        return [result.reshape(q.shape[:-1] + shape) for result, shape in zip(out, dims, strict=True)]

    def _trace(self, what: int) -> tuple[Callable, list[tuple[int, ...]]]:
        """Straight-line function (cos, sin, v) -> lists of parts of the outputs ``what`` (for
        :func:`evaluate_parts`), and their shapes; cos, sin, v are indexed by row: theta_i = v_i of
        a revolute, d_i = v_i of a prismatic row (offsets included)."""
        tracer = _Tracer()
        const = tracer.constant
        frame = [[const(x) for x in self.base[:3, j]] for j in range(4)]
        frames = [frame]
        for i, row in enumerate(self.rows):
            if row.prismatic:
                cos, sin = const(_snap(math.cos(row.theta))), const(_snap(math.sin(row.theta)))
                d = tracer.variable(f"v[{i}]")
            else:
                cos, sin, d = tracer.variable(f"cos[{i}]"), tracer.variable(f"sin[{i}]"), const(row.d)
            shift = const(row.a), const(_snap(math.cos(row.alpha))), const(_snap(math.sin(row.alpha)))
            if self.modified:
                frame = _turn(_shift(frame, *shift), cos, sin, d)
            else:
                frame = _shift(_turn(frame, cos, sin, d), *shift)
            frames.append(frame)
        tool = _times(frames[-1], [[const(x) for x in self.tool[:3, j]] for j in range(4)])
        outputs, dims = [], []
        if what & _POSE:
            outputs.append(_entries(tool))
            dims.append((4, 4))
        if what & _FRAMES:
            outputs.append([x for f in frames for x in _entries(f)])
            dims.append((len(frames), 4, 4))
        if what & _JACOBIAN:
            columns = []
            axes = frames[1:] if self.modified else frames[:-1]
            for row, (_, _, z, o) in zip(self.rows, axes, strict=True):
                if row.prismatic:
                    columns.append(z + [const(0.0)] * 3)
                else:
                    columns.append(_cross(z, [t - x for t, x in zip(tool[3], o, strict=True)]) + z)
            outputs.append([column[k] for k in range(6) for column in columns])
            dims.append((6, len(self.rows)))
        return tracer.compile(outputs, f"serial_chain_{what}"), dims

    def _coupled(self, jacobian: np.ndarray) -> np.ndarray:
        return jacobian if self._identity else jacobian @ self.coupling

    def _joint_array(self, q: ArrayLike) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.ndim == 0 or q.shape[-1] != self.n:
            raise ValueError(f"joint values must have shape (..., {self.n}), got {q.shape}")
        return q


def evaluate_parts(function: Callable[..., Sequence[Sequence]], args: Sequence[np.ndarray],
                   dims: Sequence[tuple[int, ...]]) -> list[np.ndarray]:
    """Run a function written on scalar parts for one case or a batch; its outputs as arrays.

    ``function(*args)`` indexes each argument by row and returns one list of parts per output
    (the row-major entries of an array of shape ``dims[j]``), with +, -, * and the like only, so
    that a part can be a float or an (N,) array alike. ``args``: arrays (k,) for one case, given
    to the function as lists of floats (numpy's per-call overhead would dominate small work), or
    (k, N) for a batch, given in chunks of columns so that the temporaries stay in the cache. The
    arithmetic is the same, so one case and a batch give bit-identical results. Returns arrays of
    shape ``dims[j]`` for one case, else (N, *dims[j]).
    """
    if args[0].ndim == 1:
        parts = function(*[arg.tolist() for arg in args])
        # One buffer for every output: the cheapest way from tens of floats to arrays.
        buffer = bytearray(_packer(sum(map(len, parts))).pack(*chain.from_iterable(parts)))
        out, start = [], 0
        for shape in dims:
            out.append(np.ndarray(shape, buffer=buffer, offset=start))
            start += 8 * math.prod(shape)
        return out
    count = args[0].shape[1]
    out = [np.empty((count, math.prod(shape))) for shape in dims]
    stages = [np.empty((math.prod(shape), _CHUNK)) for shape in dims]
    for start in range(0, count, _CHUNK):
        stop = min(start + _CHUNK, count)
        parts = function(*(arg[:, start:stop] for arg in args))
        # Each part into a contiguous row of a stage, copied into the output transposed: cheaper
        # than strided column writes.
        for values, stage, result in zip(parts, stages, out, strict=True):
            for k, value in enumerate(values):
                stage[k, :stop - start] = value
            result[start:stop] = stage[:, :stop - start].T
    return [result.reshape((count, *shape)) for result, shape in zip(out, dims, strict=True)]


def evaluate_angle_parts(closed_form: Callable[..., Sequence[Sequence]], args: Sequence[np.ndarray],
                         dims: Sequence[tuple[int, ...]], judge: Callable[..., Sequence[Sequence]],
                         more: Sequence[np.ndarray],
                         judged_dims: Sequence[tuple[int, ...]]) -> list[np.ndarray]:
    """A closed-form IK as two stages of scalar parts (see :func:`evaluate_parts`) with one numpy
    arctan2 between them: ``closed_form(*args)`` gives the candidates' angles as pairs y, x (of
    ``dims[0]``) and diagnostics ``extra`` (``dims[2]``); ``judge(angles, extra, *more)`` gives
    outputs of ``judged_dims`` (joint values, statuses, the selection). Returns [extra, *outputs].

    ``args`` and ``more``: arrays (k,) for one target, which then runs on floats straight through
    (evaluate_parts' packing between the stages would cost a seventh of the call), or (k, N) rows
    for a batch. The arctan2 is numpy's in both cases (math's differs in the last bit), so one
    target and a batch give the same bits.
    """
    if args[0].ndim == 1:
        y, x, extra = closed_form(*[arg.tolist() for arg in args])
        outputs = judge(np.arctan2(y, x).tolist(), extra, *[arg.tolist() for arg in more])
        arrays = [np.array(out, dtype=float).reshape(shape)
                  for out, shape in zip(outputs, judged_dims, strict=True)]
        return [np.array(extra, dtype=float), *arrays]
    # Junk from targets that are not poses is the judge's to flag; arrays must not warn about it.
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        y, x, extra = evaluate_parts(closed_form, args, dims)
        angles = np.arctan2(y, x)
    rows = [parts_rows(angles.reshape(len(angles), -1)), parts_rows(extra), *more]
    return [extra, *evaluate_parts(judge, rows, judged_dims)]


def parts_rows(values: np.ndarray) -> np.ndarray:
    """An argument for :func:`evaluate_parts`: values (k,) of one case as they are, (..., k) of a
    batch as contiguous (k, N) rows."""
    if values.ndim == 1:
        return values
    return np.ascontiguousarray(values.reshape(-1, values.shape[-1]).T)


def parts_where(condition: Any, a: Any, b: Any) -> Any:
    """np.where for a batch's parts, a conditional expression for floats (see evaluate_parts)."""
    if isinstance(condition, np.ndarray):
        return np.where(condition, a, b)
    return a if condition else b


def parts_any(condition: Any) -> bool:
    """True if the condition holds anywhere (for work a rare case alone needs)."""
    return bool(condition.any()) if isinstance(condition, np.ndarray) else bool(condition)


def parts_all(condition: Any) -> bool:
    """True if the condition holds everywhere."""
    return bool(condition.all()) if isinstance(condition, np.ndarray) else bool(condition)


def parts_sqrt(x: Any) -> Any:
    """Square root of a part (math.sqrt and np.sqrt are both correctly rounded: same bits)."""
    return np.sqrt(x) if isinstance(x, np.ndarray) else math.sqrt(x)


def parts_clip(x: Any, low: float = -1.0, high: float = 1.0) -> Any:
    """A part clipped to [low, high] (NaN stays NaN)."""
    return np.clip(x, low, high) if isinstance(x, np.ndarray) else min(max(x, low), high)


def parts_pose_checks(pose: Sequence, rotation_tol: float = 1e-6,
                      bottom_tol: float = 1e-12) -> tuple[Any, Any]:
    """(finite, rigid) of a pose's 16 row-major parts (see evaluate_parts): every entry finite; the
    rotation part orthonormal (R^T R = I to ``rotation_tol`` entry by entry) and proper (det > 0)
    and the bottom row [0, 0, 0, 1] to ``bottom_tol`` (sum of the deviations)."""
    nx, ox, ax, px, ny, oy, ay, py, nz, oz, az, pz, b0, b1, b2, b3 = pose
    bottom = abs(b0) + abs(b1) + abs(b2) + abs(b3 - 1.0)
    finite = (abs(nx) + abs(ox) + abs(ax) + abs(ny) + abs(oy) + abs(ay) + abs(nz) + abs(oz) + abs(az)
              + abs(px) + abs(py) + abs(pz) + bottom) < math.inf
    rigid = ((abs(nx * nx + ny * ny + nz * nz - 1.0) < rotation_tol)
             & (abs(ox * ox + oy * oy + oz * oz - 1.0) < rotation_tol)
             & (abs(ax * ax + ay * ay + az * az - 1.0) < rotation_tol)
             & (abs(nx * ox + ny * oy + nz * oz) < rotation_tol)
             & (abs(nx * ax + ny * ay + nz * az) < rotation_tol)
             & (abs(ox * ax + oy * ay + oz * az) < rotation_tol)
             & (nx * (oy * az - oz * ay) + ny * (oz * ax - ox * az) + nz * (ox * ay - oy * ax) > 0.0)
             & (bottom < bottom_tol))
    return finite, rigid


@functools.cache
def _packer(count: int) -> struct.Struct:
    return struct.Struct(f"{count}d")


@dataclass(frozen=True)
class JointLimits:
    """Closed intervals [lower_i, upper_i] per joint (m for prismatic, rad for revolute joints).

    ``prismatic`` marks the joints whose values are lengths (for messages); empty = none.
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    prismatic: tuple[bool, ...] = ()

    def __post_init__(self) -> None:
        lower = np.asarray(self.lower, dtype=float)
        upper = np.asarray(self.upper, dtype=float)
        if not (lower.shape == upper.shape == (len(self.names),)):
            raise ValueError(f"need one lower and one upper limit per joint {self.names}")
        if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(lower <= upper)):
            raise ValueError(f"limits must be finite with lower <= upper, got {lower} / {upper}")
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)

    def violation(self, q: ArrayLike, tol: float = 0.0) -> np.ndarray:
        """Per joint (..., n): -1 below the lower limit, +1 above the upper limit, 0 inside.

        Values within ``tol`` of a limit count as inside. NaN counts as outside (+1).
        """
        q = np.asarray(q, dtype=float)
        below = q < self.lower - tol
        inside = q <= self.upper + tol
        return np.where(below, -1, np.where(inside, 0, 1)).astype(np.int8)

    def within(self, q: ArrayLike, tol: float = 0.0) -> np.ndarray:
        """(...,) True where every joint is inside its limits (within ``tol``); False for NaN."""
        q = np.asarray(q, dtype=float)
        return ((q >= self.lower - tol) & (q <= self.upper + tol)).all(axis=-1)

    def bounds(self, tol: float = 0.0) -> tuple[float, ...]:
        """[lower_0 - tol, upper_0 + tol, lower_1 - tol, ...] as plain floats (for scalar parts,
        see :func:`evaluate_parts`)."""
        return tuple(float(v) for pair in zip(self.lower - tol, self.upper + tol, strict=True) for v in pair)

    def clip(self, q: ArrayLike) -> np.ndarray:
        """q moved into the limits (NaN stays NaN)."""
        return np.minimum(np.maximum(q, self.lower), self.upper)


def _homogeneous(matrix: ArrayLike | None, what: str) -> np.ndarray:
    if matrix is None:
        return np.eye(4)
    matrix = np.asarray(matrix, dtype=float)
    if matrix.shape != (4, 4) or not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{what} transform must be a 4x4 homogeneous matrix")
    rotation = matrix[:3, :3]
    if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9) or np.linalg.det(rotation) < 0:
        raise ValueError(f"{what} transform's rotation part is not a rotation matrix")
    return matrix


#: Cases per chunk of a batch in evaluate_parts (the temporaries then fit in the cache).
_CHUNK = 4096
# What a traced program returns (bit flags).
_POSE, _FRAMES, _JACOBIAN = 1, 2, 4


class _Part:
    """One scalar of the traced walk: a constant (``name`` None) or ``sign`` times a variable."""

    __slots__ = ("name", "sign", "tracer", "value")

    def __init__(self, tracer: _Tracer, name: int | None, sign: float = 1.0, value: float = 0.0) -> None:
        self.tracer, self.name, self.sign, self.value = tracer, name, sign, value

    def __neg__(self) -> _Part:
        if self.name is None:
            return self.tracer.constant(-self.value)
        return _Part(self.tracer, self.name, -self.sign)

    def __add__(self, other: _Part) -> _Part:
        emit = self.tracer.emit
        if other.name is None:
            if self.name is None:
                return self.tracer.constant(self.value + other.value)
            self, other = other, self
        if self.name is None:  # constant + sign * variable
            if self.value == 0.0:
                return other
            if other.sign > 0:
                return emit("{} + " + repr(self.value), other.name)
            return emit("{} - " + repr(self.value), other.name, sign=-1.0)
        if self.sign == other.sign:
            return emit("{} + {}", self.name, other.name, sign=self.sign)
        first, second = (self, other) if self.sign > 0 else (other, self)
        return emit("{} - {}", first.name, second.name)

    def __sub__(self, other: _Part) -> _Part:
        return self + -other

    def __mul__(self, other: _Part) -> _Part:
        if other.name is None:
            self, other = other, self
        if self.name is None:  # constant * (sign * variable or constant)
            if self.value == 0.0:
                return self
            if other.name is None:
                return self.tracer.constant(self.value * other.value)
            sign = other.sign * math.copysign(1.0, self.value)
            if abs(self.value) == 1.0:
                return _Part(self.tracer, other.name, sign)
            return self.tracer.emit(repr(abs(self.value)) + " * {}", other.name, sign=sign)
        return self.tracer.emit("{} * {}", self.name, other.name, sign=self.sign * other.sign)


class _Tracer:
    """Records +, -, * on :class:`_Part` as straight-line code, folding constants, then compiles
    what the outputs need of it into a Python function of (cos, sin, v)."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, tuple[int, ...]]] = []  # line i: (template, operand lines)

    def constant(self, value: float) -> _Part:
        return _Part(self, None, value=float(value))

    def variable(self, expression: str) -> _Part:
        return self.emit(expression)

    def emit(self, template: str, *operands: int, sign: float = 1.0) -> _Part:
        self.lines.append((template, operands))
        return _Part(self, len(self.lines) - 1, sign)

    def compile(self, outputs: list[list[_Part]], name: str) -> Callable:
        """The function; its lines are the ones the outputs need, and a local is reused once its
        value is dead, so a batch holds few (N,) temporaries at a time."""
        needed = {part.name for parts in outputs for part in parts} - {None}
        for line in range(len(self.lines) - 1, -1, -1):
            if line in needed:
                needed.update(self.lines[line][1])
        kept = sorted(needed)
        last_use = {operand: line for line in kept for operand in self.lines[line][1]}
        last_use.update((part.name, math.inf) for parts in outputs for part in parts)
        local: dict[int, str] = {}
        free: list[str] = []
        body = [f"def {name}(cos, sin, v):"]
        for line in kept:
            template, operands = self.lines[line]
            arguments = [local[operand] for operand in operands]
            free += [local[operand] for operand in set(operands) if last_use[operand] == line]
            local[line] = free.pop() if free else f"t{len(set(local.values()))}"
            body.append(f"    {local[line]} = {template.format(*arguments)}")

        def text(part: _Part) -> str:
            if part.name is None:
                return repr(part.value)
            return local[part.name] if part.sign > 0 else f"-{local[part.name]}"

        lists = ("[" + ", ".join(map(text, parts)) + "]" for parts in outputs)
        body.append(f"    return ({', '.join(lists)},)")
        source = "\n".join(body)
        namespace: dict[str, Any] = {}
        exec(compile(source, f"<{name}>", "exec"), namespace)  # generated above from the D-H table alone
        function = namespace[name]
        function.source = source  # to read what a chain runs: chain._programs[...][0].source
        return function


def _turn(frame: list[list[_Part]], cos: _Part, sin: _Part, d: _Part) -> list[list[_Part]]:
    """frame Rz(theta) Tz(d), frame as [x, y, z, p] (columns of three parts)."""
    x, y, z, p = frame
    return [[cos * a + sin * b for a, b in zip(x, y)], [cos * b - sin * a for a, b in zip(x, y)], z,
            [pi + d * zi for pi, zi in zip(p, z)]]


def _shift(frame: list[list[_Part]], a: _Part, ca: _Part, sa: _Part) -> list[list[_Part]]:
    """frame Tx(a) Rx(alpha)."""
    x, y, z, p = frame
    return [x, [ca * b + sa * c for b, c in zip(y, z)], [ca * c - sa * b for b, c in zip(y, z)],
            [pi + a * xi for pi, xi in zip(p, x)]]


def _times(frame: list[list[_Part]], other: list[list[_Part]]) -> list[list[_Part]]:
    """frame @ other, both as [x, y, z, p]."""
    x, y, z, p = frame
    columns = [[u[k] * col[0] + v[k] * col[1] + w[k] * col[2] for k in range(3)]
               for col, (u, v, w) in zip(other, [(x, y, z)] * 4)]
    columns[3] = [c + pk for c, pk in zip(columns[3], p)]
    return columns


def _cross(u: list[_Part], v: list[_Part]) -> list[_Part]:
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _entries(frame: list[list[_Part]]) -> list[_Part]:
    """The 16 entries, row-major, of the 4x4 transform [x, y, z, p]."""
    zero, one = frame[0][0].tracer.constant(0.0), frame[0][0].tracer.constant(1.0)
    return [frame[j][k] for k in range(3) for j in range(4)] + [zero, zero, zero, one]


def _snap(value: float) -> float:
    """cos/sin of a constant angle, exactly 0 or +-1 at multiples of 90 deg (so those terms vanish)."""
    return float(round(value)) if abs(value - round(value)) < 1e-12 else value
