"""SCARA-type planar arm (P-R-R) of Fu, Zhang and Qiu (2019): position and velocity kinematics.

Numpy only (no rclpy). SI units; REP 103: the arm moves in the base x-y plane, z up, the rail
along base +x. Joints, in this order (names configurable, these are the defaults):

* ``rail_joint``     x_l    prismatic, carriage travel along base +x (m)
* ``shoulder_joint`` theta1 revolute about +z, upper arm angle from +x (rad)
* ``elbow_joint``    theta2 revolute about +z, forearm angle relative to the upper arm (rad)

Forward kinematics, eqs. (9)-(10) in the form consistent with the A matrices of eqs. (3)-(5) (the
extracted paper's eq. 6 swaps sin and cos and eq. 10 adds a stray "+ l2" to py)::

    px  = l1 + x_l + l2 cos(theta1) + l3 cos(theta1 + theta2)
    py  =            l2 sin(theta1) + l3 sin(theta1 + theta2)
    phi = theta1 + theta2                       (tool heading in the plane, wrapped to [-pi, pi))

Inverse kinematics, eqs. (11)-(12) generalised to any tool heading phi (the paper fixes phi = 90
deg and its eq. 12 drops the arcsin): with the wrist point w = p - l3 (cos phi, sin phi),
theta1 = asin(wy / l2) (branch ``elbow_a``, upper arm toward +x, cos theta1 >= 0; the paper's) or
pi - asin(wy / l2) (branch ``elbow_b``, upper arm toward -x), then x_l = wx - l1 - l2 cos theta1
and theta2 = phi - theta1. Three modes:

* ``fixed_phi``: phi = 90 deg, the paper's eq. (12): theta1 = asin((py - l3) / l2).
* ``phi``: phi given with the target.
* ``position``: only (px, py) given; the arm is redundant (3 joints, 2 constraints). Rule: keep
  the seed's tool heading phi = theta1 + theta2 (no seed: 90 deg, the paper's); if no solution at
  that phi is inside the joint limits and away from the singularity, take the nearest phi (least
  |phi - phi_seed|; of equally near ones, within ``HEADING_TIE``, the first candidate) that has
  one. The admissible phi form closed intervals whose ends are where a constraint becomes active,
  each in closed form (|cos theta1| at the singularity threshold, theta1 or theta2 or x_l at a
  limit; the last by the planar two-link IK from the rail end), so the nearest admissible phi is
  exact, not searched.

In every mode the branch is the one asked for, else the one closest to the seed (distance
(dx_l / l2)^2 + dtheta1^2 + dtheta2^2), else ``elbow_a``.

Velocity (the paper's Jacobian, section 2): [px', py', phi'] = J [x_l', theta1', theta2'],
J = [[1, -l2 s1 - l3 s12, -l3 s12], [0, l2 c1 + l3 c12, l3 c12], [0, 1, 1]], det J = l2 cos theta1:
singular when the upper arm is perpendicular to the rail. A configuration counts as singular when
|cos theta1| < ``singularity_threshold`` (default 0.01; joint rates there exceed 100 v / l2 for a
tool speed v).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.model import (
    TIE_TOLERANCE,
    IKSolutions,
    IKStatus,
    RequestError,
    describe_limits,
    limit_status,
    select,
)
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.planar import two_link_ik, wrap_angle
from manipulator_kinematics.schema import Names, Number, Numbers, Schema, Text, require, validate
from manipulator_kinematics.serial_chain import JointLimits, SerialChain, prismatic, revolute, troty

BRANCHES = ("elbow_a", "elbow_b")
MODES = ("fixed_phi", "phi", "position")
#: The paper's working tool heading (eq. 11: theta1 + theta2 = 90 deg).
PAPER_PHI = math.pi / 2
#: Values this close (m or rad) outside a limit count as on it and are clipped to it.
LIMIT_TOL = 1e-10
#: Mode position: headings whose distances to the preferred one differ by less than this (rad) are
#: equally near, the first in candidate order is taken (mirror images, e.g. both elbow limits with
#: symmetric limits and no seed, would otherwise be decided by the last bits of arctan2).
HEADING_TIE = 1e-12
#: |z| of a target (m) and tilt / heading mismatch of a target orientation (rad) taken as zero.
PLANE_TOL = 1e-6
CONFIG_FILE = "scara.yaml"

#: The ``scara:`` section of a parameters file (manipulator_kinematics.schema).
SCHEMA: Schema = {
    "name": Text(empty=False, default="scara", doc="the machine's name: the robot name of its URDF"),
    "l1": Number(min=0.0, max=100.0, unit="m", doc="base offset: shoulder x at rail_joint = 0 (m)"),
    "l2": Number(min=0.0, max=100.0, unit="m", exclusive_min=True, doc="upper arm, shoulder to elbow (m)"),
    "l3": Number(min=0.0, max=100.0, unit="m", exclusive_min=True, doc="forearm, elbow to tool point (m)"),
    "joint_names": Names(3, doc="rail, shoulder, elbow joint names"),
    "joint_min": Numbers(3, doc="lower limits: rail (m), shoulder and elbow (rad)"),
    "joint_max": Numbers(3, doc="upper limits: rail (m), shoulder and elbow (rad)"),
    "singularity_threshold": Number(min=0.0, max=1.0, doc="singular where |cos theta1| is below this"),
}


# Plain ints for array work (IntEnum members cost an attribute lookup and a conversion per use).
_SUCCESS, _SINGULAR, _JOINT_LIMITS, _UNREACHABLE, _INVALID = (int(s) for s in IKStatus)
#: The seeds of a batch without one (ik_kernel.solve_ik_batch reads its row, never uses it).
_NO_SEEDS = np.zeros((1, 3))


@dataclass(frozen=True)
class VelocityIK:
    """Joint rates (..., 3) for a tool velocity; NaN where ``singular`` (...,) is True."""

    qd: np.ndarray
    singular: np.ndarray


@dataclass(frozen=True)
class HeadingIK:
    """:meth:`Scara.ik`'s answer for a batch of targets (leading shape ``...``): the shared
    :class:`~manipulator_kinematics.model.IKSolutions` of both branches at the heading solved for
    (``solutions``: candidates, statuses, the shared rule's selection and the text), with what the
    heading modes add: ``status`` (...,) the target's outcome (mode ``position``: the best over
    every heading tried), ``phi`` (...,) the heading solved for (mode ``position``: the one chosen)
    and ``preferred_phi`` the one the rule started from.
    """

    solutions: IKSolutions
    status: np.ndarray
    phi: np.ndarray
    preferred_phi: np.ndarray

    @property
    def q(self) -> np.ndarray:
        """(..., 3) the selected solution, NaN where there is none."""
        return self.solutions.solution

    @property
    def branch(self) -> np.ndarray:
        """(...,) the selected branch's index into ``BRANCHES``, -1 if none."""
        return self.solutions.selected

    @property
    def candidates(self) -> np.ndarray:
        """(..., 2, 3) both branches at ``phi`` (NaN where a branch does not reach)."""
        return self.solutions.q

    @property
    def branch_status(self) -> np.ndarray:
        """(..., 2) the IKStatus of each branch."""
        return self.solutions.status

    @property
    def valid(self) -> np.ndarray:
        """(..., 2) True for each branch that is a solution (inside limits, not singular)."""
        return self.solutions.valid

    @property
    def ok(self) -> np.ndarray:
        return self.status == _SUCCESS

    def reason(self, index: tuple[int, ...] | int = ()) -> str:
        """Human-readable outcome of one target: the branch and rule used, or why it failed."""
        return self.solutions.note(index)


