"""The protocol every serial machine of the package implements, and its shared IK pieces.

numpy only, no rclpy. A model is immutable and built once from its parameters (Pinocchio's
Model; results are plain arrays or small frozen records). Every entry point is vectorised over a
leading batch shape ``...``:

* ``fkine(q)``           (..., n) -> (..., 4, 4) tool pose in the base frame (REP 103, SI units);
* ``frames(q)``          (..., n) -> (..., k, 4, 4) the base frame, every joint frame and the
                         tool last (what a drawing or a URDF check needs);
* ``jacob0(q)``          (..., n) -> (..., 6, n) geometric Jacobian of the tool point in the base
                         frame, rows vx, vy, vz, wx, wy, wz;
* ``solve_ik(target)``   (..., 4, 4) -> :class:`IKSolutions`: EVERY solution the closed form
                         has, each with a status, and the one a stated rule selects.

(``fkine`` and ``jacob0`` are Robotics Toolbox for Python's names, the vocabulary users know.)

The selection rule shared by all machines (:func:`select`): only candidates whose status is
SUCCESS (solution inside every joint limit, away from singularities) count; of those the one of
the requested branch, else the one closest to the seed (weighted squared joint distance), else the
first in branch order (each machine orders its branches by preference, e.g. the palletizer's home
elbow first). Two valid candidates equally close to the seed are reported as a tie.
:func:`manipulator_kinematics.select_kernel.select_one` is the same rule for one target in the
machines' compiled IK kernels.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.serial_chain import JointLimits

#: Quaternion components below this count as zero when the sign of a quaternion is fixed.
QUATERNION_ZERO = 1e-12

# Shepperd's K = 1 x _SHEPPERD_ONE + r.flat @ _SHEPPERD (rows x, y, z, w of matrix_quaternion):
#   [1+m00-m11-m22, m01+m10, m02+m20, m21-m12], [m01+m10, 1-m00+m11-m22, m12+m21, m02-m20],
#   [m02+m20, m12+m21, 1-m00-m11+m22, m10-m01], [m21-m12, m02-m20, m10-m01, 1+m00+m11+m22].
_SHEPPERD_TERMS = {
    (0, 0): ((0, 1), (4, -1), (8, -1)),
    (0, 1): ((1, 1), (3, 1)),
    (0, 2): ((2, 1), (6, 1)),
    (0, 3): ((7, 1), (5, -1)),
    (1, 1): ((0, -1), (4, 1), (8, -1)),
    (1, 2): ((5, 1), (7, 1)),
    (1, 3): ((2, 1), (6, -1)),
    (2, 2): ((0, -1), (4, -1), (8, 1)),
    (2, 3): ((3, 1), (1, -1)),
    (3, 3): ((0, 1), (4, 1), (8, 1)),
}


def _shepperd_matrix() -> np.ndarray:
    weights = np.zeros((9, 16))
    for (a, b), terms in _SHEPPERD_TERMS.items():
        for element, sign in terms:
            weights[element, 4 * a + b] = weights[element, 4 * b + a] = sign
    return weights


_SHEPPERD = _shepperd_matrix()
_SHEPPERD_ONE = np.eye(4).reshape(16)
#: Two seed distances closer than this (relative) count as a tie.
TIE_TOLERANCE = 1e-9


class IKStatus(IntEnum):
    """Outcome of one IK candidate or target, ordered from best to worst."""

    SUCCESS = 0
    SINGULAR = 1  # a solution inside the limits exists only at or near a singularity
    JOINT_LIMITS = 2  # geometric solutions exist, every one violates a joint limit or stroke end
    UNREACHABLE = 3  # no configuration reaches the target, whatever the limits
    INVALID = 4  # the target is not finite or not a pose


_SUCCESS = int(IKStatus.SUCCESS)  # a plain int: an enum member lookup costs microseconds per call
#: Each status as an int8 scalar: np.where of two gives int8 at once (no int64 array to convert).
_STATUS8 = tuple(np.int8(s) for s in IKStatus)


class RequestError(ValueError):
    """An IK request the solver cannot take as asked: an unknown mode or branch name (``status``
    None), or options that contradict each other (``status`` INVALID)."""

    def __init__(self, message: str, status: IKStatus | None = None) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class IKSolutions:
    """Every candidate solution of a batch of targets (leading shape ``...``).

    ``q`` (..., m, n): candidate m in branch order (NaN where that branch has no solution);
    ``status`` (..., m): IKStatus per candidate; ``branches`` the m branch names; ``selected``
    (...,) the index the rule picked (-1 if none); ``tie`` (...,) True where another valid
    candidate was exactly as close to the seed; ``explain`` the machine's text for one target
    (the rule used, or why no candidate is valid), called only when a text is asked for, so a
    batch of 10^5 targets builds no strings.
    """

    q: np.ndarray
    status: np.ndarray
    branches: tuple[str, ...]
    selected: np.ndarray
    tie: np.ndarray
    explain: Callable[[IKSolutions, tuple[int, ...]], str] | None = field(default=None, repr=False)

    @property
    def valid(self) -> np.ndarray:
        """(..., m) True for each candidate that is a solution."""
        return self.status == IKStatus.SUCCESS

    @property
    def outcome(self) -> np.ndarray:
        """(...,) the best status over the candidates (SUCCESS where one was selected)."""
        return np.min(self.status, axis=-1)

    @property
    def ok(self) -> np.ndarray:
        return self.selected >= 0

    def failure(self, index: tuple[int, ...] | int = (), branch: str | None = None) -> IKStatus:
        """Why one target has no selected solution: the one rule of every machine's services.

        The best (least) failed status of its candidates, or of the ``branch`` asked for alone
        (the other branches are no answer to that request): UNREACHABLE (NO_IK_SOLUTION) when
        no geometric solution exists, JOINT_LIMITS only when solutions exist and every one breaks
        a limit. INVALID if no candidate failed (nothing was selected all the same).
        """
        status = self.status[index if isinstance(index, tuple) else (index,)]
        if branch is not None and branch in self.branches:
            status = status[[self.branches.index(branch)]]
        failed = status[status != _SUCCESS]
        return IKStatus(int(failed.min())) if failed.size else IKStatus.INVALID

    @property
    def solution(self) -> np.ndarray:
        """(..., n) the selected candidate, NaN where there is none."""
        if self.selected.ndim == 0:  # one target: plain indexing costs a tenth of the general path
            one = int(self.selected)
            return self.q[one].copy() if one >= 0 else np.full(self.q.shape[-1], np.nan)
        index = np.maximum(self.selected, 0)[..., None, None]
        chosen = np.take_along_axis(self.q, index, axis=-2)[..., 0, :]
        return np.where(self.ok[..., None], chosen, np.nan)

    def note(self, index: tuple[int, ...] | int = ()) -> str:
        """The machine's text for one target, else the branch picked or the best failure."""
        index = index if isinstance(index, tuple) else (index,)
        if self.explain is not None:
            return self.explain(self, index)
        chosen = int(self.selected[index])
        if chosen >= 0:
            tie = " (tie: another valid solution is as close to the seed)" if self.tie[index] else ""
            return f"branch {self.branches[chosen]}{tie}"
        return f"no valid solution: {IKStatus(int(self.outcome[index])).name.lower()}"

    def ordered(self, index: tuple[int, ...] | int = ()) -> list[int]:
        """Indices of the valid candidates of one target, the selected one first."""
        chosen = int(self.selected[index])
        valid = np.flatnonzero(self.valid[index])
        return ([chosen] if chosen >= 0 else []) + [int(i) for i in valid if i != chosen]


