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
   ``down`` (the shared :func:`two_link_ik`); theta4 = phi - theta2 - theta3 (eq. 7).

That gives 2 x 2 x 2 = 8 candidates, in the order of :data:`BRANCHES` (index = 4 shoulder +
2 elbow + wrist). Each angle is returned as the representative modulo 2 pi inside its joint's
limits when there is one (J5's limits [0, 270] deg span more than a half turn).

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

Selection rule (the shared :func:`manipulator_kinematics.model.select`): only candidates inside
every joint limit (J4's [20, 65] deg stop included) and away from singularities count; of those
the requested branch, else the one closest to the seed (sum of squared joint differences), else
the first in branch order. Ties and "no valid solution" are reported. The paper's claim that J4's
stop alone makes the solution unique does not hold for this model (docs/tool_changer.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.config import Names, Number, Numbers, require, validate
from manipulator_kinematics.model import (
    IKSolutions,
    IKStatus,
    RequestError,
    describe_limits,
    limit_status,
    matrix_quaternion,
    select,
)
from manipulator_kinematics.params import config_path, load_parameters
from manipulator_kinematics.planar import two_link_ik
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
#: Largest |R^T R - I| entry of a target rotation that is still a rotation.
ROTATION_TOL = 1e-6

_SUCCESS, _SINGULAR, _JOINT_LIMITS, _UNREACHABLE, _INVALID = (int(s) for s in IKStatus)
_SIX = Numbers(6)

#: The ``tool_changer:`` section of a parameters file (manipulator_kinematics.config).
SCHEMA = {
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
                 axis_singularity: float = 0.005) -> None:
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
        self._tool_inv = np.linalg.inv(self.chain.tool)

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
                   wrist_singularity=p["wrist_singularity"], axis_singularity=p["axis_singularity"])

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
        seed_q = None if seed is None else np.broadcast_to(np.asarray(seed, dtype=float), shape + (6,))
        if not use_orientation and seed_q is not None:
            target[..., :3, :3] = self.fkine(seed_q)[..., :3, :3]
        flat_seed = None if seed_q is None else seed_q.reshape(-1, 6)
        q, diag = self._candidates(target.reshape(-1, 4, 4), flat_seed)
        q = q.reshape(shape + (8, 6))
        status = limit_status(q, self._limits, LIMIT_TOL)
        singular = (diag["s5"] < self.wrist_singularity) | (diag["rho"] < self.axis_singularity)[:, None]
        status = np.where((status == _SUCCESS) & singular.reshape(shape + (8,)), _SINGULAR, status)
        invalid = diag["invalid"].reshape(shape)
        status = np.where(invalid[..., None], _INVALID, status).astype(np.int8)
        q = np.where(invalid[..., None, None], np.nan, q)
        index = None if branch is None else BRANCHES.index(branch)
        selected, tie = select(q, status, seed=seed_q, branch=index)
        diag = {key: value.reshape(shape + value.shape[1:]) for key, value in diag.items()}

        def explain(solutions: IKSolutions, at: tuple[int, ...]) -> str:
            return self._explain(solutions, at, diag, seeded=seed is not None, requested=branch)

        return IKSolutions(q=q, status=status, branches=BRANCHES, selected=selected, tie=tie, explain=explain)

    def _candidates(self, target: np.ndarray,
                    seed: np.ndarray | None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """All 8 candidates (N, 8, 6) of flange-frame targets (N, 4, 4) and per-target diagnostics."""
        n_targets = target.shape[0]
        R = target[:, :3, :3]
        finite = np.all(np.isfinite(target), axis=(-2, -1))
        with np.errstate(invalid="ignore"):
            orthonormal = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-2, -1)) < ROTATION_TOL
            proper = np.linalg.det(np.where(finite[:, None, None], R, np.eye(3))) > 0.0
        invalid = ~(finite & orthonormal & proper)
        T = np.where(invalid[:, None, None], np.eye(4), target) @ self._tool_inv
        nx, ny, nz = T[:, 0, 0], T[:, 1, 0], T[:, 2, 0]
        ax, ay, az = T[:, 0, 2], T[:, 1, 2], T[:, 2, 2]
        a1, a2, a3, a4 = self.a[:4]
        d1, d5, d6 = self.d[0], self.d[4], self.d[5]
        wx, wy, wz = T[:, 0, 3] - d6 * ax, T[:, 1, 3] - d6 * ay, T[:, 2, 3] - d6 * az
        rho = np.hypot(wx, wy)
        seed_q = np.zeros((n_targets, 6)) if seed is None else seed
        th1 = np.where(rho < AXIS_RULE, seed_q[:, 0] + self.offset[0], np.arctan2(wy, wx))
        th1 = np.stack([th1, th1 + math.pi], axis=-1)  # (N, shoulder)
        c1, s1 = np.cos(th1), np.sin(th1)
        col = (slice(None), None)
        # a, n and w in frame 1 (x1 = (c1, s1, 0), y1 = base z, z1 = (s1, -c1, 0)), w relative to o1.
        ax1, az1 = ax[col] * c1 + ay[col] * s1, ax[col] * s1 - ay[col] * c1
        nx1, nz1 = nx[col] * c1 + ny[col] * s1, nx[col] * s1 - ny[col] * c1
        ay1, ny1 = np.broadcast_to(az[col], c1.shape), np.broadcast_to(nz[col], c1.shape)
        wx1, wy1 = wx[col] * c1 + wy[col] * s1 - a1, np.broadcast_to(wz[col] - d1, c1.shape)
        s5_abs = np.hypot(ax1, ay1)
        degenerate = s5_abs < WRIST_RULE
        sign = np.array([1.0, -1.0])  # wrist noflip / flip
        s5 = s5_abs[..., None] * sign  # (N, shoulder, wrist)
        c5 = az1[..., None]
        th5 = np.arctan2(s5, c5)
        phi = np.arctan2(-ay1[..., None] * sign, -ax1[..., None] * sign)
        # Wrist singularity: keep the seed's theta6; cos theta5 = +1 fixes phi + theta6, -1 phi - theta6.
        th6_seed = (seed_q[:, 5] + self.offset[5])[:, None]
        psi = np.arctan2(ny1, nx1)
        phi_rule = np.where(az1 >= 0.0, psi - th6_seed, psi + math.pi + th6_seed)
        phi = np.where(degenerate[..., None], phi_rule[..., None], phi)
        cphi, sphi = np.cos(phi), np.sin(phi)
        th6 = np.arctan2(-(sphi * nx1[..., None] - cphi * ny1[..., None]),
                         c5 * (cphi * nx1[..., None] + sphi * ny1[..., None]) + s5 * nz1[..., None])
        o3x = wx1[..., None] - a4 * cphi - d5 * sphi
        o3y = wy1[..., None] - a4 * sphi + d5 * cphi
        arm = two_link_ik(o3x, o3y, a2, a3)
        th2, th3 = arm.theta1[..., ::-1], arm.theta2[..., ::-1]  # elbow up (theta3 <= 0) first
        th4 = phi[..., None] - th2 - th3
        shape = th2.shape  # (N, shoulder, wrist, elbow)
        theta = np.stack([np.broadcast_to(th1[:, :, None, None], shape), th2, th3, th4,
                          np.broadcast_to(th5[..., None], shape),
                          np.broadcast_to(th6[..., None], shape)], axis=-1)
        theta[:, :, 1][degenerate] = np.nan  # at the singularity the flip branch is the same configuration
        theta = np.swapaxes(theta, 2, 3).reshape(n_targets, 8, 6)  # (shoulder, elbow, wrist) order
        theta[np.isnan(theta).any(axis=-1)] = np.nan  # a branch without a solution is empty, all joints
        q = self._into_limits(theta - self.offset)
        s5_c = np.broadcast_to(s5_abs[:, :, None, None], shape).swapaxes(2, 3).reshape(n_targets, 8)
        reach = np.swapaxes(np.broadcast_to(arm.distance[..., None], shape), 2, 3).reshape(n_targets, 8)
        return q, {"s5": np.where(np.isnan(q[..., 0]), np.inf, s5_c), "rho": rho, "invalid": invalid,
                   "reach": reach}

    def _into_limits(self, q: np.ndarray) -> np.ndarray:
        """Each angle's representative modulo 2 pi inside its limits, else the one nearest to them."""
        lower, upper = self._limits.lower, self._limits.upper
        up = lower + np.mod(q - lower + LIMIT_TOL, 2 * math.pi) - LIMIT_TOL  # in [lower, lower + 2 pi)
        down = up - 2 * math.pi
        return np.where(up - upper <= lower - down, up, down)

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