class Scara:
    """The P-R-R arm: geometry l1, l2, l3 (m), joint limits, singularity threshold."""

    def __init__(
        self,
        l1: float,
        l2: float,
        l3: float,
        limits: JointLimits,
        singularity_threshold: float = 0.01,
        name: str = "scara",
    ) -> None:
        if not (l1 >= 0.0 and l2 > 0.0 and l3 > 0.0):
            raise ValueError(f"need l1 >= 0, l2 > 0, l3 > 0; got {l1}, {l2}, {l3}")
        if len(limits.names) != 3:
            raise ValueError("the SCARA has three joints: rail, shoulder, elbow")
        if not 0.0 <= singularity_threshold < 1.0:
            raise ValueError(f"singularity_threshold must be in [0, 1), got {singularity_threshold}")
        self.l1, self.l2, self.l3 = float(l1), float(l2), float(l3)
        self.limits = limits
        self.singularity_threshold = float(singularity_threshold)
        self.name = name

    # ---- construction -------------------------------------------------------------------------
    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], prefix: str = "scara") -> Scara:
        """From the nested ``scara:`` section of a parameters file; ConfigError names a bad key."""
        p = validate(params, SCHEMA, prefix)
        names, lower, upper = p["joint_names"], p["joint_min"], p["joint_max"]
        for i in range(3):
            require(
                lower[i] < upper[i],
                f"{prefix}.joint_min[{i}]",
                f"{lower[i]} must be below {prefix}.joint_max[{i}] = {upper[i]} ({names[i]})",
            )
        for i in (1, 2):
            for key, value in (("joint_min", lower[i]), ("joint_max", upper[i])):
                require(
                    abs(value) <= math.pi,
                    f"{prefix}.{key}[{i}]",
                    f"{value} rad ({names[i]}) is outside [-pi, pi]: limits are radians and the "
                    "solver returns angles in [-pi, pi)",
                )
        require(
            p["singularity_threshold"] < 1.0,
            f"{prefix}.singularity_threshold",
            f"{p['singularity_threshold']} must be below 1 (it bounds |cos theta1|)",
        )
        limits = JointLimits(tuple(names), np.array(lower), np.array(upper), prismatic=(True, False, False))
        return cls(p["l1"], p["l2"], p["l3"], limits, p["singularity_threshold"], p["name"])

    @classmethod
    def default(cls) -> Scara:
        """The reference machine of ``config/scara.yaml``."""
        return cls.from_parameters(load_parameters(config_path(CONFIG_FILE)).get("scara", {}))

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.limits.names

    @cached_property
    def chain(self) -> SerialChain:
        """The same arm as a standard D-H chain (the paper's Table 1 made spatial).

        Base transform Ry(90 deg) turns z_0 along base +x for the rail (D-H prismatic joints move
        along z); row 1 (theta = 90, alpha = -90 deg, offset l1) brings z_1 back to base +z;
        the shoulder's offset -90 deg makes theta1 = 0 point along base +x. The tool frame has x
        along the forearm and z up, so its pose is (px, py, 0) and yaw phi.
        """
        rows = [
            prismatic(theta=math.pi / 2, alpha=-math.pi / 2, offset=self.l1),
            revolute(a=self.l2, offset=-math.pi / 2),
            revolute(a=self.l3),
        ]
        return SerialChain(rows, base=troty(math.pi / 2))

    # ---- position and velocity ----------------------------------------------------------------
    def fk(self, q: ArrayLike) -> np.ndarray:
        """[px, py, phi] (..., 3) of joint values (..., 3), eqs. (9)-(10)."""
        rail, t1, t2 = _columns(q)
        t12 = t1 + t2
        px = self.l1 + rail + self.l2 * np.cos(t1) + self.l3 * np.cos(t12)
        py = self.l2 * np.sin(t1) + self.l3 * np.sin(t12)
        return np.stack([px, py, wrap_angle(t12)], axis=-1)

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """J (..., 3, 3) with [px', py', phi'] = J [x_l', theta1', theta2'] (the paper's section 2)."""
        _, t1, t2 = _columns(q)
        s1, c1 = np.sin(t1), np.cos(t1)
        s12, c12 = np.sin(t1 + t2), np.cos(t1 + t2)
        one, zero = np.ones_like(t1), np.zeros_like(t1)
        return np.stack(
            [
                np.stack([one, -self.l2 * s1 - self.l3 * s12, -self.l3 * s12], axis=-1),
                np.stack([zero, self.l2 * c1 + self.l3 * c12, self.l3 * c12], axis=-1),
                np.stack([zero, one, one], axis=-1),
            ],
            axis=-2,
        )

    def manipulability(self, q: ArrayLike) -> np.ndarray:
        """det J = l2 cos theta1 (...,)."""
        return self.l2 * np.cos(_columns(q)[1])

    def singular(self, q: ArrayLike) -> np.ndarray:
        """(...,) True where |cos theta1| < singularity_threshold."""
        return np.abs(np.cos(_columns(q)[1])) < self.singularity_threshold * (1.0 - 1e-9)

    def velocity_fk(self, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
        """Tool velocity [px', py', phi'] (..., 3) = J qd."""
        return np.einsum("...ij,...j->...i", self.jacobian(q), np.asarray(qd, dtype=float))

    def velocity_ik(self, q: ArrayLike, xd: ArrayLike) -> VelocityIK:
        """Joint rates for tool velocity xd = [px', py', phi'] (..., 3): J^-1 xd in closed form.

        From the last two rows: theta1' = (py' - l3 c12 phi') / (l2 c1), theta2' = phi' - theta1';
        then x_l' from the first row. NaN where the configuration is singular.
        """
        _, t1, t2 = _columns(q)
        vx, vy, w = _columns(xd)
        s1, c1 = np.sin(t1), np.cos(t1)
        s12, c12 = np.sin(t1 + t2), np.cos(t1 + t2)
        singular = self.singular(q)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1d = (vy - self.l3 * c12 * w) / (self.l2 * c1)
        t2d = w - t1d
        raild = vx + (self.l2 * s1 + self.l3 * s12) * t1d + self.l3 * s12 * t2d
        qd = np.stack([raild, t1d, t2d], axis=-1)
        return VelocityIK(qd=np.where(singular[..., None], np.nan, qd), singular=singular)

    def limit_violation(self, q: ArrayLike) -> np.ndarray:
        """(..., 3): -1 below, +1 above (or NaN), 0 inside each joint's limits (stroke of the rail)."""
        return self.limits.violation(q, LIMIT_TOL)

    def within_limits(self, q: ArrayLike) -> np.ndarray | np.bool_:
        return self.limits.within(q, LIMIT_TOL)

    # ---- the shared model protocol (manipulator_kinematics.model.SerialModel) -----------------
    ik_modes = MODES
    ik_branches = BRANCHES

    def fkine(self, q: ArrayLike) -> np.ndarray:
        """Tool pose (..., 4, 4): the point (px, py, 0) with heading phi about base +z (eqs. 9-10)."""
        x = self.fk(q)
        c, s = np.cos(x[..., 2]), np.sin(x[..., 2])
        pose = np.zeros(x.shape[:-1] + (4, 4))
        pose[..., 0, 0], pose[..., 0, 1], pose[..., 1, 0], pose[..., 1, 1] = c, -s, s, c
        pose[..., 2, 2] = pose[..., 3, 3] = 1.0
        pose[..., 0, 3], pose[..., 1, 3] = x[..., 0], x[..., 1]
        return pose

    def frames(self, q: ArrayLike) -> np.ndarray:
        """Base, carriage, upper arm, forearm and tool frames (..., 5, 4, 4) of the D-H chain."""
        links = self.chain.fkine(q, all_frames=True)
        return np.concatenate([links, self.fkine(q)[..., None, :, :]], axis=-3)

    def jacob0(self, q: ArrayLike) -> np.ndarray:
        """Geometric Jacobian (..., 6, 3) of the tool point; rows vx, vy, wz are :meth:`jacobian`'s."""
        rows = self.jacobian(q)
        out = np.zeros(rows.shape[:-2] + (6, 3))
        out[..., 0, :], out[..., 1, :], out[..., 5, :] = rows[..., 0, :], rows[..., 1, :], rows[..., 2, :]
        return out

    def solve_ik(
        self,
        target: ArrayLike,
        *,
        use_orientation: bool = True,
        mode: str | None = None,
        seed: ArrayLike | None = None,
        branch: str | None = None,
    ) -> IKSolutions:
        """:meth:`ik` for target poses (..., 4, 4): the protocol's entry (SolveIK).

        Mode default: ``phi`` with an orientation, ``position`` without. A target off the plane
        z = 0 or whose tool z axis is tilted is UNREACHABLE; mode ``phi`` without an orientation,
        ``position`` with one, or ``fixed_phi`` with a heading other than 90 deg are refused.
        """
        mode = mode or ("phi" if use_orientation else "position")
        if mode not in MODES:
            raise RequestError(f"unknown mode {mode!r}; known: {', '.join(MODES)}")
        if branch is not None and branch not in BRANCHES:
            raise RequestError(
                f"unknown branch {branch!r}; known: {', '.join(BRANCHES)} (empty = closest to the seed)"
            )
        if mode == "phi" and not use_orientation:
            raise RequestError(
                "mode 'phi' takes the heading from the target orientation: set use_orientation",
                IKStatus.INVALID,
            )
        if mode == "position" and use_orientation:
            raise RequestError(
                "mode 'position' leaves the heading free: use mode 'phi' to give an orientation",
                IKStatus.INVALID,
            )
        target = np.asarray(target, dtype=float)
        requested = None if branch is None else BRANCHES.index(branch)
        if target.shape == (4, 4):
            kernel = compiled_kernel(self)
            seed = _checked_seed(seed)
            if kernel is not None and (seed is None or seed.shape == (3,)):
                return self._solve_ik_one(kernel, target, use_orientation, mode, seed, requested)
        elif (
            target.ndim == 3 and target.shape[1:] == (4, 4) and (kernel := compiled_kernel(self)) is not None
        ):
            seed = _checked_seed(seed)
            if seed is None or seed.shape in ((3,), (len(target), 3)):
                many = self._solve_ik_many(kernel, target, use_orientation, mode, seed, requested)
                if many is not None:
                    return many
        finite = np.all(np.isfinite(target), axis=(-2, -1))
        position = target[..., :3, 3]
        heading = np.arctan2(target[..., 1, 0], target[..., 0, 0])
        with np.errstate(invalid="ignore"):
            tilt = np.arccos(np.clip(target[..., 2, 2], -1.0, 1.0))
        if mode == "fixed_phi" and use_orientation:
            off = finite & (np.abs(wrap_angle(heading - PAPER_PHI)) > PLANE_TOL)
            if np.any(off):
                raise _not_fixed_phi(float(heading[off].ravel()[0]))
        result = self.ik(
            position[..., :2], mode=mode, phi=heading if mode == "phi" else None, seed=seed, branch=branch
        )
        off_plane = finite & (np.abs(position[..., 2]) > PLANE_TOL)
        tilted = finite & (tilt > PLANE_TOL) if use_orientation else np.zeros_like(off_plane)
        refused = off_plane | tilted
        solved = result.solutions
        status = solved.status.copy()
        status[refused] = _UNREACHABLE
        status[~finite] = _INVALID
        if requested is not None:  # the other branch is no solution of this request
            status[..., 1 - requested] = np.maximum(status[..., 1 - requested], _JOINT_LIMITS)
        answered = ~refused & finite
        selected = np.where(answered, solved.selected, -1).astype(np.int8)

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            if off_plane[index]:
                return _off_plane_text(float(position[index + (2,)]))
            if tilted[index]:
                return _tilted_text(float(tilt[index]))
            return solved.note(index)

        return IKSolutions(
            q=solved.q,
            status=status,
            branches=BRANCHES,
            selected=selected,
            tie=answered & solved.tie,
            explain=explain,
        )

    def _solve_ik_one(
        self,
        kernel: ModuleType,
        target: np.ndarray,
        use_orientation: bool,
        mode: str,
        seed: np.ndarray | None,
        requested: int | None,
    ) -> IKSolutions:
        """:meth:`solve_ik` of one target (4, 4), mode and branch checked: the same steps in Python
        floats around the compiled kernel (:meth:`_kernel_one`). Issue #32: on 0-d arrays they cost
        2.5x :meth:`ik`, more than the kernel itself (a reduction over two axes alone 9 us)."""
        rows = target.tolist()
        finite = all(map(math.isfinite, rows[0] + rows[1] + rows[2] + rows[3]))
        x, y, z = rows[0][3], rows[1][3], rows[2][3]
        heading = math.atan2(rows[1][0], rows[0][0])
        tilt = math.acos(min(max(rows[2][2], -1.0), 1.0))  # NaN stays NaN
        if mode == "fixed_phi" and use_orientation and finite and abs(_wrap(heading - PAPER_PHI)) > PLANE_TOL:
            raise _not_fixed_phi(heading)
        q, found, selected, tie, outcome, phi_used, preferred = self._kernel_one(
            kernel, mode, x, y, heading if mode == "phi" else None, seed, requested
        )
        off_plane = finite and abs(z) > PLANE_TOL
        tilted = finite and use_orientation and tilt > PLANE_TOL
        status = found.copy()
        if off_plane or tilted:
            status[:] = _UNREACHABLE
        if not finite:
            status[:] = _INVALID
        if requested is not None:  # the other branch is no solution of this request
            status[1 - requested] = max(status[1 - requested], _JOINT_LIMITS)
        answered = finite and not (off_plane or tilted)

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            if off_plane:
                return _off_plane_text(z)
            if tilted:
                return _tilted_text(tilt)
            solved = IKSolutions(
                q=q, status=found, branches=BRANCHES, selected=np.array(selected), tie=np.array(tie)
            )  # what ik answered, for its text
            return self._explain(
                solved, index, mode, phi_used, preferred, outcome, seed is not None, requested
            )

        return IKSolutions(
            q=q,
            status=status,
            branches=BRANCHES,
            selected=np.array(selected if answered else -1, dtype=np.int8),
            tie=np.array(answered and bool(tie)),
            explain=explain,
        )

    def _solve_ik_many(
        self,
        kernel: ModuleType,
        target: np.ndarray,
        use_orientation: bool,
        mode: str,
        seed: np.ndarray | None,
        requested: int | None,
    ) -> IKSolutions | None:
        """:meth:`solve_ik` of targets (N, 4, 4), seed (3,) or (N, 3), through the kernel's loop
        (ik_kernel.solve_ik_batch, the steps of :meth:`_solve_ik_one`), None for arguments of
        types the loop does not take (:func:`_warm`); a target's text is its single call's, made
        when asked for. Issue #32: on the numpy path a batch of one cost 19x a
        single call, and a batch paid from 30 targets on."""
        n = len(target)
        q, status = np.empty((n, 2, 3)), np.empty((n, 2), dtype=np.int8)
        selected, tie = np.empty(n, dtype=np.int8), np.empty(n, dtype=bool)
        try:
            off = kernel.solve_ik_batch(
                self._packed,
                np.ascontiguousarray(target),
                _NO_SEEDS if seed is None else np.ascontiguousarray(seed.reshape(-1, 3)),
                seed is not None,
                -1 if requested is None else requested,
                TIE_TOLERANCE,
                MODES.index(mode),
                bool(use_orientation),
                PAPER_PHI,
                PLANE_TOL,
                q,
                status,
                selected,
                tie,
            )
        except TypeError:
            return None
        if off >= 0:
            raise _not_fixed_phi(math.atan2(target[off, 1, 0], target[off, 0, 0]))

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            one = self.solve_ik(
                target[index],
                use_orientation=use_orientation,
                mode=mode,
                seed=seed if seed is None or seed.ndim == 1 else seed[index],
                branch=None if requested is None else BRANCHES[requested],
            )
            return one.note()

        return IKSolutions(q=q, status=status, branches=BRANCHES, selected=selected, tie=tie, explain=explain)

    def state_note(self, q: ArrayLike) -> str:
        """A remark on one joint state for FK answers: near the singularity, or nothing."""
        return (
            f"near the singularity: |cos theta1| = {abs(math.cos(float(np.asarray(q)[1]))):.3g}"
            if self.singular(q)
            else ""
        )

    # ---- inverse kinematics -------------------------------------------------------------------
    def ik(
        self,
        position: ArrayLike,
        *,
        mode: str = "phi",
        phi: ArrayLike | None = None,
        seed: ArrayLike | None = None,
        branch: str | None = None,
        compiled: bool = True,
    ) -> HeadingIK:
        """Joint solutions for tool positions (..., 2) = [px, py] (module docstring: modes, rule).

        ``phi`` (...,) is required in mode ``phi`` and refused otherwise; ``seed`` (3,) or (..., 3)
        a current joint state; ``branch`` None (closest to the seed) or a name of ``BRANCHES``.
        Raises ValueError for an unknown mode or branch, a bad shape or a non-finite seed; a
        non-finite target gives status INVALID. One target (with one seed or none) runs the
        compiled kernel (:func:`compiled_kernel`) in every mode unless not ``compiled``.
        """
        if mode not in MODES:
            raise ValueError(f"unknown IK mode {mode!r}; known: {', '.join(MODES)}")
        if branch is not None and branch not in BRANCHES:
            raise ValueError(f"unknown branch {branch!r}; known: {', '.join(BRANCHES)}")
        if (phi is None) == (mode == "phi"):
            raise ValueError("phi is given in mode 'phi' and only there")
        position = np.asarray(position, dtype=float)
        if position.ndim == 0 or position.shape[-1] != 2:
            raise ValueError(f"positions must have shape (..., 2), got {position.shape}")
        px, py = position[..., 0], position[..., 1]
        if phi is not None:
            phi = np.asarray(phi, dtype=float)
            if phi.shape != px.shape:
                px, py, phi = np.broadcast_arrays(px, py, phi)
        seed = _checked_seed(seed)
        requested = None if branch is None else BRANCHES.index(branch)
        one = px.ndim == 0 and compiled and (seed is None or seed.shape == (3,))
        kernel = compiled_kernel(self) if one else None
        if kernel is not None:
            return self._ik_one(
                kernel, mode, float(px), float(py), None if phi is None else float(phi), seed, requested
            )
        if mode == "position":
            preferred = (
                np.full(px.shape, PAPER_PHI)
                if seed is None
                else wrap_angle(np.broadcast_to(seed[..., 1] + seed[..., 2], px.shape))
            )
            phi_used, q, status, outcome = self._position_ik(px, py, preferred, requested)
            selected, tie = select(q, status, seed=seed, branch=requested, weights=self._weights)
        else:
            phi_used = preferred = np.full(px.shape, PAPER_PHI) if phi is None else wrap_angle(phi)
            q, status = self._solve_phi(px, py, phi_used)
            selected, tie = select(q, status, seed=seed, branch=requested, weights=self._weights)
            # The best status of the branches that may answer (np.minimum: a reduction over an axis of
            # two costs several times more on a batch).
            outcome = (
                np.minimum(status[..., 0], status[..., 1]) if requested is None else status[..., requested]
            )
        finite = np.isfinite(px) & np.isfinite(py) & np.isfinite(phi_used)
        outcome = np.where(finite, outcome, _INVALID).astype(np.int8)
        if not finite.all():
            status = np.where(finite[..., None], status, _INVALID).astype(np.int8)

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            return self._explain(
                solutions,
                index,
                mode,
                float(phi_used[index]),
                float(preferred[index]),
                int(outcome[index]),
                seed is not None,
                requested,
            )

        solutions = IKSolutions(
            q=q, status=status, branches=BRANCHES, selected=selected, tie=tie, explain=explain
        )
        return HeadingIK(solutions=solutions, status=outcome, phi=phi_used, preferred_phi=preferred)

    def describe(self, q: np.ndarray, status: IKStatus, phi: float) -> str:
        """Why one branch's joint values ``q`` (3,) have ``status`` (for messages)."""
        if status is IKStatus.UNREACHABLE:
            return (
                f"wrist point out of the upper arm's reach (|wy| > l2 = {self.l2:.6g} m with "
                f"phi = {math.degrees(phi):.6g} deg)"
            )
        if status is IKStatus.JOINT_LIMITS:
            return describe_limits(q, self.limits)
        if status is IKStatus.SINGULAR:
            return (
                f"singular: |cos theta1| = {abs(math.cos(q[1])):.3g} < {self.singularity_threshold:g} "
                "(upper arm perpendicular to the rail)"
            )
        return f"solution {', '.join(f'{n} = {_show(i, q[i])}' for i, n in enumerate(self.joint_names))}"

    def _explain(
        self,
        solutions: IKSolutions,
        index: tuple[int, ...],
        mode: str,
        phi: float,
        preferred: float,
        outcome: int,
        seeded: bool,
        requested: int | None,
    ) -> str:
        """The text of one target: the branch and rule used, or why it failed."""
        status = IKStatus(outcome)
        if status is IKStatus.SUCCESS:
            name = BRANCHES[int(solutions.selected[index])]
            text = f"{mode} mode: branch {name}, phi = {math.degrees(phi):.6g} deg"
            if mode == "position":
                source = "the seed's" if seeded else "the paper's (no seed)"
                if abs(wrap_angle(phi - preferred)) < 1e-12:
                    text += f" (kept {source} heading)"
                else:
                    text += (
                        f" (moved from {source} heading {math.degrees(preferred):.6g} deg: the nearest"
                        " one with a solution inside the joint limits, away from the singularity)"
                    )
            return text
        if status is IKStatus.INVALID:
            return "target is not finite"
        if mode == "position":
            head = "no tool heading phi gives a solution inside the joint limits away from the singularity"
            if status is IKStatus.UNREACHABLE:
                return f"{head}: the target is farther than l2 + l3 = {self.l2 + self.l3:.6g} m from the rail"
            head += f"; at phi = {math.degrees(phi):.6g} deg"
        else:
            head = f"{mode} mode, phi = {math.degrees(phi):.6g} deg"
        q, branch_status = solutions.q[index], solutions.status[index]
        branches = range(2) if requested is None else (requested,)
        parts = [
            f"{BRANCHES[b]}: {self.describe(q[b], IKStatus(int(branch_status[b])), phi)}" for b in branches
        ]
        return f"{head}: " + "; ".join(parts)

    @cached_property
    def _weights(self) -> np.ndarray:
        """Seed distance weights (1 / l2, 1, 1): (dx_l / l2)^2 + dtheta1^2 + dtheta2^2."""
        return np.array([1.0 / self.l2, 1.0, 1.0])

    def _solve_phi(self, px: np.ndarray, py: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both branches (..., 2, 3) and their statuses (..., 2) for heading phi: eqs. (11)-(12)
        generalised from the wrist point w = p - l3 (cos phi, sin phi)."""
        wx = px - self.l3 * np.cos(phi)
        wy = py - self.l3 * np.sin(phi)
        sin1 = wy / self.l2  # eq. (12): sin theta1 = wy / l2
        reachable = np.abs(sin1) <= 1.0 + 1e-12
        sin1 = np.minimum(np.maximum(sin1, -1.0), 1.0)
        cos1 = np.sqrt(1.0 - sin1 * sin1)  # branch a; -cos1 on branch b
        # q[..., b, :] = (x_l, theta1, theta2) of branch b, written in place (np.stack costs more
        # than the arithmetic for one target). Branch b: theta1 = pi - asin, kept in (-pi, pi].
        q = np.empty(sin1.shape + (2, 3))
        theta1_a = np.arcsin(sin1, out=q[..., 0, 1])
        np.subtract(np.copysign(np.pi, theta1_a), theta1_a, out=q[..., 1, 1])
        shoulder, reach = wx - self.l1, self.l2 * cos1
        np.subtract(shoulder, reach, out=q[..., 0, 0])  # eq. (11): x_l = wx - l1 - l2 cos theta1
        np.add(shoulder, reach, out=q[..., 1, 0])
        q[..., 2] = wrap_angle(phi[..., None] - q[..., 1])  # theta1 + theta2 = phi
        q[~reachable] = np.nan
        status = limit_status(q, self.limits, LIMIT_TOL)
        inside = status == _SUCCESS
        q = np.where(inside[..., None], self.limits.clip(q), q)  # within LIMIT_TOL outside: put on the limit
        singular = cos1 < self.singularity_threshold * (1.0 - 1e-9)
        status[inside & singular[..., None]] = _SINGULAR
        return q, status

    def _ik_one(
        self,
        kernel: ModuleType,
        mode: str,
        px: float,
        py: float,
        phi: float | None,
        seed: np.ndarray | None,
        requested: int | None,
    ) -> HeadingIK:
        """:meth:`ik` of one target through the compiled kernel (:meth:`_kernel_one`)."""
        q, status, selected, tie, outcome, phi_used, preferred = self._kernel_one(
            kernel, mode, px, py, phi, seed, requested
        )

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            return self._explain(
                solutions, index, mode, phi_used, preferred, outcome, seed is not None, requested
            )

        solutions = IKSolutions(
            q=q,
            status=status,
            branches=BRANCHES,
            selected=np.array(selected),
            tie=np.array(tie),
            explain=explain,
        )
        return HeadingIK(
            solutions=solutions,
            status=np.array(outcome, dtype=np.int8),
            phi=np.array(phi_used),
            preferred_phi=np.array(preferred),
        )

    def _kernel_one(
        self,
        kernel: ModuleType,
        mode: str,
        px: float,
        py: float,
        phi: float | None,
        seed: np.ndarray | None,
        requested: int | None,
    ) -> tuple[Any, ...]:
        """:meth:`ik`'s steps for one target in Python floats around the compiled kernel (on 0-d
        arrays they cost several times the kernel, issue #32): q (2, 3), status (2,), and the
        selection, tie, outcome, heading used and preferred heading as Python numbers."""
        q, status = np.empty((2, 3)), np.empty(2, dtype=np.int8)
        seeded = seed is not None
        start = seed if seeded else self._packed[:3]
        chosen = -1 if requested is None else requested
        if mode == "position":
            preferred = PAPER_PHI if seed is None else _wrap(float(seed[1]) + float(seed[2]))
            phi_used, selected, tie, outcome = kernel.solve_position(
                self._packed, px, py, preferred, start, seeded, chosen, TIE_TOLERANCE, q, status
            )
        else:
            phi_used = preferred = PAPER_PHI if phi is None else _wrap(phi)
            selected, tie = kernel.solve_phi(
                self._packed, px, py, phi_used, start, seeded, chosen, TIE_TOLERANCE, q, status
            )
            first, second = status.tolist()
            outcome = min(first, second) if requested is None else (first, second)[requested]
        if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(phi_used)):
            outcome = int(_INVALID)
            status[:] = _INVALID
        return q, status, selected, tie, outcome, phi_used, preferred

    @cached_property
    def _packed(self) -> np.ndarray:
        """The kernel's constants (scara_kinematics.ik_kernel): l1, l2, l3, the limits widened by
        LIMIT_TOL (6), the limits (6), the singularity threshold, the seed weights (3); for mode
        position the wrist heights (4), the elbow limits' distances^2 (2) and turns (2) of
        :attr:`_constraint_constants`, the band l2 + l3 + LIMIT_TOL an unbounded rail reaches, and
        HEADING_TIE."""
        lower, upper = self.limits.lower, self.limits.upper
        wrist_heights, elbow_r2, elbow_turn, _ = self._constraint_constants
        return np.concatenate(
            [
                [self.l1, self.l2, self.l3],
                lower - LIMIT_TOL,
                upper + LIMIT_TOL,
                lower,
                upper,
                [self.singularity_threshold * (1.0 - 1e-9)],
                self._weights,
                wrist_heights,
                elbow_r2,
                elbow_turn[:2],
                [self.l2 + self.l3 + LIMIT_TOL, HEADING_TIE],
            ]
        )

    def _position_ik(
        self, px: np.ndarray, py: np.ndarray, preferred: np.ndarray, requested: int | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Position mode: the admissible heading nearest ``preferred`` (module docstring); the
        heading, both branches there and their statuses, and the target's outcome over every heading."""
        headings = self._candidate_headings(px, py, preferred)
        candidates, branch_status = self._solve_phi(px[..., None], py[..., None], headings)
        allowed = _allowed(requested)
        admissible = np.any((branch_status == _SUCCESS) & allowed, axis=-1)
        distance = np.where(admissible, np.abs(wrap_angle(headings - preferred[..., None])), np.inf)
        # The first of the nearest within HEADING_TIE; with none admissible (every distance inf) column
        # 0, the preferred heading itself.
        nearest = np.min(distance, axis=-1, keepdims=True)
        k = np.argmax(distance <= nearest + HEADING_TIE, axis=-1)
        phi = np.take_along_axis(headings, k[..., None], axis=-1)[..., 0]
        picked = np.take_along_axis(candidates, k[..., None, None, None], axis=-3)[..., 0, :, :]
        picked_status = np.take_along_axis(branch_status, k[..., None, None], axis=-2)[..., 0, :]
        outcome = np.min(np.where(allowed, branch_status, _INVALID), axis=(-2, -1))
        # With the rail unbounded every |py| <= l2 + l3 is reachable: if no candidate reached it,
        # the rail's stroke (a joint limit) is what stops it.
        in_band = np.abs(py) <= self.l2 + self.l3 + LIMIT_TOL
        outcome = np.where(in_band & (outcome == _UNREACHABLE), _JOINT_LIMITS, outcome)
        return phi, picked, picked_status, outcome.astype(np.int8)

    def _candidate_headings(self, px: np.ndarray, py: np.ndarray, preferred: np.ndarray) -> np.ndarray:
        """(..., 17) headings: the preferred one, then every heading where a constraint is active."""
        wrist_heights, elbow_r2, elbow_turn, rail_ends = self._constraint_constants
        py_ = py[..., None]
        with np.errstate(invalid="ignore"):
            # wy = py - l3 sin phi at a given value: the singularity band and the shoulder limits.
            wrist = np.arcsin((py_ - wrist_heights) / self.l3)
            # Elbow at a limit: the shoulder lies at distance r from p on the rail line y = 0.
            dx = np.sqrt(elbow_r2 - py_ * py_)
            elbow = np.arctan2(np.broadcast_to(py_, dx.shape[:-1] + (4,)), np.concatenate([dx, -dx], axis=-1))
            # Rail at a stroke end: the planar two-link arm from that shoulder position.
            arm = two_link_ik(px[..., None] - self.l1 - rail_ends, py_, self.l2, self.l3)
        rail = (arm.theta1 + arm.theta2).reshape(arm.theta1.shape[:-2] + (4,))
        columns = (preferred[..., None], wrist, np.pi - wrist, elbow + elbow_turn, rail)
        return wrap_angle(np.concatenate(columns, axis=-1))

    @cached_property
    def _constraint_constants(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per constraint of the position-mode rule: wrist heights l2 sin(theta1) at the singularity band
        and the shoulder limits (4,); shoulder-to-tool distance^2 at the elbow limits (2,); phi minus the
        direction shoulder -> tool at those limits, for dx >= 0 then dx <= 0 (4,); the rail ends (2,)."""
        lower, upper = self.limits.lower, self.limits.upper
        sin_singular = math.sqrt(1.0 - self.singularity_threshold**2)
        wrist = self.l2 * np.array([sin_singular, -sin_singular, math.sin(lower[1]), math.sin(upper[1])])
        t2 = np.array([lower[2], upper[2]])
        r2 = self.l2**2 + self.l3**2 + 2.0 * self.l2 * self.l3 * np.cos(t2)
        turn = t2 - np.arctan2(self.l3 * np.sin(t2), self.l2 + self.l3 * np.cos(t2))
        return wrist, r2, np.concatenate([turn, turn]), np.array([lower[0], upper[0]])


def _warm(ik_kernel: ModuleType, packed: np.ndarray) -> None:
    """Run the kernel once (numba loads or compiles it)."""
    q, status = np.empty((2, 3)), np.empty(2, dtype=np.int8)
    ik_kernel.solve_phi(packed, 0.5, 0.3, PAPER_PHI, packed[:3], True, -1, TIE_TOLERANCE, q, status)
    ik_kernel.solve_position(packed, 0.5, 0.3, PAPER_PHI, packed[:3], True, -1, TIE_TOLERANCE, q, status)
    ik_kernel.solve_ik_batch(
        packed,
        np.eye(4)[None],
        _NO_SEEDS,
        False,
        -1,
        TIE_TOLERANCE,
        1,
        True,
        PAPER_PHI,
        PLANE_TOL,
        q[None],
        status[None],
        np.empty(1, dtype=np.int8),
        np.empty(1, dtype=bool),
    )
    # The batch takes only these types: another (a read-only view, say) raises TypeError and the
    # call takes the numpy path, instead of compiling for seconds inside the call.
    ik_kernel.solve_ik_batch.disable_compile()


#: The single-target kernel (:mod:`scara_kinematics.ik_kernel`), see manipulator_kinematics.compiled.
KERNEL = Kernel("scara_kinematics.ik_kernel", _warm)


def compiled_kernel(scara: Scara, wait: bool = False) -> ModuleType | None:
    """:data:`KERNEL` once loaded, else None and its load started; ``wait``: load it first."""
    return KERNEL.get(scara._packed, wait=wait)


def _checked_seed(seed: ArrayLike | None) -> np.ndarray | None:
    """The seed as floats, or ValueError unless finite joint values of shape (..., 3)."""
    if seed is None:
        return None
    seed = np.asarray(seed, dtype=float)
    if seed.ndim == 0 or seed.shape[-1] != 3 or not np.isfinite(seed).all():
        raise ValueError(f"seed must be finite joint values of shape (..., 3), got {seed!r}")
    return seed


def _not_fixed_phi(heading: float) -> RequestError:
    """The refusal of a target whose heading (rad) is not mode ``fixed_phi``'s 90 deg."""
    return RequestError(
        f"mode 'fixed_phi' holds phi = 90 deg but the target heading is {math.degrees(heading):.6g} deg: "
        "use mode 'phi' or clear use_orientation",
        IKStatus.INVALID,
    )


def _wrap(angle: float) -> float:
    """wrap_angle of one float: the same floor modulo as numpy's, so the same bits."""
    return (angle + math.pi) % math.tau - math.pi


def _off_plane_text(z: float) -> str:
    return f"target z = {z:.6g} m: the arm moves in the plane z = 0 of its base frame"


def _tilted_text(tilt: float) -> str:
    return (
        f"target orientation tilts the tool z axis by {math.degrees(tilt):.6g} deg: the arm only turns "
        "about base z"
    )


def _allowed(requested: int | None) -> np.ndarray:
    return np.array([True, True]) if requested is None else np.arange(2) == requested


def _columns(values: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    values = np.asarray(values, dtype=float)
    if values.ndim == 0 or values.shape[-1] != 3:
        raise ValueError(f"expected shape (..., 3), got {values.shape}")
    return values[..., 0], values[..., 1], values[..., 2]


def _show(joint: int, value: float) -> str:
    return f"{value:.6g} m" if joint == 0 else f"{math.degrees(value):.6g} deg"
