"""TBM tool-changing 6R arm of Sun, Xu and Ren (paper 003): FK, Jacobian and closed-form IK.

Numpy only (no rclpy). SI units, REP 103 base frame (x forward, y left, z up, origin on the J1
axis at the slewing bearing). Joints J1..J6: base slew, boom pitch, arm pitch, wrist pitch, wrist
swing, wrist roll. Standard D-H (paper eq. 1, A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)) with
the reconstructed Table 1 (``config/tool_changer.yaml``): alpha = (+90, 0, 0, +90, -90, 0) deg,
d = (k1, 0, 0, 0, k5, k7), a = (k2, k3, k4, k6, 0, 0). FK is eq. (2), T = A1 ... A6 (times a
tool transform), computed by the shared :class:`SerialChain`.

Closed-form IK (eqs. 3-7 re-derived: the extracted theta2/theta4 formulas are garbled). With
theta_i = q_i + offset_i, R = [n o a] and p the flange pose (base and tool transforms removed):

1. Wrist centre w = p - d6 a (origin of D-H frame 5). Because alpha4 = +90 deg and alpha5 =
   -90 deg, frame 4's x and z axes and d5 lie in the arm plane through the J1 axis, so w has no
   lateral offset (the paper's element (3,4) of T1^-1 T T6^-1): theta1 = atan2(wy, wx) (branch
   ``front``) or that + pi (``back``; the paper's special case "k7 ay - py = 0" picks it).
2. In frame 1 (x1 horizontal outward, y1 up, z1 along the J2/J3/J4 axes), the tool axis is
   z5 = -sin(theta5) x4 + cos(theta5) z1 (element (3,3)): cos theta5 = a.z1 and sin theta5 =
   +-|a x z1| (wrist ``noflip`` / ``flip``); the in-plane direction of x4 then gives
   phi = theta2 + theta3 + theta4 = atan2(-a.y1, -a.x1) / sign(sin theta5).
3. theta6 (element (3,2)) from n in frame 5: cos theta6 = n.x5, sin theta6 = n.y5 with
   x5 = cos theta5 x4 + sin theta5 z1, y5 = -z4.
4. The J3 origin o3 = w - a4 x4 - d5 z4 (z4 = x4 x z1), relative to the J2 origin o1, is the tip
   of the planar 2R arm of Fig. 3 (a2, a3): law of cosines, elbow ``up`` (theta3 <= 0) or
   ``down``, theta2 = atan2(o3) - atan2(a3 sin theta3, a2 + a3 cos theta3); theta4 = phi -
   theta2 - theta3 (eq. 7).

That gives 2 x 2 x 2 = 8 candidates, in the order of :data:`BRANCHES` (index = 4 shoulder +
2 elbow + wrist). Each angle is returned as the representative modulo 2 pi inside its joint's
limits when there is one (J5's limits [0, 270] deg span more than a half turn).

The steps are plain numpy on candidate arrays (``ToolChanger._closed_form``: the 8 candidates
side by side, each angle as a (sine, cosine) pair until one arctan2 per joint into the (N, 8, 6)
result; ``_solve``: the joint values, statuses and selection), one target being a batch of one; a
batch runs in blocks of rows (the shared :func:`manipulator_kinematics.row_blocks.in_blocks`).
One target (4, 4) runs the same steps as scalar loops compiled by numba
(:mod:`tool_changer_kinematics.ik_kernel`, loaded by the shared
:class:`manipulator_kinematics.compiled.Kernel`; the numpy path answers until it is ready and
stays the reference a test compares it with): numpy's fixed cost per call, about a microsecond
per operation, would otherwise be most of a single call.

Degenerate targets, handled by a stated rule and never NaN for a solution that exists:

* wrist singularity sin theta5 = 0 (the tool axis along the J2 axis): only phi + theta6 (cos
  theta5 = +1) or phi - theta6 (-1) is fixed. Rule: keep the seed's theta6 (no seed: q6 = 0) and
  put the rest on phi; the flip branch is then the same configuration and is left empty. Applied
  when |sin theta5| < 1e-8 (below that the direction of x4 is lost to round-off);
* wrist centre on the J1 axis: theta1 is free. Rule: keep the seed's q1 (no seed: 0); ``back``
  is that + pi.

Candidates with |sin theta5| < ``wrist_singularity`` or the wrist centre within
``axis_singularity`` of the J1 axis get status SINGULAR (exact, but joint rates blow up there):
the selection rule skips them, the explanation names them.

Selection rule (the shared one, :func:`manipulator_kinematics.model.select`): only candidates inside
every joint limit (J4's [20, 65] deg stop included) and away from singularities count; of those
the requested branch, else the one closest to the seed (sum of squared joint differences), else
the first in branch order. Ties and "no valid solution" are reported. The paper's claim that J4's
stop alone makes the solution unique does not hold for this model (docs/tool_changer.md).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
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
    matrix_quaternion,
    select,
)
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.row_blocks import in_blocks
from manipulator_kinematics.schema import Names, Number, Numbers, Schema, Text, require, validate
from manipulator_kinematics.serial_chain import (
    JointLimits,
    SerialChain,
    revolute,
    transl,
    trotx,
    troty,
    trotz,
)

CONFIG_FILE = "tool_changer.yaml"
SECTION = "tool_changer"
BRANCHES = tuple(
    f"{shoulder}_{elbow}_{wrist}"
    for shoulder in ("front", "back")
    for elbow in ("up", "down")
    for wrist in ("noflip", "flip")
)
MODES = ("closed_form",)
#: The D-H twists the closed form needs (rad).
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
#: Values this close (rad) outside a limit count as on it.
LIMIT_TOL = 1e-10
#: |sin theta5| below which phi cannot be taken from the tool axis (round-off), so the rule applies.
WRIST_RULE = 1e-8
#: Wrist centre distance (m) from the J1 axis below which theta1 is taken from the seed.
AXIS_RULE = 1e-9
#: Distance (m) by which the J3 origin may lie outside the J2-J3 annulus and count as on it (round-off).
TWO_LINK_TOL = 1e-12
#: Largest |R^T R - I| entry of a target rotation that is still a rotation.
ROTATION_TOL = 1e-6
#: Largest sum of |deviations| of a target's bottom row from [0, 0, 0, 1].
BOTTOM_TOL = 1e-12
#: Each candidate's sign (index = 4 shoulder + 2 elbow + wrist, :data:`BRANCHES`) of the front /
#: back shoulder (x1, z1 flipped), the elbow up (theta3 <= 0) / down and the wrist noflip / flip.
SHOULDER = np.repeat([1.0, -1.0], 4)
ELBOW = np.tile(np.repeat([-1.0, 1.0], 2), 2)
WRIST = np.tile([1.0, -1.0], 4)
#: The elbow-up candidates (front/back shoulder x noflip/flip wrist), and each candidate's one among
#: them: what does not depend on the elbow is computed once for these four.
ELBOW_UP = np.flatnonzero(ELBOW < 0.0)
ELBOW_UP_ROW = np.array([0, 1, 0, 1, 2, 3, 2, 3])

_SUCCESS, _SINGULAR, _JOINT_LIMITS, _UNREACHABLE, _INVALID = (int(s) for s in IKStatus)
#: The seeds of a batch without one (ik_kernel.solve_batch reads its row, never uses it).
_NO_SEEDS = np.zeros((1, 6))
_ONE = ((1, 8, 6), (1, 8))  # _solve_many's candidates' shapes for one target
_SIX = Numbers(6)

#: The ``tool_changer:`` section of a parameters file (manipulator_kinematics.schema).
SCHEMA: Schema = {
    "name": Text(empty=False, default="tool_changer", doc="the machine's name: the robot name of its URDF"),
    "joint_names": Names(6),
    "dh": {
        "a": Numbers(6, Number(min=-100.0, max=100.0, unit="m")),
        "alpha": Numbers(6, Number(min=-math.pi, max=math.pi, unit="rad")),
        "d": Numbers(6, Number(min=-100.0, max=100.0, unit="m")),
        "offset": Numbers(6, Number(min=-2 * math.pi, max=2 * math.pi, unit="rad")),
    },
    "joint_min": Numbers(6, Number(min=-4 * math.pi, max=4 * math.pi, unit="rad")),
    "joint_max": Numbers(6, Number(min=-4 * math.pi, max=4 * math.pi, unit="rad")),
    "tool_xyz": Numbers(3, Number(min=-100.0, max=100.0, unit="m")),
    "tool_rpy": Numbers(3, Number(min=-2 * math.pi, max=2 * math.pi, unit="rad")),
    "wrist_singularity": Number(min=0.0, max=1.0, exclusive_min=False),
    "axis_singularity": Number(min=0.0, max=100.0, unit="m"),
}


def rigid_transform(T: np.ndarray) -> np.ndarray:
    """(...,) True where T (..., 4, 4) is finite, its rotation part orthonormal (R^T R = I to
    :data:`ROTATION_TOL` entry by entry) and proper (det > 0) and its bottom row [0, 0, 0, 1] (to
    :data:`BOTTOM_TOL`, the sum of the deviations)."""
    R = T[..., :3, :3]
    gram = np.einsum("...ki,...kj->...ij", R, R)
    det = np.einsum("...i,...i->...", R[..., 0], np.cross(R[..., 1], R[..., 2]))
    bottom = np.abs(T[..., 3, :] - (0.0, 0.0, 0.0, 1.0)).sum(axis=-1)
    return (
        np.isfinite(T).all(axis=(-2, -1))
        & (np.abs(gram - np.eye(3)) < ROTATION_TOL).all(axis=(-2, -1))
        & (det > 0.0)
        & (bottom < BOTTOM_TOL)
    )


def _warm(ik_kernel: ModuleType, packed: np.ndarray) -> None:
    """Run the kernel once (numba loads or compiles it)."""
    q, status, s5, reach = np.empty((8, 6)), np.empty(8, dtype=np.int8), np.empty(8), np.empty(8)
    ik_kernel.solve(packed, np.eye(4), packed[:6], False, -1, q, status, s5, reach)
    flags = np.empty(1, dtype=bool)
    ik_kernel.solve_batch(
        packed,
        np.eye(4)[None],
        packed[None, :6].copy(),
        False,
        -1,
        q[None],
        status[None],
        s5[None],
        reach[None],
        np.empty(1, dtype=np.intp),
        flags,
        flags.copy(),
        np.empty(1),
    )


#: The single-target kernel (:mod:`tool_changer_kinematics.ik_kernel`), see manipulator_kinematics.compiled.
KERNEL = Kernel("tool_changer_kinematics.ik_kernel", _warm)


class ToolChanger:
    """The 6R arm: a standard D-H chain of the required structure, joint limits and thresholds."""

    ik_branches = BRANCHES
    ik_modes = MODES

    def __init__(
        self,
        a: ArrayLike,
        d: ArrayLike,
        limits: JointLimits,
        *,
        offset: ArrayLike | None = None,
        tool: ArrayLike | None = None,
        wrist_singularity: float = 0.01,
        axis_singularity: float = 0.005,
        name: str = "tool_changer",
    ) -> None:
        self.name = name
        a = np.asarray(a, dtype=float)
        d = np.asarray(d, dtype=float)
        offset = np.zeros(6) if offset is None else np.asarray(offset, dtype=float)
        if a.shape != (6,) or d.shape != (6,) or offset.shape != (6,) or len(limits.names) != 6:
            raise ValueError("the tool changer has six joints: a, d, offset and limits need six entries")
        if not (a[1] > 0.0 and a[2] > 0.0) or np.any(a[4:] != 0.0) or np.any(d[1:4] != 0.0):
            raise ValueError(
                f"closed-form IK needs a2, a3 > 0, a5 = a6 = 0, d2 = d3 = d4 = 0; got a = {a}, d = {d}"
            )
        self.a, self.d, self.offset = a, d, offset
        self._limits = limits
        self.wrist_singularity = float(wrist_singularity)
        self.axis_singularity = float(axis_singularity)
        rows = [revolute(a=a[i], alpha=ALPHA[i], d=d[i], offset=offset[i]) for i in range(6)]
        self.chain = SerialChain(rows, tool=tool)
        identity = np.array_equal(self.chain.tool, np.eye(4))
        self._tool_inv = None if identity else np.linalg.inv(self.chain.tool)
        self._lengths = tuple(float(x) for x in (*a[:4], d[0], d[4], d[5]))  # a1..a4, d1, d5, d6
        self._reach = (abs(a[1] - a[2]) - TWO_LINK_TOL, a[1] + a[2] + TWO_LINK_TOL)
        # The representative of an angle inside [lower, upper], else the nearest to them, lies in
        # (top - 2 pi, top]: top = (lower + upper) / 2 + pi (the angle farthest from the limits) or,
        # for limits a full turn wide or more, lower + 2 pi. theta - offset spans [-pi - offset,
        # pi - offset]; whole turns added to offset put its top into that window (within LIMIT_TOL),
        # so one more turn up where an angle is at or below the window's bottom is all that is left.
        top = np.minimum(0.5 * (limits.lower + limits.upper) + math.pi, limits.lower + 2 * math.pi)
        turns = np.floor((top + 2 * LIMIT_TOL - math.pi + offset) / (2 * math.pi))
        # q = theta - offset as that representative: one more turn up at or below the bottom (_solve).
        self._wrap_offset = offset - 2 * math.pi * turns
        self._wrap_bottom = top - 2 * math.pi
        # The constants of the compiled kernel (ik_kernel's order).
        self._packed = np.array(
            [
                *self._lengths,
                *self._reach,
                self.wrist_singularity,
                self.axis_singularity,
                *self._wrap_offset,
                *self._wrap_bottom,
                *(limits.lower - LIMIT_TOL),
                *(limits.upper + LIMIT_TOL),
                offset[0],
                offset[5],
                AXIS_RULE,
                WRIST_RULE,
                ROTATION_TOL,
                BOTTOM_TOL,
                TIE_TOLERANCE,
            ]
        )

    # ---- construction -------------------------------------------------------------------------
    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], prefix: str = SECTION) -> ToolChanger:
        """From the nested ``tool_changer:`` section; ConfigError names a bad key."""
        p = validate(params, SCHEMA, prefix)
        dh = p["dh"]
        for i, (given, needed) in enumerate(zip(dh["alpha"], ALPHA, strict=True)):
            require(
                abs(given - needed) < 1e-9,
                f"{prefix}.dh.alpha[{i}]",
                f"{given} rad: the closed-form IK needs alpha = (+90, 0, 0, +90, -90, 0) deg",
            )
        for key, indices in (("a", (4, 5)), ("d", (1, 2, 3))):
            for i in indices:
                require(
                    dh[key][i] == 0.0,
                    f"{prefix}.dh.{key}[{i}]",
                    f"{dh[key][i]} m: the closed-form IK needs a5 = a6 = 0 and d2 = d3 = d4 = 0",
                )
        for i in (1, 2):
            require(
                dh["a"][i] > 0.0, f"{prefix}.dh.a[{i}]", f"{dh['a'][i]} m: boom and arm lengths must be > 0"
            )
        names, lower, upper = p["joint_names"], p["joint_min"], p["joint_max"]
        for i in range(6):
            require(
                lower[i] < upper[i],
                f"{prefix}.joint_min[{i}]",
                f"{lower[i]} must be below {prefix}.joint_max[{i}] = {upper[i]} ({names[i]})",
            )
        roll, pitch, yaw = p["tool_rpy"]
        tool = transl(*p["tool_xyz"]) @ trotz(yaw) @ troty(pitch) @ trotx(roll)
        limits = JointLimits(tuple(names), np.array(lower), np.array(upper))
        return cls(
            dh["a"],
            dh["d"],
            limits,
            offset=dh["offset"],
            tool=tool,
            wrist_singularity=p["wrist_singularity"],
            axis_singularity=p["axis_singularity"],
            name=p["name"],
        )

    @classmethod
    def default(cls) -> ToolChanger:
        """The reconstructed arm of ``config/tool_changer.yaml``."""
        return cls.from_parameters(load_parameters(config_path(CONFIG_FILE))[SECTION])

    # ---- protocol: forward kinematics ------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._limits.names

    @property
    def limits(self) -> JointLimits:
        return self._limits

    def fkine(self, q: ArrayLike) -> np.ndarray:
        """Tool pose (..., 4, 4) in the base frame (eq. 2)."""
        return self.chain.fkine(q)

    def frames(self, q: ArrayLike) -> np.ndarray:
        """Base, the six D-H frames and the tool frame, (..., 8, 4, 4)."""
        links = self.chain.fkine(q, all_frames=True)
        return np.concatenate([links, (links[..., -1, :, :] @ self.chain.tool)[..., None, :, :]], axis=-3)

    def jacob0(self, q: ArrayLike) -> np.ndarray:
        """Geometric Jacobian (..., 6, 6) of the tool frame in the base frame, linear rows first."""
        return self.chain.jacob0(q)

    def pose(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """PoseStamped-ready tool pose: position (..., 3) m and quaternion (..., 4) (x, y, z, w)."""
        T = self.fkine(q)
        return T[..., :3, 3], matrix_quaternion(T[..., :3, :3])

    def twist(self, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
        """Velocity FK: tool twist (..., 6) = J(q) qd, (vx, vy, vz, wx, wy, wz) in the base frame."""
        return (self.jacob0(q) @ np.asarray(qd, dtype=float)[..., None])[..., 0]

    def wrist_centre(self, q: ArrayLike) -> np.ndarray:
        """Origin of D-H frame 5 (..., 3): where J4's arm ends and the J5/J6 wrist begins."""
        return self.chain.fkine(q, all_frames=True)[..., 5, :3, 3]

    def state_note(self, q: ArrayLike) -> str:
        """A remark on one joint state for FK answers: near a singularity, or nothing."""
        q = np.asarray(q, dtype=float)
        s5 = abs(math.sin(float(q[4]) + self.offset[4]))
        w = self.wrist_centre(q)
        notes = []
        if s5 < self.wrist_singularity:
            notes.append(f"wrist singularity: |sin q5| = {s5:.3g}")
        if math.hypot(w[0], w[1]) < self.axis_singularity:
            notes.append(f"wrist centre {math.hypot(w[0], w[1]):.3g} m from the J1 axis")
        return "; ".join(notes)

    # ---- protocol: inverse kinematics ------------------------------------------------------------
    def solve_ik(
        self,
        target: ArrayLike,
        *,
        use_orientation: bool = True,
        mode: str | None = None,
        seed: ArrayLike | None = None,
        branch: str | None = None,
        compiled: bool = True,
    ) -> IKSolutions:
        """Every closed-form solution of target poses (..., 4, 4), each with a status (module docstring).

        ``use_orientation=False``: the arm has six joints for three position constraints, so the
        rule is to keep the seed's tool orientation (without a seed, the target's rotation part is
        used as given). ``seed`` (6,) or (..., 6) joint values; ``branch`` one of :data:`BRANCHES`.
        One target (4, 4) runs the compiled kernel once it is loaded (:meth:`compiled_kernel`), a
        batch its loop over the targets, unless not ``compiled``; the numpy path otherwise (the
        reference: the same results within 1e-12).
        """
        if mode is not None and mode not in MODES:
            raise RequestError(f"unknown mode {mode!r}; known: {', '.join(MODES)}")
        if branch is not None and branch not in BRANCHES:
            raise RequestError(
                f"unknown branch {branch!r}; known: {', '.join(BRANCHES)} (empty = closest to the seed)"
            )
        target = np.array(target, dtype=float)
        if target.shape[-2:] != (4, 4):
            raise ValueError(f"targets must have shape (..., 4, 4), got {target.shape}")
        shape = target.shape[:-2]
        seed_q = seeds = None if seed is None else np.asarray(seed, dtype=float)
        if seeds is not None and seeds.shape != shape + (6,):
            seed_q = np.broadcast_to(seeds, shape + (6,))
            # One seed for a batch: the kernel's loop reads its one row for every target.
            seeds = seeds.reshape(1, 6) if seeds.shape == (6,) else seed_q
        if not use_orientation and seed_q is not None:
            target[..., :3, :3] = self.fkine(seed_q)[..., :3, :3]
        index = None if branch is None else BRANCHES.index(branch)
        kernel = self.compiled_kernel() if compiled else None
        if kernel is not None and not shape:
            q, status, selected, tie, diag = self._solve_one(kernel, target, seed_q, index)
        elif kernel is not None and len(shape) == 1:  # (N,): the kernel's outputs as they are
            q, status, selected, tie, diag = self._solve_many(kernel, self._flange(target), seeds, index)
        elif kernel is not None:
            flat_seed = seeds if seeds is None or seeds.ndim == 2 else seeds.reshape(-1, 6)
            flange = self._flange(target).reshape(-1, 4, 4)
            q, status, selected, tie, diag = self._solve_many(kernel, flange, flat_seed, index)
            q, status, selected, tie = (
                value.reshape(shape + value.shape[1:]) for value in (q, status, selected, tie)
            )
            diag = {key: value.reshape(shape + value.shape[1:]) for key, value in diag.items()}
        else:
            flange = self._flange(target)
            flat_seed = None if seed_q is None else seed_q.reshape(-1, 6)
            judged = in_blocks(
                functools.partial(self._solve, branch=index), flange.reshape(-1, 4, 4), flat_seed
            )
            q, status, selected, tie, invalid, rho, s5, reach = (
                value.reshape(shape + value.shape[1:]) for value in judged
            )
            diag = {"invalid": invalid, "rho": rho, "s5": s5, "reach": reach}

        def explain(solutions: IKSolutions, at: tuple[int, ...]) -> str:
            return self._explain(solutions, at, diag, seeded=seed is not None, requested=branch)

        return IKSolutions(q=q, status=status, branches=BRANCHES, selected=selected, tie=tie, explain=explain)

    def _flange(self, target: np.ndarray) -> np.ndarray:
        """Flange poses (..., 4, 4) of tool poses, by numpy's product on both paths (near the wrist
        singularity theta4 and theta6 amplify its last bits by 1 / sin theta5)."""
        if self._tool_inv is None:
            return target
        with np.errstate(invalid="ignore", over="ignore"):  # a target that is not a pose: INVALID
            return target @ self._tool_inv

    def _solve(
        self, flange: np.ndarray, seed: np.ndarray | None, branch: int | None
    ) -> tuple[np.ndarray, ...]:
        """Flange poses (N, 4, 4) -> candidates q (N, 8, 6), statuses (N, 8), selected and tie (N,),
        and the diagnostics of the texts: not a pose (N,), rho (N,), |sin theta5| and the J3 origin's
        distance from J2 (N, 8) (:meth:`_closed_form`)."""
        # The degenerate rules' theta1 and theta6: the seed's, else q1 = q6 = 0.
        rule = self.offset[::5] if seed is None else seed[:, ::5] + self.offset[::5]
        # Junk from targets that are not poses is flagged INVALID; it must not warn.
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            invalid = ~rigid_transform(flange)
            theta, rho, s5, reach = self._closed_form(flange, np.broadcast_to(rule, (len(flange), 2)))
            q = theta  # in place: q = theta - offset as its representative inside the limits (__init__)
            q -= self._wrap_offset
            np.add(q, 2 * math.pi, out=q, where=q <= self._wrap_bottom)
            status = limit_status(q, self._limits, LIMIT_TOL)
            singular = (s5 < self.wrist_singularity) | (rho < self.axis_singularity)[:, None]
        status[(status == _SUCCESS) & singular] = _SINGULAR
        status[invalid] = _INVALID
        selected, tie = select(q, status, seed=seed, branch=branch)
        q[invalid] = np.nan
        return q, status, selected, tie, invalid, rho, s5, reach

    def _closed_form(self, flange: np.ndarray, rule: np.ndarray) -> tuple[np.ndarray, ...]:
        """The module docstring's steps 1-4 (eqs. 3-7) on flange poses (N, 4, 4), each angle as a pair
        (y, x) for one arctan2 per joint at the end. ``rule`` (N, 2) the degenerate rules' theta1 and theta6.

        Returns theta (N, 8, 6), NaN in every joint of a candidate without a solution; rho (N,), the
        wrist centre's distance from the J1 axis; |sin theta5| (N, 8), NaN where no solution; the J3
        origin's distance from J2 (N, 8). Inside, the candidates are rows (k, N), the signs
        :data:`SHOULDER`, :data:`ELBOW`, :data:`WRIST` columns, so that every operation runs along
        the N targets (a last axis of 8 costs numpy several times more per element); steps 1-3 and
        the J3 origin run on the four rows :data:`ELBOW_UP`, the elbow's part of step 4 on all 8.
        """
        a1, a2, a3, a4, d1, d5, d6 = self._lengths
        shoulder, wrist = SHOULDER[ELBOW_UP, None], WRIST[ELBOW_UP, None]
        nx, _, ax, px, ny, _, ay, py, nz, _, az, pz = np.ascontiguousarray(flange.reshape(-1, 16)[:, :12].T)
        # 1. Wrist centre and theta1 (front shoulder), element (3,4); on the J1 axis the seed's theta1.
        wx, wy, wz = px - d6 * ax, py - d6 * ay, pz - d6 * az
        rho = np.sqrt(wx * wx + wy * wy)
        on_axis = rho < AXIS_RULE
        safe = np.where(rho == 0.0, 1.0, rho)
        c1 = np.where(on_axis, np.cos(rule[:, 0]), wx / safe)
        s1 = np.where(on_axis, np.sin(rule[:, 0]), wy / safe)
        # a, n and w in frame 1 of the front shoulder: x1 = (c1, s1, 0), y1 = base z, z1 = (s1, -c1, 0);
        # the back shoulder (theta1 + pi) flips x1 and z1.
        ax1, az1 = ax * c1 + ay * s1, ax * s1 - ay * c1
        nx1, nz1 = nx * c1 + ny * s1, nx * s1 - ny * c1
        w1, wy1 = wx * c1 + wy * s1, wz - d1
        ax1_k, az1_k, nx1_k, nz1_k = shoulder * ax1, shoulder * az1, shoulder * nx1, shoulder * nz1
        # 2. theta5, element (3,3): cos theta5 = a.z1, sin theta5 = +-|a x z1|; the direction of x4
        # in the arm plane gives phi = theta2 + theta3 + theta4.
        s5 = np.sqrt(ax1 * ax1 + az * az)
        sin5 = wrist * s5
        safe5 = np.where(s5 == 0.0, 1.0, s5)
        cphi, sphi = -wrist * ax1_k / safe5, -wrist * az / safe5
        exists = np.ones(sin5.shape, dtype=bool)
        degenerate = s5 < WRIST_RULE
        if np.any(degenerate):
            # Wrist singularity: cos theta5 = +1 fixes phi + theta6 = psi, -1 fixes phi - theta6 =
            # psi + pi, psi = atan2(n.y1, n.x1); theta6 is the seed's. The flip branch is the noflip
            # configuration there: left empty.
            norm = np.sqrt(nx1 * nx1 + nz * nz)
            norm = np.where(norm == 0.0, 1.0, norm)
            cpsi, spsi = shoulder * nx1 / norm, nz / norm
            c6, s6 = np.cos(rule[:, 1]), np.sin(rule[:, 1])
            up = az1_k >= 0.0
            cphi = np.where(degenerate, np.where(up, cpsi * c6 + spsi * s6, spsi * s6 - cpsi * c6), cphi)
            sphi = np.where(degenerate, np.where(up, spsi * c6 - cpsi * s6, -spsi * c6 - cpsi * s6), sphi)
            exists = ~(degenerate & (wrist < 0.0))
        # 3. theta6 from n in frame 5, element (3,2).
        y6 = cphi * nz - sphi * nx1_k
        x6 = az1_k * (cphi * nx1_k + sphi * nz) + sin5 * nz1_k
        # 4. The J3 origin relative to J2: the tip of the planar 2R arm (a2, a3), elbow angle theta3
        # by the law of cosines, theta2 = atan2(o3) - atan2(a3 s3, a2 + a3 c3), theta4 = phi -
        # theta2 - theta3 (eq. 7).
        o3x = shoulder * w1 - a1 - a4 * cphi - d5 * sphi
        o3y = wy1 - a4 * sphi + d5 * cphi
        r = np.sqrt(o3x * o3x + o3y * o3y)
        exists &= (r >= self._reach[0]) & (r <= self._reach[1])
        c3 = np.clip((r * r - a2 * a2 - a3 * a3) / (2.0 * a2 * a3), -1.0, 1.0)
        theta = np.empty((len(rho), 8, 6))
        for j, (y, x) in ((0, (shoulder * s1, shoulder * c1)), (4, (sin5, az1_k)), (5, (y6, x6))):
            theta[..., j] = np.arctan2(y, x)[ELBOW_UP_ROW].T  # theta1, theta5, theta6: as the elbow-up twin's
        # The elbow: all 8 candidates, each from its elbow-up twin.
        cphi, sphi, o3x, o3y, c3, exists, r = (v[ELBOW_UP_ROW] for v in (cphi, sphi, o3x, o3y, c3, exists, r))
        s3 = ELBOW[:, None] * np.sqrt(1.0 - c3 * c3)
        k1, k2 = a2 + a3 * c3, a3 * s3
        y2, x2 = o3y * k1 - o3x * k2, o3x * k1 + o3y * k2
        y23, x23 = y2 * c3 + x2 * s3, x2 * c3 - y2 * s3
        theta4 = (sphi * x23 - cphi * y23, cphi * x23 + sphi * y23)  # phi - theta2 - theta3
        for j, (y, x) in ((1, (y2, x2)), (2, (s3, c3)), (3, theta4)):
            np.arctan2(y, x, out=theta[..., j].T)  # straight into the (N, 8, 6) result
        theta[~exists.T] = np.nan
        return theta, rho, np.where(exists, s5, np.nan).T, r.T

    # ---- the compiled single call ------------------------------------------------------------------
    def compiled_kernel(self, wait: bool = False) -> ModuleType | None:
        """The compiled kernel module if ready, else None (:class:`manipulator_kinematics.compiled.Kernel`:
        the first IK call starts loading it, calls take the numpy path meanwhile).
        ``wait``: load it now (tests, benchmarks)."""
        return KERNEL.get(self._packed, wait=wait)

    def _solve_one(
        self, kernel: ModuleType, target: np.ndarray, seed: np.ndarray | None, branch: int | None
    ) -> tuple:
        """One target (4, 4) through :func:`tool_changer_kinematics.ik_kernel.solve`."""
        q, status = np.empty((8, 6)), np.empty(8, dtype=np.int8)
        s5, reach = np.empty(8), np.empty(8)
        seeded = seed is not None
        selected, tie, invalid, rho = kernel.solve(
            self._packed,
            self._flange(target),
            np.ascontiguousarray(seed) if seeded else self._packed[:6],
            seeded,
            -1 if branch is None else branch,
            q,
            status,
            s5,
            reach,
        )
        diag = {"invalid": np.array(invalid), "rho": np.array(rho), "s5": s5, "reach": reach}
        return q, status, np.array(selected, dtype=np.intp), np.array(tie), diag

    def _solve_many(
        self, kernel: ModuleType, flange: np.ndarray, seeds: np.ndarray | None, branch: int | None
    ) -> tuple:
        """Flange poses (N, 4, 4) through the kernel's loop (ik_kernel.solve_batch), seeds (N, 6) or
        (1, 6) for every target."""
        n = len(flange)
        # A batch of one's shapes made once: a tuple made per call costs 0.05 us (issue #32).
        shape, candidates = _ONE if n == 1 else ((n, 8, 6), (n, 8))
        q, status = np.empty(shape), np.empty(candidates, dtype=np.int8)
        s5, reach, rho = np.empty(candidates), np.empty(candidates), np.empty(n)
        selected, tie, invalid = np.empty(n, dtype=np.intp), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        seeded = seeds is not None
        kernel.solve_batch(
            self._packed,
            flange,  # C-contiguous: solve_ik's copy, or _flange's product
            np.ascontiguousarray(seeds) if seeded else _NO_SEEDS,
            seeded,
            -1 if branch is None else branch,
            q,
            status,
            s5,
            reach,
            selected,
            tie,
            invalid,
            rho,
        )
        return q, status, selected, tie, {"invalid": invalid, "rho": rho, "s5": s5, "reach": reach}

    def _explain(
        self,
        solutions: IKSolutions,
        at: tuple[int, ...],
        diag: dict[str, np.ndarray],
        *,
        seeded: bool,
        requested: str | None,
    ) -> str:
        if diag["invalid"][at]:
            return "target is not a finite rigid transform (4x4 with a rotation part)"
        rho = float(diag["rho"][at])
        status, q = solutions.status[at], solutions.q[at]
        valid = [BRANCHES[i] for i in solutions.ordered(at)]
        chosen = int(solutions.selected[at])
        if chosen >= 0:
            how = (
                "the requested branch"
                if requested
                else "closest to the seed"
                if seeded
                else "first in branch order (no seed)"
            )
            text = f"branch {BRANCHES[chosen]} ({how}); valid: {', '.join(valid)}"
            if solutions.tie[at]:
                text += "; tie: another valid solution is as close to the seed"
            return text
        parts = []
        for i in range(8) if requested is None else (BRANCHES.index(requested),):
            kind = int(status[i])
            reach = float(diag["reach"][at + (i,)])
            shortest, longest = abs(self.a[1] - self.a[2]), self.a[1] + self.a[2]
            if kind == _UNREACHABLE and not shortest <= reach <= longest:
                reason = (
                    f"J2-J3 cannot reach the J3 origin ({reach:.4g} m from J2, "
                    f"needs [{shortest:.4g}, {longest:.4g}])"
                )
            elif kind == _UNREACHABLE:
                reason = "same configuration as the noflip branch (wrist singularity)"
            elif kind == _JOINT_LIMITS:
                reason = describe_limits(q[i], self._limits)
            elif kind == _SINGULAR:
                s5 = float(diag["s5"][at + (i,)])
                reason = (
                    f"wrist singularity, |sin q5| = {s5:.3g}"
                    if s5 < self.wrist_singularity
                    else f"wrist centre {rho:.3g} m from the J1 axis"
                )
            else:
                reason = "not the requested branch"
            parts.append(f"{BRANCHES[i]}: {reason}")
        return "no valid solution: " + "; ".join(parts)
