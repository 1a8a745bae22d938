"""Hydraulic excavator kinematics as a hybrid chain (paper 000: Zhang, Su, Yin, 1994).

The manipulator is an open main chain (swing theta1, boom theta2, arm theta3, bucket theta4)
driven by independent closed-loop cylinder mechanisms with secondary coordinates
D = [theta1, d2, d3, d4] (swing angle and the boom, arm and bucket cylinder lengths). The
bucket tip is Q = [x, y, z, alpha] (m, rad). Frames and conventions: docs/excavator.md.

Paper equation -> where it is computed:

====  ===========================================  ==============================================
eq.   relation                                     function
====  ===========================================  ==============================================
1     boom/arm triangle: theta(d), d(theta),       ``Triangle.closes`` (via ``joint_angles``,
      k21 = dtheta/dd, k22 = d2theta/dd2           ``k_entries``); inverse: ``cylinder_lengths``
2     bucket six-bar = cylinder four-bar + bucket  ``Excavator._linkages`` (via
      four-bar in series: theta4(d4) and rates     ``joint_angles``); inverse: ``cylinder_lengths``
3     Q(theta), open chain                         ``pose``, ``open_chain_pose`` (``_tip``)
4     Qdot by columns: coefficients a_i, b_i       ``Excavator._chain_terms``
5     Qdot = J0 thetadot                           ``j0``
6     thetadot = J0^-1 Qdot                        ``joint_rates``
7     thetadot = K Ddot                            ``k_matrix``, ``k_entries``; ``state.theta_dot``
8     Qdot = JC0 Ddot, JC0 = J0 K                  ``jc0``; ``state.Q_dot``, ``state.jc0``
9     Ddot = JC0^-1 Qdot                           ``cylinder_rates``
10    Qddot = J0 thetaddot + Jdot0 thetadot        ``state.Q_ddot`` (``Excavator._states``)
11    Qddot = JC0 Dddot + JC1_0 Ddot^2 + JC2_0 DD  ``acceleration_matrices`` (same value as eq. 10)
12    thetaddot = J0^-1 (Qddot - Jdot0 thetadot)   ``joint_accelerations``
13    Dddot = JC0^-1 (Qddot - JC1_0 .. - JC2_0 ..) ``cylinder_accelerations``
====  ===========================================  ==============================================

Everything is closed form, written once as plain vectorised numpy on (..., n) arrays: one state
(shape (4,)) is a batch of one through the same code (the same bits as that row of a batch); a
batch (shape (N, 4)) runs in blocks of rows (:func:`manipulator_kinematics.row_blocks.in_blocks`).
Rates and accelerations have D's shape or (4,), broadcast over a batch. The single call of
:meth:`Excavator.state`, :meth:`Excavator.pose` and :meth:`Excavator.jc0`, and a batch of
``state`` and ``pose``, run the same steps compiled (:mod:`excavator_kinematics.core.state_kernel`,
numba) once that kernel has loaded in the background
(:class:`manipulator_kinematics.compiled.Kernel`; the numpy path answers meanwhile and
stays the reference, within 1e-12). Errors: a wrong shape is a ``ValueError`` saying "shape"; a
state the machine cannot take (outside a stroke or the swing range, not finite, a linkage that
cannot close, a singular JC0) is a :class:`StrokeError` (also a ValueError). The machine file is
read by :mod:`excavator_kinematics.core.machine_file`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from excavator_kinematics.core import inverse
from excavator_kinematics.core.geometry import Linkages, StrokeError, closing_sine, cos_sin
from excavator_kinematics.core.layouts import STATE, check_compiled
from excavator_kinematics.core.machine_file import (
    CYLINDERS,
    DYADS,
    FAMILY,
    STROKE_TOLERANCE,
    TOPOLOGY,
    Description,
    parse,
    wrap_swing,
)
from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.model import IKSolutions
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.row_blocks import BLOCK, in_blocks
from manipulator_kinematics.serial_chain import JointLimits

JOINTS = ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")
# Names of D's components in D's order: the actuators (swing drive and the three cylinders).
ACTUATORS = (JOINTS[0], *CYLINDERS)
DEFAULT_CONFIG = "excavator_cet200.yaml"

# States per block of pose, jc0 and state: the blocks write their entries into the batch's table
# where they stay (in_blocks' rows); numpy's fixed cost per call (60-200 calls per block) falls
# with the block, the cache misses of its some 150 temporaries rise. Measured on 10^5 states, CPU
# ms per batch (state / pose): 4096 states per block 17.2 / 9.6, 8192 15.2 / 8.3, 16384 15.7 /
# 10.0, 32768 18.8 / 9.3, the whole batch in one 39.0 / 8.4.
_BLOCK = 2 * BLOCK
# Once the kernel is loaded, batches of full states and poses of every size run its loop into
# one preallocated table (issue #32): numpy's fixed cost made a batch of one 10x (state) or 90x
# (pose) a single call, and its temporaries, above glibc's mmap threshold, cost a fresh process
# 2-4x per state in batches of 3k-16k states until a larger batch had run once
# (benchmarks/bench_batch.py). The numpy path (blocks of _BLOCK) is the reference and what runs
# until the kernel has loaded.

# Dddot of a state, and of every state of a batch, without accelerations (the kernel reads them,
# never writes them).
_NO_ACCELERATION = np.zeros(4)
_NO_ACCELERATIONS = np.zeros((1, 4))


def _warm(state_kernel: ModuleType) -> None:
    """Run each kernel function once (numba loads or compiles it; the values do not matter, zero
    limits refuse the state), then let it take only those types: arguments of other types (a
    list, a strided or read-only view, integers) raise TypeError, and the caller takes the numpy
    path, instead of compiling for seconds in a call. A kernel compiled for another layout is
    refused (layouts.check_compiled)."""
    check_compiled(state_kernel)
    packed, D, three = np.zeros(STATE.size), np.zeros(4), np.empty(3)
    state_kernel.state(packed, D, D, D, np.empty((10, 4)))
    state_kernel.pose(packed, D, np.empty(4))
    state_kernel.jc0(packed, D, np.empty((4, 4)))
    batch = np.zeros((1, 4))
    state_kernel.states(packed, batch, batch, batch, np.empty((10, 1, 4)))
    state_kernel.poses(packed, batch, np.empty((1, 4)))
    state_kernel.bucket_quaternion(0.0, 0.0, np.empty(4))
    state_kernel.bucket_angular_velocity(0.0, 0.0, 0.0, three)
    state_kernel.bucket_angular_acceleration(0.0, 0.0, 0.0, 0.0, 0.0, three)
    for function in (
        state_kernel.state,
        state_kernel.pose,
        state_kernel.jc0,
        state_kernel.states,
        state_kernel.poses,
        state_kernel.bucket_quaternion,
        state_kernel.bucket_angular_velocity,
        state_kernel.bucket_angular_acceleration,
        state_kernel.layout_signature,
    ):
        function.disable_compile()


#: The single-state kernel (:mod:`excavator_kinematics.core.state_kernel`), see
#: manipulator_kinematics.compiled.
KERNEL = Kernel("excavator_kinematics.core.state_kernel", _warm)


def compiled_kernel(model: Excavator, wait: bool = False) -> ModuleType | None:
    """The compiled kernel module if ready, else None (the first call starts loading it;
    calls take the numpy path meanwhile, the same results within 1e-12). ``wait``: load it now.
    One kernel serves every machine (``model``: for the call's symmetry with the IK's)."""
    return KERNEL.get(wait=wait)


class Excavator:
    """Kinematics of one excavator (geometry + limits), see the module docstring.

    Coordinates: D = [theta1, d2, d3, d4] (rad, m, m, m), theta = [theta1..theta4] (rad),
    Q = [x, y, z, alpha]: bucket tip in the base frame (m) and bucket line angle (rad).
    """

    def __init__(self, description: Description) -> None:
        """Build from a machine description (:func:`excavator_kinematics.core.machine_file.parse` makes
        one from a parameters file's section); raises ConfigError unless the linkage assembles
        over the whole stroke box."""
        g = description
        self.description = g
        self.name = g.name
        self.l1, self.l0 = g.foot
        self.l2, self.l3, self.l4 = g.boom_length, g.arm_length, g.bucket_length
        self.bucket_width = g.bucket_width
        #: The cylinder linkages (eqs. 1-2), read by this model and by the pose IK.
        self.linkages = Linkages.of(g)
        self.limits = g.limits
        #: The sensors' zero offsets in the order of D: true state = reading + zero_offset
        #: (:meth:`true_state`, :meth:`readings`); the limits are true values.
        self.zero_offset = np.array(g.zero_offset, dtype=float)
        # The limits of D as the shared IK pieces read them (cylinder values are lengths, m).
        # A continuous swing's angles are wrapped to (-pi, pi]: the IK answers in that range, and a
        # state outside it takes validate's slow path, which wraps it.
        lower, upper = self.limits.d_min, self.limits.d_max
        if self.limits.continuous_swing:
            lower, upper = np.concatenate(([-math.pi], lower[1:])), np.concatenate(([math.pi], upper[1:]))
        self.joint_limits = JointLimits(ACTUATORS, lower, upper, prismatic=(False, True, True, True))
        # The limits with the stroke tolerance applied (what validate and the kernel accept).
        self._lo = lower - STROKE_TOLERANCE
        self._hi = upper + STROKE_TOLERANCE
        if self.limits.continuous_swing:  # exactly (-pi, pi]: -pi goes the slow way, to pi
            self._lo[0], self._hi[0] = np.nextafter(-math.pi, 0.0), math.pi
        self._check_whole_stroke()
        self._check_branches()
        #: The IK's constants (:class:`excavator_kinematics.core.inverse.Constants`).
        self.ik_constants = inverse.Constants.of(self)
        #: The constants of the compiled single call (state_kernel), layout ``layouts.STATE``.
        self.packed = STATE.pack(
            {
                "l0": self.l0,
                "l1": self.l1,
                "l2": self.l2,
                "l3": self.l3,
                "l4": self.l4,
                "boom": self.linkages.boom.constants,
                "arm": self.linkages.arm.constants,
                "side": self.linkages.side.constants,
                "pivot_from_bucket_pin": self.linkages.pivot_from_bucket_pin,
                "four_bar": self.linkages.h_constants,
                "lower": self._lo,
                "upper": self._hi,
            }
        )

    def _check_whole_stroke(self) -> None:
        """Every length in the stroke box must assemble; a bad pin or length fails here, naming it."""
        samples = np.linspace(self.limits.stroke_min, self.limits.stroke_max, 2001)
        try:
            self.joint_angles(samples)
        except StrokeError as error:
            # Each linkage depends on its own cylinder only: the error names the culprit.
            i = next(i for i, name in enumerate(CYLINDERS) if str(error).startswith(name))
            raise ConfigError(
                f"{FAMILY}.cylinders.{CYLINDERS[i]}: the stroke [{self.limits.stroke_min[i]:g}, "
                f"{self.limits.stroke_max[i]:g}] m cannot be assembled with these pins and links: {error}"
            ) from None

    def _check_branches(self) -> None:
        """What a wrong assembly branch (an orientation's sign) does, refused naming the key: each
        cylinder must move its joint the documented way over its whole stroke (a backhoe's:
        extending the boom cylinder raises the boom, theta2 up; the arm and bucket cylinders curl
        the arm and the bucket in, theta3 and theta4 down; docs/excavator.md), the bucket's
        four-bar must not be crossed (the H-link pin and the side-link pivot on either side of the
        line from the bucket pin to the rod pin) and at the reference state the tip must be in
        front of the swing axis. A flipped boom cylinder orientation otherwise loads as a boom
        hanging down behind the machine (theta2 = -164 deg, tip at r = -3.4 m). Then each joint's
        range over its stroke (K keeps its sign: the stroke ends) must lie in the chain's limits."""
        samples = np.linspace(self.limits.stroke_min, self.limits.stroke_max, 2001)
        k, _ = self.k_entries(samples)
        for i, (name, sign, joint, what) in enumerate(
            (
                ("boom_cylinder", 1.0, "theta2", "raise the boom"),
                ("arm_cylinder", -1.0, "theta3", "curl the arm in"),
                ("bucket_cylinder", -1.0, "theta4", "curl the bucket in"),
            )
        ):
            wrong = k[:, i] * sign <= 0.0
            if np.any(wrong):
                at = samples[np.argmax(wrong), i]
                raise ConfigError(
                    f"{FAMILY}.dyads.{DYADS[i]}.orientation: extending {name} must {what} ({joint} "
                    f"{'up' if sign > 0 else 'down'}), this branch turns it the other way "
                    f"(d{joint}/dd = {k[np.argmax(wrong), i]:.3g} rad/m at {at:.4g} m): flip the sign"
                )
        reference = self.limits.reference
        (ex, ey), (hx, hy) = (np.ravel(v) for v in self._linkages(*(reference[1:, None]))[4])
        fx, fy = self.linkages.pivot_from_bucket_pin
        if (ex * hy - ey * hx) * (ex * fy - ey * fx) >= 0.0:
            raise ConfigError(
                f"{FAMILY}.dyads.{DYADS[3]}.orientation: this branch crosses the bucket linkage (the H-link "
                "pin on the side-link pivot's side of the line bucket pin -> rod pin): flip the sign"
            )
        r = self.open_chain_pose(np.concatenate(([0.0], self.joint_angles(reference[1:]))))[0]
        if r <= 0.0:
            raise ConfigError(
                f"{FAMILY}.cylinders.boom_cylinder.reference_length: at the reference lengths the bucket tip "
                f"is {-r:.3g} m behind the swing axis (r = {r:.3g} m); a backhoe's tool is in front: "
                "check the pins"
            )
        theta = (
            self.joint_angles(self.limits.stroke_min[None]),
            self.joint_angles(self.limits.stroke_max[None]),
        )
        for i, (joint, (lo, hi)) in enumerate(
            zip(TOPOLOGY["chain"], self.description.joint_limits, strict=True)
        ):
            ends = sorted(float(t[0, i]) for t in theta)
            if ends[0] < lo or ends[1] > hi:
                raise ConfigError(
                    f"{FAMILY}.chain.{joint}.limits: over the stroke {joint} spans "
                    f"[{math.degrees(ends[0]):.3f}, {math.degrees(ends[1]):.3f}] deg, outside its limits "
                    f"[{math.degrees(lo):.3f}, {math.degrees(hi):.3f}] deg"
                )

    @classmethod
    def from_file(cls, path: str | Path, node_name: str = "/**") -> Excavator:
        """The machine of a ROS 2 parameters file's ``hydraulic_machine`` and ``excavator``
        sections (an old-form file converted on load, :mod:`excavator_kinematics.core.machine_file`)."""
        return cls(parse(load_parameters(path, node_name), str(path)))

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> Excavator:
        """The machine of a file's nested top-level sections (``hydraulic_machine`` and
        ``excavator``, or an old-form ``excavator``); ConfigError names a bad key."""
        return cls(parse(params))

    @classmethod
    def default(cls) -> Excavator:
        """The package's default machine (CET200)."""
        return cls.from_file(config_path(DEFAULT_CONFIG))

    # ------------------------------------------------------------------ pose IK (inverse of eqs. 1-3)
    #: The SerialModel names of the IK (excavator_kinematics.core.inverse).
    ik_branches = inverse.BRANCHES
    ik_modes = inverse.MODES
    joint_names = ACTUATORS

    def ik(self, Q: Any, seed: Any = None, branch: str | None = None) -> IKSolutions:
        """Every D reaching Q = [x, y, z, alpha] (..., 4), each with a status, and the selected one
        (closed form, :mod:`excavator_kinematics.core.inverse`)."""
        return inverse.solve_pose(self, Q, seed, branch)

    def position_ik(self, position: Any, seed: Any = None, branch: str | None = None) -> IKSolutions:
        """:meth:`ik` for tip positions (..., 3): alpha the seed's, else the widest stroke margin."""
        return inverse.solve_position(self, position, seed, branch)

    def solve_ik(
        self,
        target: Any,
        *,
        use_orientation: bool = True,
        mode: str | None = None,
        seed: Any = None,
        branch: str | None = None,
    ) -> IKSolutions:
        """The SerialModel entry for bucket poses (..., 4, 4) (:func:`inverse.solve_ik`)."""
        return inverse.solve_ik(
            self, target, use_orientation=use_orientation, mode=mode, seed=seed, branch=branch
        )

    def fkine(self, D: Any) -> np.ndarray:
        """Bucket pose (..., 4, 4) in the base frame for D (..., 4): the tip, yaw theta1, then
        -alpha about y (eqs. 1-3; StrokeError outside the limits)."""
        D = np.asarray(D, dtype=float)
        Q = self.pose(D.reshape(-1, 4)).reshape(D.shape)
        pose = np.zeros(D.shape[:-1] + (4, 4))
        pose[..., :3, :3] = bucket_rotation(D[..., 0], Q[..., 3])
        pose[..., :3, 3] = Q[..., :3]
        pose[..., 3, 3] = 1.0
        return pose

    def jacob0(self, D: Any) -> np.ndarray:
        """(..., 6, 4): bucket twist [v; omega] = jacob0 Ddot; v = JC0's first rows (eq. 8), omega =
        theta1dot z - alphadot y' (docs/excavator.md, bucket twist)."""
        D = np.asarray(D, dtype=float)
        jc0 = self.jc0(D.reshape(-1, 4)).reshape(D.shape[:-1] + (4, 4))
        c1, s1 = np.cos(D[..., 0])[..., None], np.sin(D[..., 0])[..., None]
        swing = np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), jc0.shape[:-2] + (4,))
        angular = np.stack((s1 * jc0[..., 3, :], -c1 * jc0[..., 3, :], swing), axis=-2)
        return np.concatenate((jc0[..., :3, :], angular), axis=-2)

    def _compiled(self, function: str, out: np.ndarray, *arguments: np.ndarray) -> np.ndarray | None:
        """``out`` filled by the kernel's ``function`` (:mod:`excavator_kinematics.core.state_kernel`)
        for one state, or None: the kernel not loaded yet, arguments of types it does not take
        (:func:`_warm`), or a state it refuses (the numpy path then says why)."""
        kernel = KERNEL.ready or KERNEL.get()
        if kernel is None:
            return None
        try:
            return out if getattr(kernel, function)(self.packed, *arguments, out) else None
        except TypeError:
            return None

    # ------------------------------------------------------------------ validation
    def validate(self, D: Any) -> np.ndarray:
        """D as a float array of shape (4,) or (N, 4) (a continuous swing's angle wrapped to
        (-pi, pi]); raises StrokeError naming what is wrong."""
        D = np.asarray(D, dtype=float)
        if D.shape != (4,) and (D.ndim != 2 or D.shape[1] != 4):
            raise ValueError(
                f"expected D = [swing, boom, arm, bucket] of shape (4,) or (N, 4), got shape {D.shape}"
            )
        # Everything inside the limits: done (NaN fails every comparison, so it falls through to
        # the checks below, which name what is wrong).
        if np.all((self._lo <= D) & (self._hi >= D)):
            return D
        self._check_lengths(D[..., 1:])
        swing = D[..., 0]
        if not np.all(np.isfinite(swing)):
            raise StrokeError(f"swing_joint angle is not finite: {_first_bad(swing, np.isfinite(swing))}")
        if self.limits.continuous_swing:
            D = D.copy()
            D[..., 0] = wrap_swing(swing)
            return D
        lo, hi = self.limits.swing_min - STROKE_TOLERANCE, self.limits.swing_max + STROKE_TOLERANCE
        inside = (swing >= lo) & (swing <= hi)
        if not np.all(inside):
            raise StrokeError(
                f"swing_joint angle {_first_bad(swing, inside)} rad outside "
                f"[{self.limits.swing_min:.6g}, {self.limits.swing_max:.6g}] rad"
            )
        return D

    def true_state(self, readings: Any) -> np.ndarray:
        """D (4,) or (N, 4) from sensor readings [swing, boom, arm, bucket] (as on joint_states and
        cylinder_lengths): reading + zero_offset, validated as :meth:`validate` (the stroke box is
        of true lengths). Rates need no conversion: an offset is constant."""
        return self.validate(np.asarray(readings, dtype=float) + self.zero_offset)

    def readings(self, D: Any) -> np.ndarray:
        """What the sensors read at true states D (4,) or (N, 4): D - zero_offset (a continuous
        swing's reading wrapped to (-pi, pi]); the inverse of :meth:`true_state`."""
        out = np.asarray(D, dtype=float) - self.zero_offset
        if self.limits.continuous_swing:
            out[..., 0] = wrap_swing(out[..., 0])
        return out

    def _check_lengths(self, lengths: np.ndarray) -> None:
        finite = np.isfinite(lengths)
        inside = (lengths >= self.limits.stroke_min - STROKE_TOLERANCE) & (
            lengths <= self.limits.stroke_max + STROKE_TOLERANCE
        )
        if np.all(finite & inside):
            return
        for i, cylinder in enumerate(CYLINDERS):
            column = lengths[..., i]
            if not np.all(finite[..., i]):
                raise StrokeError(f"{cylinder} length is not finite: {_first_bad(column, finite[..., i])}")
            if not np.all(inside[..., i]):
                raise StrokeError(
                    f"{cylinder} length {_first_bad(column, inside[..., i]):.6g} m outside the stroke "
                    f"[{self.limits.stroke_min[i]:.6g}, {self.limits.stroke_max[i]:.6g}] m"
                )

    # ------------------------------------------------------------------ closed loops (eqs. 1-2, 7)
    def _linkages(self, d2: np.ndarray, d3: np.ndarray, d4: np.ndarray) -> tuple[tuple[Any, ...], ...]:
        """theta2..4 (eqs. 1-2) with their first (K, eq. 7) and second (K1) derivatives w.r.t.
        d2..d4 and their cosines and sines, plus the bucket linkage's rod pin R and H-link pin H
        relative to the bucket pin (arm frame): ``(theta, k, dk, trig, (R, H))``."""
        linkages = self.linkages
        theta2, k2, dk2, c2, s2 = linkages.boom.closes(d2)
        theta3, k3, dk3, c3, s3 = linkages.arm.closes(d3)
        # Cylinder four-bar (Fig. 7b): side-link angle phi's derivatives, same form; phi itself is
        # never needed, only R - pivot = side length * (cos, sin) phi.
        _, phi_d, phi_dd, rx, ry = linkages.side.closes(d4, angle=False)
        fx, fy = linkages.pivot_from_bucket_pin
        ex, ey = fx + rx, fy + ry  # R - bucket pin
        # Bucket four-bar (Fig. 7c, eq. 2): H from the triangle (bucket pin, R, H).
        h = linkages.h_constants
        b, o, cp, sp = h.b, h.o, h.cos_phase, h.sin_phase
        e2 = ex * ex + ey * ey
        e = np.sqrt(e2)
        ch = (e2 + h.bb_aa) / (h.two_b * e)
        sh = o * closing_sine(ch, "bucket_cylinder (bucket four-bar)")
        # H - bucket pin = fc (R - bucket pin) + fs perp(R - bucket pin): turned by the H angle
        # and scaled to length b.
        f = b / e
        fc, fs = f * ch, f * sh
        ox, oy = fc * ex - fs * ey, fc * ey + fs * ex
        theta4 = np.arctan2(ey, ex) + o * np.arccos(ch) - h.phase
        c4, s4 = ox * cp + oy * sp, oy * cp - ox * sp
        # Four-bar velocity ratio g1 = dpsi/dphi and g2 = d2psi/dphi2 from the loop constraint
        # (H - R).(vH - vR) = 0 and its time derivative; closed form, no iteration. With the
        # form of H above, (H - R) . perp(H - O4) = fs e^2 and (H - R) . (H - O4) = b^2 - fc e^2.
        cx, cy = ox - ex, oy - ey  # H - R
        den = fs * e2
        g1 = (cy * rx - cx * ry) / den
        wx, wy = g1 * ox - rx, g1 * oy - ry
        g2 = (g1 * g1 * (h.bb - fc * e2) - (cx * rx + cy * ry) - (wx * wx + wy * wy)) / den
        return (
            (theta2, theta3, theta4),
            (k2, k3, g1 * phi_d),
            (dk2, dk3, g2 * phi_d * phi_d + g1 * phi_dd),
            (c2, s2, c3, s3, c4, s4),
            ((ex, ey), (ox, oy)),
        )

    def joint_angles(self, lengths: Any) -> np.ndarray:
        """Cylinder lengths [d2, d3, d4] (..., 3) -> [theta2, theta3, theta4] (eqs. 1-2)."""
        lengths = _vectors(lengths, 3, "[boom, arm, bucket] lengths")
        self._check_lengths(lengths)
        flat = lengths.reshape(-1, 3)
        return _table(self._linkages(*_columns(flat))[0], flat.shape[:-1]).reshape(lengths.shape)

    def k_entries(self, lengths: Any) -> tuple[np.ndarray, np.ndarray]:
        """dtheta_i/dd_i (the diagonal of K, eq. 7) and d2theta_i/dd_i2 (of K1), for i = 2..4."""
        lengths = _vectors(lengths, 3, "[boom, arm, bucket] lengths")
        self._check_lengths(lengths)
        flat = lengths.reshape(-1, 3)
        _, k, dk, _, _ = self._linkages(*_columns(flat))
        return (
            _table(k, flat.shape[:-1]).reshape(lengths.shape),
            _table(dk, flat.shape[:-1]).reshape(lengths.shape),
        )

    def cylinder_lengths(self, angles: Any) -> np.ndarray:
        """Joint angles [theta2, theta3, theta4] (..., 3) -> cylinder lengths (inverse of eqs. 1-2).

        Closed form (:meth:`linkage_lengths`). Raises StrokeError when an angle needs a length
        outside the stroke or cannot be assembled.
        """
        angles = _vectors(angles, 3, "[theta2, theta3, theta4]")
        if not np.all(np.isfinite(angles)):
            raise StrokeError("joint angles are not finite")
        lengths = self.linkage_lengths(angles)
        for i, tri in enumerate((self.linkages.boom, self.linkages.arm)):
            if np.any(np.isnan(lengths[..., i])):
                raise StrokeError(f"{JOINTS[i + 1]} angle cannot be reached by {tri.name} on this assembly")
        if np.any(np.isnan(lengths[..., 2])):
            raise StrokeError("bucket_joint angle cannot be reached: side link and H-link cannot meet")
        try:
            self._check_lengths(lengths)
        except StrokeError as error:
            raise StrokeError(f"joint angles out of reach: {error}") from None
        return lengths

    def linkage_lengths(self, angles: np.ndarray) -> np.ndarray:
        """The cylinder lengths (..., 3) of joint angles (..., 3), NaN where a linkage cannot close
        (or an angle is NaN); no stroke check: what the pose IK judges candidate by candidate.

        Eq. 1's second line for boom and arm (the triangle closes for gamma in (0, pi] on its
        assembly); for the bucket, H from theta4, then the rod pin R as the intersection of the
        side-link and H-link circles on the assembly branch (eq. 2 backwards).
        """
        angles = np.asarray(angles, dtype=float)
        with np.errstate(invalid="ignore"):
            columns = inverse.linkage_length_columns(
                self.ik_constants, angles[..., 0], angles[..., 1], angles[..., 2]
            )
        return np.stack(columns, axis=-1)

    # ------------------------------------------------------------------ open chain (eqs. 3-5)
    def pose(self, D: Any) -> np.ndarray:
        """Q = [x, y, z, alpha] of the bucket tip for D (eqs. 1-3)."""
        D = np.asarray(D, dtype=float)
        if D.shape == (4,) and (Q := self._compiled("pose", np.empty(4), D)) is not None:
            return Q
        if D.ndim == 2 and D.shape[1] == 4 and (kernel := KERNEL.ready or KERNEL.get()) is not None:
            Q = np.empty(D.shape)  # _compiled written out, as in state
            try:
                if kernel.poses(self.packed, D, Q):
                    return Q
            except TypeError:  # arguments of types the kernel does not take (_warm)
                pass
        D = self.validate(D)
        return in_blocks(self._poses, D.reshape(-1, 4), block=_BLOCK, rows=True).T.reshape(D.shape)

    def _poses(self, D: np.ndarray) -> tuple[np.ndarray, ...]:
        """The columns of Q (N, 4) of valid states D (N, 4) (eqs. 1-3)."""
        t1, d2, d3, d4 = _columns(D)
        (t2, t3, t4), _, _, trig, _ = self._linkages(d2, d3, d4)
        a1, _, _, b1, _, _ = self._chain_terms(*trig)
        return tuple(self._tip(t1, a1, b1, t2 + t3 + t4))

    def open_chain_pose(self, theta: Any) -> np.ndarray:
        """Q = [x, y, z, alpha] from the open-chain joints theta1..theta4 (eq. 3), no limits."""
        theta = _vectors(theta, 4, "theta = [theta1, theta2, theta3, theta4]")
        t1, t2, t3, t4 = _columns(theta.reshape(-1, 4))
        a1, _, _, b1, _, _ = self._chain_terms(
            np.cos(t2), np.sin(t2), np.cos(t3), np.sin(t3), np.cos(t4), np.sin(t4)
        )
        return _table(self._tip(t1, a1, b1, t2 + t3 + t4), t1.shape).reshape(theta.shape)

    def _tip(self, t1: np.ndarray, a1: np.ndarray, b1: np.ndarray, alpha: np.ndarray) -> list[np.ndarray]:
        """Eq. 3 from eq. 4's coefficients: the boom-plane radius rho = l1 + b1 turned by the
        swing, z = l0 + a1."""
        rho, (c1, s1) = self.l1 + b1, cos_sin(t1)
        return [rho * c1, rho * s1, self.l0 + a1, alpha]

    def pins(self, D: Any) -> dict[str, np.ndarray]:
        """Every pin (and the tip) in the base frame, shape (..., 3), for drawing and checking."""
        D = self.validate(D)
        t1, d2, d3, d4 = _columns(D)
        (t2, t3, t4), _, _, _, ((ex, ey), (ox, oy)) = self._linkages(d2, d3, d4)
        bx, by = self.linkages.bucket_pin.tolist()
        pins = self.linkages.pins
        foot = np.array([self.l1, self.l0])

        def place(origin: np.ndarray, angle: Any, local: Any) -> np.ndarray:
            c, s = np.cos(angle), np.sin(angle)
            x = np.asarray(local[0]) * c - np.asarray(local[1]) * s
            y = np.asarray(local[0]) * s + np.asarray(local[1]) * c
            return np.stack((origin[..., 0] + x, origin[..., 1] + y), axis=-1)

        zero = np.zeros_like(t2)
        boom = (foot + zero[..., None], t2)
        arm_pin = place(*boom, (self.l2, 0.0))
        arm = (arm_pin, t2 + t3)
        bucket_pin = place(*arm, self.linkages.bucket_pin)
        bucket = (bucket_pin, t2 + t3 + t4)
        side = {
            "boom_foot": foot + zero[..., None],
            "boom_cylinder_base": pins["boom_cylinder_base"] + zero[..., None],
            "boom_cylinder_rod": place(*boom, pins["boom_cylinder_rod"]),
            "arm_pin": arm_pin,
            "arm_cylinder_base": place(*boom, pins["arm_cylinder_base"]),
            "arm_cylinder_rod": place(*arm, pins["arm_cylinder_rod"]),
            "bucket_pin": bucket_pin,
            "bucket_cylinder_base": place(*arm, pins["bucket_cylinder_base"]),
            "side_link_pivot": place(*arm, self.linkages.pivot),
            "bucket_cylinder_rod": place(*arm, (bx + ex, by + ey)),
            "h_link_pin": place(*arm, (bx + ox, by + oy)),
            "h_link_pin_on_bucket": place(*bucket, pins["h_link_pin"]),
            "bucket_tip": place(*bucket, (self.l4, 0.0)),
        }
        c1, s1 = np.cos(t1)[..., None], np.sin(t1)[..., None]
        return {
            name: np.concatenate((p[..., :1] * c1, p[..., :1] * s1, p[..., 1:]), axis=-1)
            for name, p in side.items()
        }

    def _chain_terms(
        self, c2: np.ndarray, s2: np.ndarray, c3: np.ndarray, s3: np.ndarray, c4: np.ndarray, s4: np.ndarray
    ) -> tuple[np.ndarray, ...]:
        """a1..a3, b1..b3 of eq. 4 from cos/sin of theta2, theta3, theta4 (the sums by angle
        addition): a_i = sum of l_j sin(theta2 + .. + theta_j) over j >= i, b_i the cosines."""
        c23, s23 = c2 * c3 - s2 * s3, s2 * c3 + c2 * s3
        c234, s234 = c23 * c4 - s23 * s4, s23 * c4 + c23 * s4
        a3, b3 = self.l4 * s234, self.l4 * c234
        a2, b2 = self.l3 * s23 + a3, self.l3 * c23 + b3
        return self.l2 * s2 + a2, a2, a3, self.l2 * c2 + b2, b2, b3

    def j0(self, theta: Any) -> np.ndarray:
        """J0(theta) of eq. 5: Qdot = J0 thetadot, rows x, y, z, alpha; columns theta1..theta4."""
        theta = _vectors(theta, 4, "theta = [theta1, theta2, theta3, theta4]")
        t1, t2, t3, t4 = _columns(theta.reshape(-1, 4))
        a1, a2, a3, b1, b2, b3 = self._chain_terms(
            np.cos(t2), np.sin(t2), np.cos(t3), np.sin(t3), np.cos(t4), np.sin(t4)
        )
        rho, c1, s1 = self.l1 + b1, np.cos(t1), np.sin(t1)
        entries = [
            -rho * s1,
            -a1 * c1,
            -a2 * c1,
            -a3 * c1,
            rho * c1,
            -a1 * s1,
            -a2 * s1,
            -a3 * s1,
            0.0,
            b1,
            b2,
            b3,
            0.0,
            1.0,
            1.0,
            1.0,
        ]
        return _table(entries, t1.shape).reshape(theta.shape[:-1] + (4, 4))

    def joint_rates(self, theta: Any, Q_dot: Any) -> np.ndarray:
        """thetadot = J0^-1 Qdot (eq. 6): open-chain joint rates for a tip velocity.

        StrokeError where J0 is exactly singular: det J0 = rho l2 l3 sin(theta3) up to sign, zero
        with the tip on the swing axis or the arm in line with the boom.
        """
        theta = _vectors(theta, 4, "theta = [theta1, theta2, theta3, theta4]")
        Q_dot = _finite(Q_dot, theta.shape, "Q_dot")
        try:
            return np.linalg.solve(self.j0(theta), Q_dot[..., None])[..., 0]
        except np.linalg.LinAlgError:
            raise StrokeError("J0 is singular at this state (bucket tip on the swing axis)") from None

    def k_matrix(self, D: Any) -> np.ndarray:
        """K = diag(1, dtheta2/dd2, dtheta3/dd3, dtheta4/dd4) of eq. 7 (theta1 is D's own swing)."""
        D = self.validate(D)
        k, _ = self.k_entries(D[..., 1:])
        ones = np.ones(D.shape[:-1] + (1,))
        diagonal = np.concatenate((ones, k), axis=-1)
        return diagonal[..., :, None] * np.eye(4)

    def jc0(self, D: Any) -> np.ndarray:
        """JC0 = J0 K (eq. 8): Qdot = JC0 Ddot."""
        D = np.asarray(D, dtype=float)
        if D.shape == (4,) and (jc0 := self._compiled("jc0", np.empty((4, 4)), D)) is not None:
            return jc0
        D = self.validate(D)
        table = in_blocks(self._jc0s, D.reshape(-1, 4), block=_BLOCK, rows=True)
        return table.T.reshape(D.shape[:-1] + (4, 4))

    def _jc0s(self, D: np.ndarray) -> tuple[np.ndarray, ...]:
        """The 16 entries of JC0 (eq. 8), row by row, of valid states D (N, 4), each (N,)."""
        t1, d2, d3, d4 = _columns(D)
        _, (k2, k3, k4), _, trig, _ = self._linkages(d2, d3, d4)
        a1, a2, a3, b1, b2, b3 = self._chain_terms(*trig)
        return tuple(
            _jc0_entries(self.l1 + b1, *cos_sin(t1), a1, a2, a3, b1, b2, b3, k2, k3, k4, np.zeros(t1.shape))
        )

    # ------------------------------------------------------------------ full state (eqs. 3-11)
    def state(self, D: Any, D_dot: Any, D_ddot: Any = None) -> BucketState:
        """Bucket pose, velocity (eq. 8) and acceleration (eqs. 10-11) from cylinder states.

        The acceleration is Qddot = J0 thetaddot + Jdot0 thetadot with thetaddot = K Dddot +
        K1 Ddot^2, i.e. JC0 Dddot plus the velocity-product terms of eq. 11 (see
        :meth:`acceleration_matrices` for the paper's JC1_0 / JC2_0 split of those terms).
        """
        D = np.asarray(D, dtype=float)
        if (kernel := KERNEL.ready or KERNEL.get()) is not None:
            # The single call (a 1 kHz node calls it per message) and a batch (N, 4), each one
            # call of the kernel into a new table (the caller keeps the views): the kernel checks
            # shapes and values; the numpy path below raises the error for what it refuses.
            # _compiled written out: calling it costs 0.17 us, a fifth of the benchmark's peer (a
            # numba pose call); a batch of one took 10x a single call through the numpy checks.
            rates = np.asarray(D_dot, dtype=float)
            try:
                if D.ndim == 1:
                    given = _NO_ACCELERATION if D_ddot is None else np.asarray(D_ddot, dtype=float)
                    rows = np.empty((10, 4))
                    if kernel.state(self.packed, D, rates, given, rows):
                        return BucketState(rows)
                elif D.ndim == 2:
                    # Rates (4,) for every state: one row the kernel reads for each.
                    rates = rates if rates.ndim == 2 else rates.reshape(1, -1)
                    given = _NO_ACCELERATIONS if D_ddot is None else np.asarray(D_ddot, dtype=float)
                    if given.ndim == 1:
                        given = given.reshape(1, -1)
                    rows = np.empty((10, len(D), 4))
                    if kernel.states(self.packed, D, rates, given, rows):
                        return BucketState(rows)
            except TypeError:  # arguments of types the kernel does not take (_warm)
                pass
        D = self.validate(D)
        rates = _finite(D_dot, D.shape, "D_dot").reshape(-1, 4)
        accelerations = None if D_ddot is None else _finite(D_ddot, D.shape, "D_ddot").reshape(-1, 4)
        flat = np.ascontiguousarray(D.reshape(-1, 4))
        # (40, N): entry j of every state in row j.
        table = in_blocks(self._states, flat, rates, accelerations, block=_BLOCK, rows=True)
        return BucketState(table.reshape(10, 4, len(flat)).swapaxes(1, 2).reshape((10, *D.shape)))

    def _states(self, D: np.ndarray, D_dot: np.ndarray, D_ddot: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """The 40 entries of BucketStates, each (N,): theta, theta_dot, theta_ddot, Q, Q_dot,
        Q_ddot, then JC0 row by row, of valid states D (N, 4) with rates D_dot and accelerations
        D_ddot (None: zero)."""
        t1, d2, d3, d4 = _columns(D)
        w1, v2, v3, v4 = _columns(D_dot)
        e1, f2, f3, f4 = np.zeros((4, len(D))) if D_ddot is None else _columns(D_ddot)
        (t2, t3, t4), (k2, k3, k4), (dk2, dk3, dk4), trig, _ = self._linkages(d2, d3, d4)
        a1, a2, a3, b1, b2, b3 = self._chain_terms(*trig)
        rho, (c1, s1) = self.l1 + b1, cos_sin(t1)
        # thetadot = K Ddot (eq. 7); thetaddot = K Dddot + K1 Ddot^2 (its time derivative).
        w2, w3, w4 = k2 * v2, k3 * v3, k4 * v4
        e2, e3, e4 = k2 * f2 + dk2 * v2 * v2, k3 * f3 + dk3 * v3 * v3, k4 * f4 + dk4 * v4 * v4
        # Eqs. 8 and 10 in the boom plane: rho = l1 + l2 c2 + l3 c23 + l4 c234 and z = l0 +
        # l2 s2 + l3 s23 + l4 s234, whose links turn at w2, o23 = w2 + w3 and alphadot = o23 + w4.
        # The rates are eq. 4's columns times thetadot; the accelerations add each link's
        # centripetal term -(l c, l s) o^2, where l2 c2 = b1 - b2, l3 c23 = b2 - b3, l4 c234 = b3
        # (likewise a for the sines): eq. 4's coefficients, no new trigonometry.
        o23 = w2 + w3
        alpha_dot = o23 + w4
        q2, q23, q234 = w2 * w2, o23 * o23, alpha_dot * alpha_dot
        rho_dot, z_dot = -(a1 * w2 + a2 * w3 + a3 * w4), b1 * w2 + b2 * w3 + b3 * w4
        rho_ddot = -(a1 * e2 + a2 * e3 + a3 * e4 + (b1 - b2) * q2 + (b2 - b3) * q23 + b3 * q234)
        z_ddot = b1 * e2 + b2 * e3 + b3 * e4 - ((a1 - a2) * q2 + (a2 - a3) * q23 + a3 * q234)
        # x, y = rho (cos, sin) theta1: the boom plane's motion turned by the swing; d/dt of
        # (c1, s1) brings in the swing rate w1 and acceleration e1.
        x, y = rho * c1, rho * s1
        radial = rho_ddot - rho * w1 * w1
        tangential = 2.0 * rho_dot * w1 + rho * e1
        entries = [
            t1,
            t2,
            t3,
            t4,
            w1,
            w2,
            w3,
            w4,
            e1,
            e2,
            e3,
            e4,
            x,
            y,
            self.l0 + a1,
            t2 + t3 + t4,
            rho_dot * c1 - y * w1,
            rho_dot * s1 + x * w1,
            z_dot,
            alpha_dot,
            c1 * radial - s1 * tangential,
            s1 * radial + c1 * tangential,
            z_ddot,
            e2 + e3 + e4,
            *_jc0_entries(rho, c1, s1, a1, a2, a3, b1, b2, b3, k2, k3, k4, np.zeros(t1.shape)),
        ]
        return tuple(entries)

    def acceleration_matrices(self, D: Any) -> tuple[np.ndarray, np.ndarray]:
        """JC1_0 (..., 4, 4) and JC2_0 (..., 4, 6) of eq. 11.

        Qddot = JC0 Dddot + JC1_0 Ddot^2 + JC2_0 DDdot with Ddot^2 = the squared rates and
        DDdot = [d1 d2, d1 d3, d1 d4, d2 d3, d2 d4, d3 d4] (products of the rates of D).
        JC1_0 = J0 K1 + J1_0 K^2, JC2_0 = J2_0 K2, where J1_0 / J2_0 hold the pure and mixed
        second derivatives of eq. 3 and K2 the products k_i k_j.
        """
        D = self.validate(D)
        t1, d2, d3, d4 = (D[..., i] for i in range(4))
        (t2, t3, t4), (k2, k3, k4), (dk2, dk3, dk4), trig, _ = self._linkages(d2, d3, d4)
        a1, a2, a3, b1, b2, b3 = self._chain_terms(*trig)
        rho, c1, s1 = self.l1 + b1, np.cos(t1), np.sin(t1)
        k = np.stack((np.ones_like(k2), k2, k3, k4), axis=-1)
        dk = np.stack((np.zeros_like(dk2), dk2, dk3, dk4), axis=-1)
        # Hessian of Q(theta): d2rho/dthj dthk = -b_max(j,k); d2z = -a_max(j,k); rho = l1 + b1.
        a = np.stack((a1, a2, a3), axis=-1)
        b = np.stack((b1, b2, b3), axis=-1)
        hess = np.zeros(D.shape[:-1] + (4, 4, 4))
        hess[..., 0, 0, 0], hess[..., 1, 0, 0] = -rho * c1, -rho * s1
        for j in range(1, 4):
            hess[..., 0, 0, j] = hess[..., 0, j, 0] = s1 * a[..., j - 1]
            hess[..., 1, 0, j] = hess[..., 1, j, 0] = -c1 * a[..., j - 1]
            for i in range(1, 4):
                top = max(i, j) - 1
                hess[..., 0, i, j] = -c1 * b[..., top]
                hess[..., 1, i, j] = -s1 * b[..., top]
                hess[..., 2, i, j] = -a[..., top]
        j0 = self.j0(np.stack((t1, t2, t3, t4), axis=-1))
        diag = np.arange(4)
        jc1 = j0 * dk[..., None, :] + hess[..., diag, diag] * (k * k)[..., None, :]
        pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
        jc2 = np.stack(
            [2.0 * hess[..., i, j] * (k[..., i] * k[..., j])[..., None] for i, j in pairs], axis=-1
        )
        return jc1, jc2

    # ------------------------------------------------------------------ inverse (eqs. 9, 12-13)
    def cylinder_rates(self, D: Any, Q_dot: Any) -> RateSolution:
        """Ddot = JC0^-1 Qdot (eq. 9), solved (LU), with the 2-norm condition number of JC0.

        The condition number is in the mixed units of JC0 (rows m/s, m/s, m/s, rad/s; columns
        rad/s, m/s, m/s, m/s). Raises StrokeError when JC0 is exactly singular (tip on the swing
        axis); callers that must always produce a command use damped least squares on jc0().
        """
        D = self.validate(D)
        Q_dot = _finite(Q_dot, D.shape, "Q_dot")
        jc0 = self.jc0(D)
        try:
            rates = np.linalg.solve(jc0, Q_dot[..., None])[..., 0]
        except np.linalg.LinAlgError:
            raise StrokeError("JC0 is singular at this state (bucket tip on the swing axis)") from None
        return RateSolution(D_dot=rates, condition=np.linalg.cond(jc0))

    def cylinder_accelerations(self, D: Any, D_dot: Any, Q_ddot: Any) -> np.ndarray:
        """Dddot = JC0^-1 (Qddot - velocity-product terms) (eq. 13); D_dot from eq. 9."""
        D = self.validate(D)
        Q_ddot = _finite(Q_ddot, D.shape, "Q_ddot")
        free = self.state(D, D_dot)  # Dddot = 0: only the velocity-product terms remain
        try:
            return np.linalg.solve(free.jc0, (Q_ddot - free.Q_ddot)[..., None])[..., 0]
        except np.linalg.LinAlgError:
            raise StrokeError("JC0 is singular at this state (bucket tip on the swing axis)") from None

    def joint_accelerations(self, D: Any, D_dot: Any, Q_ddot: Any) -> np.ndarray:
        """thetaddot = J0^-1 (Qddot - Jdot0 thetadot) (eq. 12)."""
        D = self.validate(D)
        Q_ddot = _finite(Q_ddot, D.shape, "Q_ddot")
        free = self.state(D, D_dot)
        j0 = self.j0(free.theta)
        # free.Q_ddot = J0 K1 Ddot^2 + Jdot0 thetadot; remove the K1 part to keep Jdot0 thetadot.
        return np.linalg.solve(j0, (Q_ddot - free.Q_ddot)[..., None])[..., 0] + free.theta_ddot


def _row(i: int, doc: str) -> property:
    """The field in row ``i`` of :class:`BucketState`'s rows: a view, made when read."""
    return property(lambda state: state._rows[i], doc=doc)


class BucketState:
    """Forward kinematic state; arrays of shape (..., 4) (jc0: (..., 4, 4)).

    The fields are views of one array ``rows`` (10, ..., 4), made when a field is read: theta,
    theta_dot, theta_ddot, Q, Q_dot, Q_ddot in rows 0-5, JC0's rows in 6-9 (what the kernel
    writes per state). Why not a NamedTuple of the seven views: making them costs 0.5-0.8 us,
    as much as the compiled call they come from, whether the caller reads them or not. Read
    like the NamedTuple it was: by name, by position (``s[3]``, slices), unpacked, ``len``,
    ``_fields``, ``_asdict``.
    """

    __slots__ = ("_rows",)
    _fields = ("theta", "theta_dot", "theta_ddot", "Q", "Q_dot", "Q_ddot", "jc0")

    def __init__(self, rows: np.ndarray) -> None:
        self._rows = rows

    theta = _row(0, "open-chain joints theta1..theta4 (rad)")
    theta_dot = _row(1, "open-chain joint rates (rad/s, eq. 7)")
    theta_ddot = _row(2, "open-chain joint accelerations (rad/s^2)")
    Q = _row(3, "[x, y, z, alpha]: bucket tip (m) and bucket angle (rad), eq. 3")
    Q_dot = _row(4, "tip velocity (eq. 8)")
    Q_ddot = _row(5, "tip acceleration (eqs. 10-11)")

    @property
    def jc0(self) -> np.ndarray:
        """JC0 = J0 K (eq. 8), (..., 4, 4)."""
        return self._rows[6:].swapaxes(0, -2)  # (4, ..., 4) -> (..., 4, 4): "..." is (N,) or ()

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.theta, self.theta_dot, self.theta_ddot, self.Q, self.Q_dot, self.Q_ddot, self.jc0))

    def __len__(self) -> int:
        return len(self._fields)

    def __getitem__(self, index: int | slice) -> Any:
        return tuple(self)[index]

    def _asdict(self) -> dict[str, np.ndarray]:
        return dict(zip(self._fields, self, strict=True))

    def __repr__(self) -> str:
        return f"BucketState({', '.join(f'{name}={value!r}' for name, value in self._asdict().items())})"


