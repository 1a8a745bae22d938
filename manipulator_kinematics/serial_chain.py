"""Serial kinematic chains from Denavit-Hartenberg tables (numpy only, no rclpy).

One :class:`SerialChain` serves every machine of the package: standard (distal) or modified
(Craig, proximal) D-H rows, revolute or prismatic joints, a constant offset per joint, optional
base and tool transforms. Forward kinematics gives 4x4 homogeneous transforms; the geometric
Jacobian is 6 x n with the linear rows first, in the world frame (the frame the base transform is
given in), like Robotics Toolbox for Python's ``fkine``/``jacob0``.

Every function takes joint values of shape (..., n): one configuration (n,) or any batch
(N, n), (N, M, n); outputs carry the same leading shape. The only Python loop is over the n
joints (matrix products along the chain), never over configurations.

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

from collections.abc import Sequence
from dataclasses import dataclass

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
    """Forward kinematics and geometric Jacobian of a D-H chain, vectorised over configurations."""

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
        frames = self._frames(q)
        if all_frames:
            return frames
        return frames[..., -1, :, :] @ self.tool

    def jacob0(self, q: ArrayLike) -> np.ndarray:
        """Geometric Jacobian in the world frame, shape (..., 6, n): rows vx, vy, vz, wx, wy, wz.

        Column i of the rows' Jacobian is (z x (p_tool - o), z) for a revolute and (z, 0) for a
        prismatic row, where z and o are the joint's axis direction and a point on it: frame i-1
        in standard D-H, frame i in modified D-H (after Rz(theta_i) Tz(d_i), which leave z_i in
        place); coupled joints multiply it by C.
        """
        frames = self._frames(q)
        tool = frames[..., -1, :, :] @ self.tool
        axis_frames = frames[..., 1:, :, :] if self.modified else frames[..., :-1, :, :]
        z = axis_frames[..., :3, 2]
        origin = axis_frames[..., :3, 3]
        moment = np.cross(z, tool[..., None, :3, 3] - origin)
        prismatic = self._prismatic[:, None]
        linear = np.where(prismatic, z, moment)
        angular = np.where(prismatic, 0.0, z)
        rows = np.concatenate([np.swapaxes(linear, -1, -2), np.swapaxes(angular, -1, -2)], axis=-2)
        return rows if self._identity else rows @ self.coupling

    def _frames(self, q: ArrayLike) -> np.ndarray:
        links = self.link_transforms(q)
        frames = np.empty(links.shape[:-3] + (self.n_rows + 1, 4, 4))
        frames[..., 0, :, :] = self.base
        for i in range(self.n_rows):
            frames[..., i + 1, :, :] = frames[..., i, :, :] @ links[..., i, :, :]
        return frames

    def _joint_array(self, q: ArrayLike) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.ndim == 0 or q.shape[-1] != self.n:
            raise ValueError(f"joint values must have shape (..., {self.n}), got {q.shape}")
        return q


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