def select(
    q: np.ndarray,
    status: np.ndarray,
    *,
    seed: ArrayLike | None = None,
    branch: int | None = None,
    weights: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The shared selection rule (module docstring): ``selected`` (...,) and ``tie`` (...,).

    ``q`` (..., m, n) candidates, ``status`` (..., m); ``seed`` (n,) or (..., n); ``branch`` a
    candidate index that alone may be selected; ``weights`` (n,) per-joint scale of the distance
    (e.g. 1 / l for a prismatic joint, so metres and radians weigh alike).
    """
    valid = status == _SUCCESS
    if branch is not None:
        valid = valid & (np.arange(status.shape[-1]) == branch)
    if seed is None:
        first = np.argmax(valid, axis=-1)
        return np.where(valid.any(axis=-1), first, -1), np.zeros(valid.shape[:-1], dtype=bool)
    difference = q - np.asarray(seed, dtype=float)[..., None, :]
    if weights is not None:
        difference *= np.asarray(weights, dtype=float)
    # einsum: a fraction of the memory passes of np.sum(d * d, axis=-1) on large batches.
    cost = np.where(valid, np.einsum("...i,...i->...", difference, difference), np.inf)
    # The lowest cost through argmin: a min reduction over the short candidate axis costs 3x more.
    chosen = np.argmin(cost, axis=-1)
    lowest = np.take_along_axis(cost, chosen[..., None], axis=-1)
    near = valid & (cost <= lowest * (1.0 + TIE_TOLERANCE) + TIE_TOLERANCE)
    # A seed at infinity makes every cost inf: argmin's 0 may be an invalid candidate, the first
    # valid one is the rule's answer then.
    chosen = np.where(
        np.take_along_axis(valid, chosen[..., None], axis=-1)[..., 0], chosen, np.argmax(valid, axis=-1)
    )
    return np.where(valid.any(axis=-1), chosen, -1), near.sum(axis=-1) > 1


def limit_status(q: np.ndarray, limits: JointLimits, tol: float = 1e-10) -> np.ndarray:
    """(..., m) SUCCESS where candidate q (..., m, n) is inside the limits, JOINT_LIMITS outside,
    UNREACHABLE where it is NaN (no solution on that branch)."""
    finite = np.isfinite(q)
    exists = finite[..., 0]
    for joint in range(1, q.shape[-1]):  # joint by joint: np.all over the short last axis costs 6x more
        exists = exists & finite[..., joint]
    inside = limits.within(q, tol)
    return np.where(
        exists,
        np.where(inside, _STATUS8[IKStatus.SUCCESS], _STATUS8[IKStatus.JOINT_LIMITS]),
        _STATUS8[IKStatus.UNREACHABLE],
    )


def describe_limits(q: np.ndarray, limits: JointLimits) -> str:
    """Which joints of ``q`` (n,) are outside ``limits``, with values (m or deg) and the limit."""
    parts = []
    for i, name in enumerate(limits.names):
        linear = bool(limits.prismatic) and limits.prismatic[i]
        show = (lambda v: f"{v:.6g} m") if linear else (lambda v: f"{math.degrees(v):.6g} deg")
        if q[i] < limits.lower[i]:
            parts.append(f"{name} = {show(q[i])} below its limit {show(limits.lower[i])}")
        elif q[i] > limits.upper[i]:
            parts.append(f"{name} = {show(q[i])} above its limit {show(limits.upper[i])}")
    return ", ".join(parts) or "inside every limit"


def level_rotation(up: ArrayLike) -> np.ndarray:
    """(..., 3, 3) rows: the axes of the gravity-aligned *level frame* in a body frame whose world
    up is ``up`` (..., 3): z = up, x = the body's x projected onto the horizontal, y = z x x. Same
    origin and heading as the body, roll and pitch taken out (REP 105's gravity-aligned frames);
    ``p_level = R @ p_body``. Needs a body x that is not vertical (any machine standing)."""
    z = np.asarray(up, dtype=float)
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    x = np.array([1.0, 0.0, 0.0]) - z[..., :1] * z
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    return np.stack([x, np.cross(z, x), z], axis=-2)


def pose_matrix(position: ArrayLike, quaternion: ArrayLike | None = None) -> np.ndarray:
    """4x4 from a position (3,) and a unit quaternion (x, y, z, w) (identity rotation if None)."""
    matrix = np.eye(4)
    matrix[:3, 3] = np.asarray(position, dtype=float)
    if quaternion is not None:
        matrix[:3, :3] = quaternion_matrix(quaternion)
    return matrix


def quaternion_matrix(quaternion: ArrayLike) -> np.ndarray:
    """Rotation matrix (..., 3, 3) of quaternions (..., 4) (x, y, z, w), normalised first."""
    q = np.asarray(quaternion, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def matrix_quaternion(rotation: ArrayLike) -> np.ndarray:
    """Unit quaternions (..., 4) (x, y, z, w) of rotation matrices (..., 3, 3), sign fixed.

    Shepperd's method: the largest of the four squared components is taken from the trace, so
    the result is accurate for every rotation (no division by a small number). Of q and -q the
    one with w > 0 is returned; for a half turn (|w| below 1e-12, e.g. a tool pointing straight
    down) the one whose first non-zero of x, y, z is positive, so round-off in w cannot flip it.
    """
    r = np.asarray(rotation, dtype=float)
    # Row k of Shepperd's symmetric matrix K is 4 q_k q (its diagonal 4 q_k^2): one product with
    # constants builds all four rows (one call instead of some twenty small ones, per message in
    # the forward nodes), the row of the largest diagonal divided by 2 sqrt(K_kk) is q.
    K = (r.reshape(*r.shape[:-2], 9) @ _SHEPPERD + _SHEPPERD_ONE).reshape(*r.shape[:-2], 4, 4)
    diagonal = K.diagonal(axis1=-2, axis2=-1)
    row = np.take_along_axis(K, diagonal.argmax(axis=-1)[..., None, None], axis=-2)[..., 0, :]
    q = row / (2 * np.sqrt(np.maximum(diagonal.max(axis=-1, keepdims=True), 1e-300)))
    leading = np.where(np.abs(q) > QUATERNION_ZERO, q, 0.0)
    # The sign of the first component (w, then x, y, z) that is not zero decides.
    order = leading[..., [3, 0, 1, 2]]
    first = np.take_along_axis(order, np.argmax(order != 0.0, axis=-1)[..., None], axis=-1)
    return np.where(first < 0, -q, q)


@runtime_checkable
class SerialModel(Protocol):
    """What the generic forward node, IK/FK server and bag tools need of a serial machine."""

    @property
    def joint_names(self) -> tuple[str, ...]: ...

    @property
    def limits(self) -> JointLimits: ...

    #: Branch names of :meth:`solve_ik`'s candidates, in preference order.
    ik_branches: tuple[str, ...]
    #: Solver modes :meth:`solve_ik` knows (machine-specific names, e.g. SCARA "fixed_phi").
    ik_modes: tuple[str, ...]

    def fkine(self, q: ArrayLike) -> np.ndarray: ...

    def frames(self, q: ArrayLike) -> np.ndarray: ...

    def jacob0(self, q: ArrayLike) -> np.ndarray: ...

    def solve_ik(
        self,
        target: ArrayLike,
        *,
        use_orientation: bool = True,
        mode: str | None = None,
        seed: ArrayLike | None = None,
        branch: str | None = None,
    ) -> IKSolutions:
        """Every candidate for target poses (..., 4, 4); raises RequestError for an unknown mode
        or branch; a target it cannot take (not finite, outside the machine's plane) gets status
        INVALID or UNREACHABLE with a note, never an exception.

        A machine whose candidates are other joints in some mode (the palletizer's D-H angles
        beside its axis angles) also has ``joint_names_for(mode)``, which the IK server uses to
        name the seed and the solutions."""
        ...