@dataclass(frozen=True)
class RateSolution:
    """Result of eq. 9."""

    D_dot: np.ndarray  # (..., 4) [swing rate rad/s, boom, arm, bucket cylinder rates m/s]
    condition: np.ndarray  # (...,) 2-norm condition number of JC0


def _jc0_entries(
    rho: np.ndarray,
    c1: np.ndarray,
    s1: np.ndarray,
    a1: np.ndarray,
    a2: np.ndarray,
    a3: np.ndarray,
    b1: np.ndarray,
    b2: np.ndarray,
    b3: np.ndarray,
    k2: np.ndarray,
    k3: np.ndarray,
    k4: np.ndarray,
    zero: np.ndarray,
) -> list[np.ndarray]:
    """JC0 = J0 K (eqs. 5, 7, 8), row by row; column 1 is theta1 itself (k1 = 1).

    The boom-plane columns are -a_i k_i (d rho / d D_i, eq. 4) turned by the swing; ``zero``
    (zeros of the batch's shape) fills the two entries that are zero by structure.
    """
    r2, r3, r4 = a1 * k2, a2 * k3, a3 * k4
    return [
        -s1 * rho,
        -c1 * r2,
        -c1 * r3,
        -c1 * r4,
        c1 * rho,
        -s1 * r2,
        -s1 * r3,
        -s1 * r4,
        zero,
        b1 * k2,
        b2 * k3,
        b3 * k4,
        zero,
        k2,
        k3,
        k4,
    ]


