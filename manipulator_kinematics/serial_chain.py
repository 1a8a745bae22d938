"""Serial kinematic chains from Denavit-Hartenberg tables (numpy only, no rclpy).

One :class:`SerialChain` serves every machine of the package: standard (distal) or modified
(Craig, proximal) D-H rows, revolute or prismatic joints, a constant offset per joint, optional
base and tool transforms. Forward kinematics gives 4x4 homogeneous transforms; the geometric
Jacobian is 6 x n with the linear rows first, in the world frame (the frame the base transform is
given in), like Robotics Toolbox for Python's ``fkine``/``jacob0``.

Every function takes joint values of shape (..., n): one configuration (n,) or any batch
(N, n), (N, M, n); outputs carry the same leading shape. There is no Python loop over
configurations: a batch is one numpy computation on (N, n) arrays, or one call of the compiled
kernel (:mod:`manipulator_kinematics.chain_kernel`, the same steps as scalar loops).

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

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.row_blocks import in_blocks


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

    The math is the textbook's (Robotics Toolbox's ``fkine``/``jacob0``) in plain numpy on
    (N, n) arrays: the link transforms A_i (:meth:`link_transforms`), the frames
    base A_1 ... A_i by a cumulative product, the tool pose = the last frame times the tool, and
    the Jacobian's columns from the frames' z axes and origins. One configuration (n,) is a
    batch of one through the same code, so it gives the same bits as that row of a batch.

    That numpy path is the reference. A call costs numpy's fixed price per ufunc (tens of them,
    about 100 us for FK + Jacobian of one configuration), so the same steps also run as scalar
    loops compiled by numba (:mod:`manipulator_kinematics.chain_kernel`, loaded in the background
    by the first call, :class:`manipulator_kinematics.compiled.Kernel`): once it is ready every
    call, one configuration or a batch, goes through it (benchmarks/bench_serial_chain.py: one call
    ~1-2 us; batches several times faster than numpy's). ``compiled=False`` asks for the numpy path.
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
        if (
            self.coupling.ndim != 2
            or self.coupling.shape[0] != len(rows)
            or not np.all(np.isfinite(self.coupling))
        ):
            raise ValueError(f"coupling must be a finite ({len(rows)}, n) matrix, got {self.coupling.shape}")
        self._identity = self.coupling.shape == (len(rows), len(rows)) and bool(
            np.array_equal(self.coupling, np.eye(len(rows)))
        )
        self.modified = bool(modified)
        self.base = _homogeneous(base, "base")
        self.tool = _homogeneous(tool, "tool")
        self._a = np.array([r.a for r in rows], dtype=float)
        self._alpha = np.array([r.alpha for r in rows], dtype=float)
        self._d = np.array([r.d for r in rows], dtype=float)
        self._theta = np.array([r.theta for r in rows], dtype=float)
        self._offset = np.array([r.offset for r in rows], dtype=float)
        self._prismatic = np.array([r.prismatic for r in rows], dtype=bool)
        # self.n once: the property is a call on the batches' hot path.
        self._jacobian_shape, self._columns = (6, self.n), self.n
        self._jacobian_one = (1, 6, self.n)  # a batch of one's, made once
        self._packed = self._pack()

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
        ca, sa, a = np.cos(self._alpha), np.sin(self._alpha), self._a
        A = np.zeros(theta.shape + (4, 4))
        if self.modified:  # Rx(alpha) Tx(a) Rz(theta) Tz(d)
            A[..., 0, 0], A[..., 0, 1], A[..., 0, 3] = ct, -st, a
            A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = st * ca, ct * ca, -sa, -sa * d
            A[..., 2, 0], A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = st * sa, ct * sa, ca, ca * d
        else:  # Rz(theta) Tz(d) Tx(a) Rx(alpha)
            A[..., 0, 0], A[..., 0, 1], A[..., 0, 2], A[..., 0, 3] = ct, -st * ca, st * sa, a * ct
            A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = st, ct * ca, -ct * sa, a * st
            A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = sa, ca, d
        A[..., 3, 3] = 1.0
        return A

    def fkine(self, q: ArrayLike, all_frames: bool = False, compiled: bool = True) -> np.ndarray:
        """Tool pose base A_1 ... A_n tool, shape (..., 4, 4).

        With ``all_frames`` the link frames instead, shape (..., n_rows + 1, 4, 4): index 0 is the base
        frame, index i the frame of link i (base A_1 ... A_i; the tool transform not applied).
        ``compiled=False``: the numpy path (the reference), not the compiled kernel.
        """
        kernel = KERNEL.ready
        if kernel is not None and compiled and not all_frames and type(q) is np.ndarray:
            try:  # the hot paths, as in fkine_jacob0
                if q.ndim == 1:
                    pose = np.empty((4, 4))
                    kernel.fkine(self._packed, q, pose)
                    return pose
                n = len(q)  # (N, n); other dimensions: TypeError in the kernel
                pose = np.empty(_POSE_ONE if n == 1 else (n, 4, 4))
                kernel.fkine_batch(self._packed, q, pose)
                return pose
            except (TypeError, ValueError):
                pass
        q = self._joint_array(q)
        kernel = KERNEL.get() if compiled else None
        if all_frames:
            shape = (self.n_rows + 1, 4, 4)
            if kernel is None:
                return self._numpy(q, self._frames, shape)
            frames = np.empty(q.shape[:-1] + shape)
            if q.ndim == 1:
                kernel.frames(self._packed, q, frames)
            else:
                kernel.frames_batch(self._packed, q.reshape(-1, self.n), frames.reshape(-1, *shape))
            return frames
        if kernel is None:
            return self._numpy(q, self._pose, (4, 4))
        if q.ndim == 1:
            pose = np.empty((4, 4))
            kernel.fkine(self._packed, q, pose)
            return pose
        pose = np.empty(q.shape[:-1] + (4, 4))
        kernel.fkine_batch(self._packed, q.reshape(-1, self.n), pose.reshape(-1, 4, 4))
        return pose

    def jacob0(self, q: ArrayLike, compiled: bool = True) -> np.ndarray:
        """Geometric Jacobian in the world frame, shape (..., 6, n): rows vx, vy, vz, wx, wy, wz.

        Column i of the rows' Jacobian is (z x (p_tool - o), z) for a revolute and (z, 0) for a
        prismatic row, where z and o are the joint's axis direction and a point on it: frame i-1
        in standard D-H, frame i in modified D-H (after Rz(theta_i) Tz(d_i), which leave z_i in
        place); coupled joints multiply it by C. ``compiled=False``: the numpy path.
        """
        return self.fkine_jacob0(q, compiled)[1]

    def fkine_jacob0(self, q: ArrayLike, compiled: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """``(fkine(q), jacob0(q))`` from one walk along the chain: tool pose (..., 4, 4) and
        Jacobian (..., 6, n), for callers that need both (velocity FK, an IK iteration).
        ``compiled=False``: the numpy path."""
        kernel = KERNEL.ready
        if kernel is not None and compiled and type(q) is np.ndarray:
            # The hot paths (one configuration: a node's call, an IK iteration; a batch (N, n)),
            # q as given: the kernel's signature takes float64 C-contiguous arrays only and checks
            # the length, so any other q raises before the kernel runs and takes the general path
            # below, which converts or refuses it. Validating here first cost 0.3 us of 1.5, and
            # a batch of one 2.4x a single call through the general path (issue #32). A batch's
            # shapes are built of ints: np.empty((n, *shape)) costs 0.1-0.2 us more.
            try:
                if q.ndim == 1:
                    pose, jacobian = np.empty((4, 4)), np.empty(self._jacobian_shape)
                    kernel.fkine_jacob0(self._packed, q, pose, jacobian)
                    return pose, jacobian
                n = len(q)  # (N, n); other dimensions: TypeError in the kernel
                if n == 1:
                    pose, jacobian = np.empty(_POSE_ONE), np.empty(self._jacobian_one)
                else:
                    pose, jacobian = np.empty((n, 4, 4)), np.empty((n, 6, self._columns))
                kernel.fkine_jacob0_batch(self._packed, q, pose, jacobian)
                return pose, jacobian
            except (TypeError, ValueError):
                pass
        q = self._joint_array(q)
        kernel = KERNEL.get() if compiled else None
        if kernel is None:
            return self._numpy(q, self._pose_jacobian, (4, 4), self._jacobian_shape)
        if q.ndim == 1:
            pose, jacobian = np.empty((4, 4)), np.empty(self._jacobian_shape)
            kernel.fkine_jacob0(self._packed, q, pose, jacobian)
            return pose, jacobian
        pose, jacobian = np.empty(q.shape[:-1] + (4, 4)), np.empty(q.shape[:-1] + self._jacobian_shape)
        kernel.fkine_jacob0_batch(
            self._packed,
            q.reshape(-1, self.n),
            pose.reshape(-1, 4, 4),
            jacobian.reshape(-1, *self._jacobian_shape),
        )
        return pose, jacobian

    # ---- the numpy path, on (N, n) arrays ---------------------------------------------------------
    def _frames(self, q: np.ndarray) -> np.ndarray:
        """(N, n_rows + 1, 4, 4): base, base A_1, base A_1 A_2, ... (the cumulative product)."""
        links = self.link_transforms(q)
        frames = [np.broadcast_to(self.base, (len(q), 4, 4))]
        for i in range(self.n_rows):
            frames.append(frames[-1] @ links[:, i])
        return np.stack(frames, axis=1)

    def _pose(self, q: np.ndarray) -> np.ndarray:
        return self._frames(q)[:, -1] @ self.tool

    def _pose_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        frames = self._frames(q)
        pose = frames[:, -1] @ self.tool
        axes = frames[:, 1:] if self.modified else frames[:, :-1]
        z, origin = axes[..., :3, 2], axes[..., :3, 3]  # (N, n_rows, 3) each
        prismatic = self._prismatic[:, None]
        linear = np.where(prismatic, z, np.cross(z, pose[:, None, :3, 3] - origin))
        angular = np.where(prismatic, 0.0, z)
        jacobian = np.concatenate([linear, angular], axis=-1).swapaxes(-1, -2)  # (N, 6, n_rows)
        return pose, jacobian if self._identity else jacobian @ self.coupling

    def _numpy(self, q: np.ndarray, function: Callable, *shapes: tuple[int, ...]) -> Any:
        """``function`` on q (..., n) as rows (N, n), in blocks (in_blocks); outputs (..., *shape)."""
        outputs = in_blocks(function, q.reshape(-1, self.n))
        if isinstance(outputs, np.ndarray):  # one output (len(shapes) == 1)
            return outputs.reshape(q.shape[:-1] + shapes[0])
        return tuple(out.reshape(q.shape[:-1] + shape) for out, shape in zip(outputs, shapes, strict=True))

    def _pack(self) -> np.ndarray:
        """The chain's constants as one float array, laid out as chain_kernel reads them (BASE below)."""
        rows = np.column_stack(
            [
                self._a,
                np.cos(self._alpha),
                np.sin(self._alpha),
                self._d,
                self._theta,
                self._offset,
                self._prismatic,
                np.cos(self._theta),
                np.sin(self._theta),
            ]
        )
        identity = np.eye(4)
        head = [self.n_rows, self.n, self.modified, self._identity, np.array_equal(self.tool, identity)]
        constants = (head, self.base.ravel(), self.tool.ravel(), rows.ravel(), self.coupling.ravel())
        return np.concatenate(constants)

    def _joint_array(self, q: ArrayLike) -> np.ndarray:
        q = np.ascontiguousarray(q, dtype=float)  # the layout the kernel is compiled for
        if q.ndim == 0 or q.shape[-1] != self.n:
            raise ValueError(f"joint values must have shape (..., {self.n}), got {q.shape}")
        return q


