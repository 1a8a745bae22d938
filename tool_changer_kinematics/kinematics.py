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

Speed (benchmarks/bench_tool_changer_ik.py): the steps run on scalar parts, Python floats for one
target and (M,) arrays for chunks of a batch (the shared :func:`evaluate_angle_parts`, one code path),
with every angle kept as a (sine, cosine)-like pair (sums and differences of angles are products
of pairs) until one arctan2 over all 48; then the joint values, statuses and the selection on
parts again. numpy on (8, 6) arrays would cost more in per-call overhead than the arithmetic.

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

Selection rule (the shared one, :func:`manipulator_kinematics.model.select_parts`): only candidates inside
every joint limit (J4's [20, 65] deg stop included) and away from singularities count; of those
the requested branch, else the one closest to the seed (sum of squared joint differences), else
the first in branch order. Ties and "no valid solution" are reported. The paper's claim that J4's
stop alone makes the solution unique does not hold for this model (docs/tool_changer.md).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.config import Names, Number, Numbers, Text, require, validate
from manipulator_kinematics.model import (
    IKSolutions,
    IKStatus,
    RequestError,
    describe_limits,
    matrix_quaternion,
    select_parts,
)
from manipulator_kinematics.params import config_path, load_parameters
from manipulator_kinematics.serial_chain import (
    JointLimits,
    SerialChain,
    evaluate_angle_parts,
    parts_all,
    parts_any,
    parts_clip,
    parts_pose_checks,
    parts_rows,
    parts_sqrt,
    parts_where,
    revolute,
    transl,
    trotx,
    troty,
    trotz,
)

CONFIG_FILE = "tool_changer.yaml"
SECTION = "tool_changer"
BRANCHES = tuple(f"{shoulder}_{elbow}_{wrist}" for shoulder in ("front", "back") for elbow in ("up", "down")
                 for wrist in ("noflip", "flip"))
MODES = ("closed_form",)
#: The D-H twists the closed form needs (rad).
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
#: Values this close (rad) outside a limit count as on it.
LIMIT_TOL = 1e-10
#: |sin theta5| below which phi cannot be taken from the tool axis (round-off), so the rule applies.
WRIST_RULE = 1e-8
#: Wrist centre distance (m) from the J1 axis below which theta1 is taken from the seed.
AXIS_RULE = 1e-9
#: Targets per chunk of a batch in solve_ik.
IK_CHUNK = 2048
#: Distance (m) by which the J3 origin may lie outside the J2-J3 annulus and count as on it (round-off).
TWO_LINK_TOL = 1e-12
#: Largest |R^T R - I| entry of a target rotation that is still a rotation.
ROTATION_TOL = 1e-6

_SUCCESS, _SINGULAR, _JOINT_LIMITS, _UNREACHABLE, _INVALID = (int(s) for s in IKStatus)
_SIX = Numbers(6)

#: The ``tool_changer:`` section of a parameters file (manipulator_kinematics.config).
SCHEMA = {
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


class ToolChanger:
    """The 6R arm: a standard D-H chain of the required structure, joint limits and thresholds."""

    ik_branches = BRANCHES
    ik_modes = MODES

    def __init__(self, a: ArrayLike, d: ArrayLike, limits: JointLimits, *, offset: ArrayLike | None = None,
                 tool: ArrayLike | None = None, wrist_singularity: float = 0.01,
                 axis_singularity: float = 0.005, name: str = "tool_changer") -> None:
        self.name = name
        a = np.asarray(a, dtype=float)
        d = np.asarray(d, dtype=float)
        offset = np.zeros(6) if offset is None else np.asarray(offset, dtype=float)
        if a.shape != (6,) or d.shape != (6,) or offset.shape != (6,) or len(limits.names) != 6:
            raise ValueError("the tool changer has six joints: a, d, offset and limits need six entries")
        if not (a[1] > 0.0 and a[2] > 0.0) or np.any(a[4:] != 0.0) or np.any(d[1:4] != 0.0):
            raise ValueError("closed-form IK needs a2, a3 > 0, a5 = a6 = 0, d2 = d3 = d4 = 0; "
                             f"got a = {a}, d = {d}")
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
        # q = theta - offset as that representative: one more turn up at or below the bottom
        # (_judge). Plain floats for the scalar parts.
        self._wrap_offset_parts = (offset - 2 * math.pi * turns).tolist()
        self._wrap_bottom_parts = (top - 2 * math.pi).tolist()
        self._bounds = limits.bounds(LIMIT_TOL)

    # ---- construction -------------------------------------------------------------------------
    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], prefix: str = SECTION) -> ToolChanger:
        """From the nested ``tool_changer:`` section; ConfigError names a bad key."""
        p = validate(params, SCHEMA, prefix)
        dh = p["dh"]
        for i, (given, needed) in enumerate(zip(dh["alpha"], ALPHA, strict=True)):
            require(abs(given - needed) < 1e-9, f"{prefix}.dh.alpha[{i}]",
                    f"{given} rad: the closed-form IK needs alpha = (+90, 0, 0, +90, -90, 0) deg")
        for key, indices in (("a", (4, 5)), ("d", (1, 2, 3))):
            for i in indices:
                require(dh[key][i] == 0.0, f"{prefix}.dh.{key}[{i}]",
                        f"{dh[key][i]} m: the closed-form IK needs a5 = a6 = 0 and d2 = d3 = d4 = 0")
        for i in (1, 2):
            require(dh["a"][i] > 0.0, f"{prefix}.dh.a[{i}]",
                    f"{dh['a'][i]} m: boom and arm lengths must be > 0")
        names, lower, upper = p["joint_names"], p["joint_min"], p["joint_max"]
        for i in range(6):
            require(lower[i] < upper[i], f"{prefix}.joint_min[{i}]",
                    f"{lower[i]} must be below {prefix}.joint_max[{i}] = {upper[i]} ({names[i]})")
        roll, pitch, yaw = p["tool_rpy"]
        tool = transl(*p["tool_xyz"]) @ trotz(yaw) @ troty(pitch) @ trotx(roll)
        limits = JointLimits(tuple(names), np.array(lower), np.array(upper))
        return cls(dh["a"], dh["d"], limits, offset=dh["offset"], tool=tool,
                   wrist_singularity=p["wrist_singularity"], axis_singularity=p["axis_singularity"],
                   name=p["name"])

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
    def solve_ik(self, target: ArrayLike, *, use_orientation: bool = True, mode: str | None = None,
                 seed: ArrayLike | None = None, branch: str | None = None) -> IKSolutions:
        """Every closed-form solution of target poses (..., 4, 4), each with a status (module docstring).

        ``use_orientation=False``: the arm has six joints for three position constraints, so the
        rule is to keep the seed's tool orientation (without a seed, the target's rotation part is
        used as given). ``seed`` (6,) or (..., 6) joint values; ``branch`` one of :data:`BRANCHES`.
        """
        if mode is not None and mode not in MODES:
            raise RequestError(f"unknown mode {mode!r}; known: {', '.join(MODES)}")
        if branch is not None and branch not in BRANCHES:
            raise RequestError(f"unknown branch {branch!r}; known: {', '.join(BRANCHES)} "
                               "(empty = closest to the seed)")
        target = np.array(target, dtype=float)
        if target.shape[-2:] != (4, 4):
            raise ValueError(f"targets must have shape (..., 4, 4), got {target.shape}")
        shape = target.shape[:-2]
        seed_q = None if seed is None else np.asarray(seed, dtype=float)
        if seed_q is not None and seed_q.shape != shape + (6,):
            seed_q = np.broadcast_to(seed_q, shape + (6,))
        if not use_orientation and seed_q is not None:
            target[..., :3, :3] = self.fkine(seed_q)[..., :3, :3]
        index = None if branch is None else BRANCHES.index(branch)
        if not shape:
            q, status, selected, tie, diag = self._solve(target, seed_q, index)
        else:
            # In chunks of targets, so that every (chunk, 8, 6) array of the pipeline stays in the
            # cache (the work is a few dozen memory-bound passes over the candidates).
            target = target.reshape(-1, 4, 4)
            flat_seed = None if seed_q is None else seed_q.reshape(-1, 6)
            pieces = [self._solve(target[start:start + IK_CHUNK], None if flat_seed is None
                                  else flat_seed[start:start + IK_CHUNK], index)
                      for start in range(0, len(target), IK_CHUNK) or [0]]
            q, status, selected, tie = (np.concatenate(arrays).reshape(shape + arrays[0].shape[1:])
                                        for arrays in zip(*(piece[:4] for piece in pieces), strict=True))
            diag = {key: np.concatenate([piece[4][key] for piece in pieces]).reshape(shape + value.shape[1:])
                    for key, value in pieces[0][4].items()}

        def explain(solutions: IKSolutions, at: tuple[int, ...]) -> str:
            return self._explain(solutions, at, diag, seeded=seed is not None, requested=branch)

        return IKSolutions(q=q, status=status, branches=BRANCHES, selected=selected, tie=tie, explain=explain)

    def _solve(self, target: np.ndarray, seed: np.ndarray | None, branch: int | None) -> tuple:
        """Candidates, statuses, selection and diagnostics of one target (4, 4) or a chunk (M, 4, 4)."""
        shape = target.shape[:-2]
        flange = target if self._tool_inv is None else target @ self._tool_inv
        rule = self.offset[::5] if seed is None else seed[..., ::5] + self.offset[::5]  # theta1, theta6
        pose = parts_rows(flange.reshape(shape + (16,)))
        if shape:
            rule = parts_rows(np.broadcast_to(rule, shape + (2,)))
        extra, q, status, choice = evaluate_angle_parts(
            self._closed_form, [pose, np.cos(rule), np.sin(rule)], ((8, 6), (8, 6), (18,)),
            functools.partial(self._judge, branch=branch), [] if seed is None else [parts_rows(seed)],
            ((8, 6), (8,), (2,)),
        )
        invalid, rho, s5 = extra[..., 0] == 0.0, extra[..., 1], extra[..., 2:10]
        if parts_any(invalid):
            q[invalid] = np.nan
        diag = {"invalid": invalid, "rho": rho, "s5": s5, "reach": extra[..., 10:]}
        return q, status.astype(np.int8), choice[..., 0].astype(np.intp), choice[..., 1] != 0.0, diag

    def _judge(self, angles: Sequence, extra: Sequence, seed: Sequence | None = None, *,
               branch: int | None) -> tuple[list, list, list]:
        """Each candidate's joint values (into the limits: __init__), status and the selection rule on
        scalar parts, like :meth:`_closed_form` (numpy on (8, 6) arrays would cost more than the
        arithmetic for one target). ``angles`` the 48 arctan2 results, ``extra`` from
        :meth:`_closed_form`, ``seed`` 6 joint values or None, ``branch`` the requested candidate.
        Returns q (48), status (8) and [selected, tie].
        """
        invalid, near_axis = extra[0] == 0.0, extra[1] < self.axis_singularity
        offset, bottom, bounds = self._wrap_offset_parts, self._wrap_bottom_parts, self._bounds
        q, status = [], []
        tau = 2 * math.pi
        for i in range(8):
            inside = True
            for j in range(6):
                value = angles[6 * i + j] - offset[j]
                value = value + tau * (value <= bottom[j])
                inside = inside & (value >= bounds[2 * j]) & (value <= bounds[2 * j + 1])
                q.append(value)
            exists = value == value  # not NaN: a branch without a solution is NaN in every joint
            singular = (extra[2 + i] < self.wrist_singularity) | near_axis
            # Arithmetic on booleans: SUCCESS, SINGULAR or JOINT_LIMITS, then UNREACHABLE, INVALID.
            kind = _JOINT_LIMITS - inside * (_JOINT_LIMITS - singular)
            kind = _UNREACHABLE + exists * (kind - _UNREACHABLE)
            status.append(kind + invalid * (_INVALID - kind))
        allowed = None if branch is None else [i == branch for i in range(8)]
        return q, status, list(select_parts(q, status, seed=seed, allowed=allowed))

    def _closed_form(self, pose: Sequence, rule_cos: Sequence, rule_sin: Sequence) -> tuple[list, list, list]:
        """The module docstring's steps 1-4 on scalar parts (floats for one target, (M,) arrays for
        a chunk: :func:`evaluate_parts`), every angle as a pair (y, x) for one arctan2 afterwards, so
        that no inverse trigonometry (whose math and numpy versions differ in the last bit) runs here.

        ``pose`` the 16 entries of the flange pose, row-major; ``rule_cos``, ``rule_sin`` cos/sin of
        the seed's theta1 and theta6 (the degenerate rules). Returns y (48) and x (48), candidate by
        candidate in :data:`BRANCHES` order, NaN in every joint of a branch without a solution, and
        [valid, rho, |sin theta5| of the 8 candidates (NaN if none), J3 origin distance from J2 of
        the 8]. Never raises: a target that is not a rigid transform gives junk and valid = 0.
        """
        nx, _, ax, px, ny, _, ay, py, nz, _, az, pz = pose[:12]
        a1, a2, a3, a4, d1, d5, d6 = self._lengths
        finite, rigid = parts_pose_checks(pose, ROTATION_TOL)
        valid = finite & rigid
        # 1. Wrist centre and theta1 (front shoulder); on the J1 axis the seed's theta1.
        wx, wy, wz = px - d6 * ax, py - d6 * ay, pz - d6 * az
        rho = parts_sqrt(wx * wx + wy * wy)
        on_axis = rho < AXIS_RULE
        safe = rho + (rho == 0.0)  # divisors: 0 becomes 1 (floats would raise; the rules take over there)
        c1, s1 = wx / safe, wy / safe
        if parts_any(on_axis):
            c1, s1 = parts_where(on_axis, rule_cos[0], c1), parts_where(on_axis, rule_sin[0], s1)
        # a, n and the wrist centre in frame 1 of the front shoulder (x1 = (c1, s1, 0), y1 = base z,
        # z1 = (s1, -c1, 0)); the back shoulder (theta1 + pi) flips x1 and z1.
        ax1, az1 = ax * c1 + ay * s1, ax * s1 - ay * c1
        nx1, nz1 = nx * c1 + ny * s1, nx * s1 - ny * c1
        w1, wy1 = wx * c1 + wy * s1, wz - d1
        # 2. |sin theta5| and the direction of x4 in the arm plane: phi = theta2 + theta3 + theta4.
        s5 = parts_sqrt(ax1 * ax1 + az * az)
        degenerate = s5 < WRIST_RULE
        safe5 = s5 + (s5 == 0.0)
        rule = parts_any(degenerate)
        if rule:  # wrist singularity: phi from psi = atan2(n.y1, n.x1) and the seed's theta6
            norm = parts_sqrt(nx1 * nx1 + nz * nz)
            norm = norm + (norm == 0.0)
            cpsi, spsi = nx1 / norm, nz / norm
            c6, s6 = rule_cos[1], rule_sin[1]
        y, x, sin5, reach = [], [], [], []
        for shoulder in (1.0, -1.0):
            ax1k, az1k, nx1k, nz1k = shoulder * ax1, shoulder * az1, shoulder * nx1, shoulder * nz1
            wx1 = shoulder * w1 - a1
            if rule:  # cos theta5 = +1 fixes phi + theta6 = psi, -1 fixes phi - theta6 = psi + pi
                up = az1k >= 0.0
                cpsi_k = shoulder * cpsi
                cphi_rule = parts_where(up, cpsi_k * c6 + spsi * s6, spsi * s6 - cpsi_k * c6)
                sphi_rule = parts_where(up, spsi * c6 - cpsi_k * s6, -spsi * c6 - cpsi_k * s6)
            branches = {}
            for wrist in (1.0, -1.0):  # noflip, flip
                sin5_k = wrist * s5
                cphi, sphi = -wrist * ax1k / safe5, -wrist * az / safe5
                if rule:  # the flip branch is the noflip configuration there: left empty
                    cphi = parts_where(degenerate, cphi_rule, cphi)
                    sphi = parts_where(degenerate, sphi_rule, sphi)
                    if wrist < 0.0:
                        sin5_k = parts_where(degenerate, math.nan, sin5_k)
                # 3. theta6 from n in frame 5.
                y6 = cphi * nz - sphi * nx1k
                x6 = az1k * (cphi * nx1k + sphi * nz) + sin5_k * nz1k
                # 4. The J3 origin relative to J2: the tip of the planar 2R arm (a2, a3), elbow angle
                # theta3 by the law of cosines, theta2 = atan2(o3) - atan2(a3 s3, a2 + a3 c3).
                o3x = wx1 - a4 * cphi - d5 * sphi
                o3y = wy1 - a4 * sphi + d5 * cphi
                r = parts_sqrt(o3x * o3x + o3y * o3y)
                c3 = parts_clip((r * r - a2 * a2 - a3 * a3) / (2.0 * a2 * a3))
                s3_abs = parts_sqrt(1.0 - c3 * c3)
                reachable = (r >= self._reach[0]) & (r <= self._reach[1])
                alive = 1.0 + 0.0 * sin5_k  # NaN where this branch has no solution: every joint NaN
                if not parts_all(reachable):
                    alive = parts_where(reachable, alive, math.nan)
                k1 = a2 + a3 * c3
                for elbow in (-1.0, 1.0):  # up (theta3 <= 0), down
                    s3 = elbow * s3_abs
                    k2 = a3 * s3
                    y2, x2 = o3y * k1 - o3x * k2, o3x * k1 + o3y * k2
                    y23, x23 = y2 * c3 + x2 * s3, x2 * c3 - y2 * s3
                    branches[elbow, wrist] = (
                        [alive * shoulder * s1, alive * y2, alive * s3, alive * (sphi * x23 - cphi * y23),
                         alive * sin5_k, alive * y6],  # theta4 = phi - theta2 - theta3
                        [shoulder * c1, x2, c3, cphi * x23 + sphi * y23, az1k, x6], alive * s5, r)
            for elbow in (-1.0, 1.0):  # BRANCHES order: shoulder, elbow, wrist
                for wrist in (1.0, -1.0):
                    yk, xk, s5k, rk = branches[elbow, wrist]
                    y += yk
                    x += xk
                    sin5.append(s5k)
                    reach.append(rk)
        return y, x, [valid, rho, *sin5, *reach]

    def _explain(self, solutions: IKSolutions, at: tuple[int, ...], diag: dict[str, np.ndarray], *,
                 seeded: bool, requested: str | None) -> str:
        if diag["invalid"][at]:
            return "target is not a finite rigid transform (4x4 with a rotation part)"
        rho = float(diag["rho"][at])
        status, q = solutions.status[at], solutions.q[at]
        valid = [BRANCHES[i] for i in solutions.ordered(at)]
        chosen = int(solutions.selected[at])
        if chosen >= 0:
            how = ("the requested branch" if requested else
                   "closest to the seed" if seeded else "first in branch order (no seed)")
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
                reason = (f"J2-J3 cannot reach the J3 origin ({reach:.4g} m from J2, "
                          f"needs [{shortest:.4g}, {longest:.4g}])")
            elif kind == _UNREACHABLE:
                reason = "same configuration as the noflip branch (wrist singularity)"
            elif kind == _JOINT_LIMITS:
                reason = describe_limits(q[i], self._limits)
            elif kind == _SINGULAR:
                s5 = float(diag["s5"][at + (i,)])
                reason = (f"wrist singularity, |sin q5| = {s5:.3g}" if s5 < self.wrist_singularity
                          else f"wrist centre {rho:.3g} m from the J1 axis")
            else:
                reason = "not the requested branch"
            parts.append(f"{BRANCHES[i]}: {reason}")
        return "no valid solution: " + "; ".join(parts)