def _columns(values: np.ndarray) -> np.ndarray:
    """The columns of values (N, k) as the contiguous rows of one array (k, N): every later
    ufunc then streams memory instead of striding through rows."""
    return np.ascontiguousarray(values.T)


def _table(entries: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Entries (arrays of ``shape`` (N,) or floats) -> array (N, len(entries)); filled entry by
    entry into contiguous rows and returned as a view (the layout of the blocks' outputs)."""
    out = np.empty((len(entries), *shape))
    for row, entry in zip(out, entries, strict=True):
        row[...] = entry
    return out.T


def _finite(values: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    """``values`` as a finite float array of ``shape`` = D's shape; one vector of four is
    broadcast over a batch. ValueError (shape) or StrokeError (not finite) naming ``name``."""
    array = np.asarray(values, dtype=float)
    if array.shape != shape:
        if array.shape != (4,):
            raise ValueError(f"{name}: expected shape (4,) or {shape} (D's), got shape {array.shape}")
        array = np.broadcast_to(array, shape)
    if not np.all(np.isfinite(array)):
        raise StrokeError(f"{name} is not finite: {array}")
    return array


def _vectors(values: Any, k: int, what: str) -> np.ndarray:
    """``values`` as a float array of shape (k,) or (N, k), else ValueError saying the shape."""
    array = np.asarray(values, dtype=float)
    if array.ndim not in (1, 2) or array.shape[-1] != k:
        raise ValueError(f"expected {what} of shape ({k},) or (N, {k}), got shape {array.shape}")
    return array


def _first_bad(values: np.ndarray, good: np.ndarray) -> float:
    return float(np.asarray(values)[~np.asarray(good)].flat[0])


# ---------------------------------------------------------------------- ROS-facing geometry
def _last_axis(*components: np.ndarray) -> np.ndarray:
    return np.stack(np.broadcast_arrays(*components), axis=-1)


def _floats(*values: Any) -> bool:
    """All Python (or numpy) floats: one state, which the kernel computes once loaded."""
    return all(isinstance(value, float) for value in values)


def bucket_rotation(theta1: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """R = Rz(theta1) Ry(-alpha) (..., 3, 3): the bucket frame (docs/excavator.md, Frames)."""
    c1, s1, ca, sa = np.cos(theta1), np.sin(theta1), np.cos(alpha), np.sin(alpha)
    zero = np.zeros_like(c1)
    return np.stack(
        [
            np.stack([c1 * ca, -s1, -c1 * sa], axis=-1),
            np.stack([s1 * ca, c1, -s1 * sa], axis=-1),
            np.stack([sa, zero, ca], axis=-1),
        ],
        axis=-2,
    )


def bucket_quaternion(theta1: Any, alpha: Any) -> np.ndarray:
    """Bucket orientation [x, y, z, w] in the REP 103 base frame: yaw theta1 about z, then
    the bucket angle alpha about the boom-plane normal, i.e. a rotation about +y by -alpha.
    One state of floats runs compiled (a node calls this per message), arrays on numpy."""
    if _floats(theta1, alpha) and (kernel := KERNEL.get()) is not None:
        out = np.empty(4)
        kernel.bucket_quaternion(theta1, alpha, out)
        return out
    theta1, alpha = np.asarray(theta1, dtype=float), np.asarray(alpha, dtype=float)
    cy, sy = np.cos(0.5 * theta1), np.sin(0.5 * theta1)
    cp, sp = np.cos(0.5 * alpha), -np.sin(0.5 * alpha)
    # q_z(theta1) * q_y(-alpha)
    return _last_axis(-sy * sp, cy * sp, sy * cp, cy * cp)


def bucket_angular_velocity(theta1: Any, theta1_dot: Any, alpha_dot: Any) -> np.ndarray:
    """omega = theta1dot z - alphadot y', y' = (-sin theta1, cos theta1, 0) the boom-plane normal
    (one state of floats compiled, as :func:`bucket_quaternion`)."""
    if _floats(theta1, theta1_dot, alpha_dot) and (kernel := KERNEL.get()) is not None:
        out = np.empty(3)
        kernel.bucket_angular_velocity(theta1, theta1_dot, alpha_dot, out)
        return out
    theta1, alpha_dot = np.asarray(theta1, dtype=float), np.asarray(alpha_dot, dtype=float)
    return _last_axis(
        alpha_dot * np.sin(theta1), -alpha_dot * np.cos(theta1), np.asarray(theta1_dot, dtype=float)
    )


def bucket_angular_acceleration(
    theta1: Any, theta1_dot: Any, theta1_ddot: Any, alpha_dot: Any, alpha_ddot: Any
) -> np.ndarray:
    """Time derivative of :func:`bucket_angular_velocity` (y' turns with the swing)."""
    state = (theta1, theta1_dot, theta1_ddot, alpha_dot, alpha_ddot)
    if _floats(*state) and (kernel := KERNEL.get()) is not None:
        out = np.empty(3)
        kernel.bucket_angular_acceleration(*state, out)
        return out
    theta1, w, w_dot, a_dot, a_ddot = (
        np.asarray(v, dtype=float) for v in (theta1, theta1_dot, theta1_ddot, alpha_dot, alpha_ddot)
    )
    c, s = np.cos(theta1), np.sin(theta1)
    return _last_axis(a_ddot * s + a_dot * w * c, -a_ddot * c + a_dot * w * s, w_dot)