#: Layout of SerialChain._packed, the chain's constants for chain_kernel: n_rows, n, and 1.0 or
#: 0.0 for modified D-H, identity coupling, identity tool; then base and tool
#: (16 each, row-major); then per row a, cos alpha, sin alpha, d, theta, offset, prismatic, cos
#: theta, sin theta (ROW floats; the last two are a prismatic row's constant link angle); then the
#: coupling C (n_rows x n, row-major).
BASE, TOOL, ROWS, ROW = 5, 21, 37, 9
#: A batch of one's pose shape, made once (a tuple made per call costs 0.04-0.08 us, issue #32).
_POSE_ONE = (1, 4, 4)


def _warm(kernel: ModuleType) -> None:
    """Run each kernel function once (numba loads or compiles it) for one configuration and a batch."""
    packed = SerialChain([revolute(a=0.5), prismatic(alpha=1.0)], coupling=[[1.0], [2.0]])._packed
    q, pose, frames, jacobian = np.zeros(1), np.empty((4, 4)), np.empty((3, 4, 4)), np.empty((6, 1))
    kernel.fkine(packed, q, pose)
    kernel.frames(packed, q, frames)
    kernel.fkine_jacob0(packed, q, pose, jacobian)
    q, pose = np.zeros((2, 1)), np.empty((2, 4, 4))
    frames, jacobian = np.empty((2, 3, 4, 4)), np.empty((2, 6, 1))
    kernel.fkine_batch(packed, q, pose)
    kernel.frames_batch(packed, q, frames)
    kernel.fkine_jacob0_batch(packed, q, pose, jacobian)


#: The compiled chain (:mod:`manipulator_kinematics.chain_kernel`), see manipulator_kinematics.compiled.
KERNEL = Kernel("manipulator_kinematics.chain_kernel", _warm)


def compiled_kernel(wait: bool = False) -> ModuleType | None:
    """The compiled kernel module if ready, else None (the first call starts loading it; calls
    take the numpy path meanwhile, the same results within 1e-12). ``wait``: load it now (tests,
    benchmarks)."""
    return KERNEL.get(wait=wait)


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
        """(...,) True where every joint is inside its limits (within ``tol``); False for NaN.
        A 0-d array for one state: indexable like a batch's."""
        q = np.asarray(q, dtype=float)
        return np.asarray(((q >= self.lower - tol) & (q <= self.upper + tol)).all(axis=-1))

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
