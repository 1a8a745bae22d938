"""Hydraulic excavator kinematics as a hybrid chain (paper 000: Zhang, Su, Yin, 1994).

The manipulator is an open main chain (swing theta1, boom theta2, arm theta3, bucket theta4)
driven by independent closed-loop cylinder mechanisms with secondary coordinates
D = [theta1, d2, d3, d4] (swing angle and the boom, arm and bucket cylinder lengths). The
bucket tip is Q = [x, y, z, alpha] (m, rad). Frames and conventions: docs/excavator.md.

The numpy path, the reference, is the hydraulic family's numpy core
(:class:`manipulator_kinematics.hydraulic.HydraulicModel`, held as :attr:`Excavator.hydraulic`):
the same machine file's ``hydraulic_machine`` section solved by sequential dyads, the pins carried
with their derivatives (docs/hydraulic_family.md). This module checks D the excavator's way (the
stroke tolerance, a continuous swing wrapped), maps the core's results onto the excavator's API
(:class:`BucketState`, the excavator's pin names, its errors) and adds what only the excavator
has (sensor offsets, the bucket frame, the pose IK of :mod:`excavator_kinematics.core.inverse`).

Paper equation -> where it is computed:

====  ===========================================  ==============================================
eq.   relation                                     function
====  ===========================================  ==============================================
1     boom/arm triangle: theta(d), d(theta),       the core's dyads (via ``joint_angles``,
      k21 = dtheta/dd, k22 = d2theta/dd2           ``k_entries``); inverse: ``cylinder_lengths``
2     bucket six-bar = cylinder four-bar + bucket  the core's dyads (via ``joint_angles``);
      four-bar in series: theta4(d4) and rates     inverse: ``cylinder_lengths``
3     Q(theta), open chain                         ``pose``, ``open_chain_pose``
4-5   Qdot = J0 thetadot, J0 by columns            ``j0`` (the core's closed form)
6     thetadot = J0^-1 Qdot                        ``joint_rates``
7     thetadot = K Ddot                            ``k_matrix``, ``k_entries``; ``state.theta_dot``
8     Qdot = JC0 Ddot, JC0 = J0 K                  ``jc0``; ``state.Q_dot``, ``state.jc0``
9     Ddot = JC0^-1 Qdot                           ``cylinder_rates``
10    Qddot = J0 thetaddot + Jdot0 thetadot        ``state.Q_ddot`` (the core's jets)
11    Qddot = JC0 Dddot + JC1_0 Ddot^2 + JC2_0 DD  ``acceleration_matrices`` (same value as eq. 10)
12    thetaddot = J0^-1 (Qddot - Jdot0 thetadot)   ``joint_accelerations``
13    Dddot = JC0^-1 (Qddot - JC1_0 .. - JC2_0 ..) ``cylinder_accelerations``
====  ===========================================  ==============================================

Everything is closed form, plain vectorised numpy on (..., n) arrays: one state (shape (4,)) is
a batch of one through the same code (the same bits as that row of a batch); a batch (shape (N,
4)) runs in blocks of rows (:func:`manipulator_kinematics.row_blocks.in_blocks`). Rates and
accelerations have D's shape or (4,), broadcast over a batch. The single call of
:meth:`Excavator.state`, :meth:`Excavator.pose` and :meth:`Excavator.jc0`, and a batch of
``state`` and ``pose``, run the same steps compiled (:mod:`excavator_kinematics.core.state_kernel`,
numba; the excavator's own kernel, faster than the family's generic one: see ``Excavator.packed``)
once that kernel has loaded in the background (:class:`manipulator_kinematics.compiled.Kernel`;
the numpy path answers meanwhile and stays the reference, within 1e-12). Errors: a wrong shape
is a ``ValueError`` saying "shape"; a state the machine cannot take (outside a stroke or the
swing range, not finite, a singular JC0) is a :class:`StrokeError` (also a ValueError). The
machine file is read by :mod:`excavator_kinematics.core.machine_file`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from excavator_kinematics.core import inverse
from excavator_kinematics.core.geometry import Linkages, StrokeError
from excavator_kinematics.core.layouts import STATE, check_compiled
from excavator_kinematics.core.machine_file import (
    CYLINDERS,
    DYADS,
    FAMILY,
    PINS,
    STROKE_TOLERANCE,
    TOPOLOGY,
    Description,
    parse,
    wrap_swing,
)
from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.hydraulic import HydraulicModel, HydraulicState
from manipulator_kinematics.hydraulic.model import KERNEL as FAMILY_KERNEL
from manipulator_kinematics.model import IKSolutions
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.row_blocks import BLOCK, in_blocks
from manipulator_kinematics.serial_chain import JointLimits

JOINTS = ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")
# Names of D's components in D's order: the actuators (swing drive and the three cylinders).
ACTUATORS = (JOINTS[0], *CYLINDERS)
DEFAULT_CONFIG = "excavator_cet200.yaml"

# States per block of the numpy path (pose, jc0, K and state): the family core's fixed cost per
# call (some 600 array operations) falls with the block, the cache misses of its temporaries rise.
# Measured on 10^5 states, CPU ms per batch (state / pose): 1024 states per block 788 / 686,
# 2048 618 / 591, 4096 557 / 551, 8192 554 / 553, 16384 591 / 539, 32768 771 / 603.
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
# The table's shape for a batch of one, made once (a tuple made per call costs 0.04 us).
_ROWS_OF_ONE = (10, 1, 4)
# The cylinders at 1 m/s, the swing still (Excavator.k_entries); the rates along which Qddot gives
# eq. 11's matrices: each actuator alone, then each pair (Excavator.acceleration_matrices).
_CYLINDER_RATES = np.array([0.0, 1.0, 1.0, 1.0])
_AT_REST = np.zeros(4)
_PAIRS = np.array([(i, j) for i in range(4) for j in range(i + 1, 4)])
_PROBES = np.concatenate((np.eye(4), np.eye(4)[_PAIRS[:, 0]] + np.eye(4)[_PAIRS[:, 1]]))


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
        #: The cylinder linkages (eqs. 1-2) folded: the pose IK's and the kernel's constants.
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
        #: The hydraulic family's model of this machine (the same section of the same file): its
        #: numpy core computes every forward quantity here (the reference); the excavator adds its
        #: checks of D (the stroke tolerance, a continuous swing) and its API around it.
        self.hydraulic = HydraulicModel(g.family, check=False)
        # Where each pin of PINS is among the family kernel's monitored points (one state's pins).
        points = self.hydraulic.monitored_points.names
        self._pin_rows = np.array([points.index(pin) for pin in PINS.values()])
        self._check_assembly()
        self.hydraulic.check()  # the family's own checks too, after the excavator's named ones
        #: The IK's constants (:class:`excavator_kinematics.core.inverse.Constants`).
        self.ik_constants = inverse.Constants.of(self)
        # The compiled path stays the excavator's own kernel (state_kernel, packed from the folded
        # linkages), not the family's generic one (manipulator_kinematics.hydraulic.kernel, which
        # runs this machine's program): that one is 2x slower on one call and 3.5x slower per state
        # in batches (docs/benchmarks.md: 2.5 against 1.2-1.35 us, 1.07 against 0.29 us a state
        # at 10^4), which would lose issue 31's "batch >= today". One numpy core, two kernels: this
        # one is tested against the family's numpy core (the numpy path here) to 1e-12.
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

    def _check_assembly(self) -> None:
        """Refuse, naming the key, a linkage that does not assemble over its whole stroke box the
        way a backhoe's does (on 2001 lengths of each stroke, ends included: each joint depends
        on its own cylinder alone). Every length must close its linkage. Each cylinder must move
        its joint the documented way over its whole stroke (a backhoe's: extending the boom
        cylinder raises the boom, theta2 up; the arm and bucket cylinders curl the arm and the
        bucket in, theta3 and theta4 down; docs/excavator.md), the bucket's four-bar must not be
        crossed (the H-link pin and the side-link pivot on either side of the line from the bucket
        pin to the rod pin) and at the reference state the tip must be in front of the swing axis:
        a wrong assembly branch (an orientation's sign) otherwise loads, e.g. a flipped boom
        cylinder as a boom hanging down behind the machine (theta2 = -164 deg, tip at r = -3.4 m).
        Then each joint's range over its stroke (K keeps its sign: the stroke ends) must lie in the
        chain's limits."""
        samples = np.linspace(self.limits.stroke_min, self.limits.stroke_max, 2001)
        with np.errstate(invalid="ignore"):  # a linkage that does not close: NaN, named below
            plane = self.hydraulic.solve(np.insert(samples, 0, 0.0, axis=1), _CYLINDER_RATES)
        theta, k = plane.theta[:, 1:], plane.theta_dot[:, 1:]  # K's diagonal: the rates of 1 m/s
        open_ = np.isnan(theta)
        if np.any(open_):
            # Each linkage depends on its own cylinder only: the column names the culprit.
            i = int(np.argmax(np.any(open_, axis=0)))
            raise ConfigError(
                f"{FAMILY}.cylinders.{CYLINDERS[i]}: the stroke [{self.limits.stroke_min[i]:g}, "
                f"{self.limits.stroke_max[i]:g}] m cannot be assembled with these pins and links: its "
                f"linkage does not close at {samples[np.argmax(open_[:, i]), i]:.6g} m"
            )
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
        reference = np.concatenate(([0.0], self.limits.reference[1:]))  # in the boom plane (r, z)
        pins = {name: p[[0, 2]] for name, p in self.hydraulic.solve_pins(reference).items()}
        (ex, ey), (hx, hy), (fx, fy) = (
            pins[pin] - pins["bucket_pin"]
            for pin in ("bkt_cyl_rod", "hlink_pin_on_bucket", "ilink_pin_on_arm")
        )
        if (ex * hy - ey * hx) * (ex * fy - ey * fx) >= 0.0:
            raise ConfigError(
                f"{FAMILY}.dyads.{DYADS[3]}.orientation: this branch crosses the bucket linkage (the H-link "
                "pin on the side-link pivot's side of the line bucket pin -> rod pin): flip the sign"
            )
        r = pins["tip"][0]
        if r <= 0.0:
            raise ConfigError(
                f"{FAMILY}.cylinders.boom_cylinder.reference_length: at the reference lengths the bucket tip "
                f"is {-r:.3g} m behind the swing axis (r = {r:.3g} m); a backhoe's tool is in front: "
                "check the pins"
            )
        for i, (joint, (lo, hi)) in enumerate(
            zip(TOPOLOGY["chain"], self.description.joint_limits, strict=True)
        ):
            ends = sorted((float(theta[0, i]), float(theta[-1, i])))
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

    # ------------------------------------------------------------------ the numpy core (eqs. 1-11)
    def _in_blocks(
        self, part: Callable[[HydraulicState], np.ndarray], D: np.ndarray, *motion: Any
    ) -> np.ndarray:
        """``part`` of the family core's state (:meth:`HydraulicModel.solve`) of valid states D
        (..., 4) with their rates and accelerations (D's shape, or None: zero), computed _BLOCK
        states at a time; the result has D's leading axes."""
        flat = [None if x is None else x.reshape(-1, 4) for x in (D, *motion)]
        out = in_blocks(lambda *block: part(self.hydraulic.solve(*block)), *flat, block=_BLOCK)
        return out.reshape(D.shape[:-1] + out.shape[1:])

    def joint_angles(self, lengths: Any) -> np.ndarray:
        """Cylinder lengths [d2, d3, d4] (..., 3) -> [theta2, theta3, theta4] (eqs. 1-2): the family
        core's, the same arithmetic as :meth:`pins` (the URDF's body frames, urdf_joints, are made
        from both and must agree to the bit). One state: the family kernel's once loaded, as
        :meth:`pins` (the forward node's URDF joints per message: 2 ms in numpy)."""
        lengths = _vectors(lengths, 3, "[boom, arm, bucket] lengths")
        self._check_lengths(lengths)
        D = self._at_reference_swing(lengths)
        if D.ndim == 1 and FAMILY_KERNEL.ready is not None:
            return self.hydraulic.state(self.family_state(D), _AT_REST).theta[1:]
        return self._in_blocks(_joints, D)

    def k_entries(self, lengths: Any) -> tuple[np.ndarray, np.ndarray]:
        """dtheta_i/dd_i (the diagonal of K, eq. 7) and d2theta_i/dd_i2 (of K1), for i = 2..4:
        :meth:`state` with every cylinder extending at 1 m/s (each joint turns with its own cylinder
        alone, eqs. 1-2: theta_dot is K's diagonal, theta_ddot K1's), so the compiled kernel once
        loaded (the IMU state node's rates, per message), else the family core."""
        lengths = _vectors(lengths, 3, "[boom, arm, bucket] lengths")
        self._check_lengths(lengths)
        state = self.state(self._at_reference_swing(lengths), _CYLINDER_RATES)
        return state.theta_dot[..., 1:], state.theta_ddot[..., 1:]

    def family_state(self, D: Any) -> np.ndarray:
        """States D (..., 4) as the family's model (:attr:`hydraulic`) takes them: a continuous
        swing wrapped to (-pi, pi], a length a round-off past a stroke end (within STROKE_TOLERANCE,
        which this model accepts and the family's refuses) taken at the end; one farther out
        stays, for the family's model to refuse naming it."""
        D = np.array(D, dtype=float)
        if self.limits.continuous_swing:
            D[..., 0] = wrap_swing(D[..., 0])
        at_end = np.clip(D, self.hydraulic.lower, self.hydraulic.upper)
        return np.where(np.abs(at_end - D) <= STROKE_TOLERANCE, at_end, D)

    def _at_reference_swing(self, lengths: np.ndarray) -> np.ndarray:
        """D of cylinder lengths (..., 3) at the reference swing (the joints do not depend on it)."""
        return np.concatenate(
            (np.full(lengths.shape[:-1] + (1,), self.limits.reference[0]), lengths), axis=-1
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
        return self._in_blocks(_pose, self.validate(D))

    def open_chain_pose(self, theta: Any) -> np.ndarray:
        """Q = [x, y, z, alpha] from the open-chain joints theta1..theta4 (eq. 3), no limits."""
        return self.hydraulic.open_chain_pose(_vectors(theta, 4, "theta = [theta1, theta2, theta3, theta4]"))

    def pins(self, D: Any) -> dict[str, np.ndarray]:
        """Every pin (and the tip) in the base frame, shape (..., 3), for drawing and checking:
        the family core's pins under the excavator's names (``machine_file.PINS``; the H-link pin
        under both of its names is one array). One state: the family kernel's once loaded (its
        monitored points hold every pin; about 30 us with the checks, where the numpy core takes
        2 ms), the same arithmetic as :meth:`joint_angles` of one state."""
        D = self.validate(D)
        if D.ndim == 1 and FAMILY_KERNEL.ready is not None:
            positions = self.hydraulic.monitored_motion(self.family_state(D), _AT_REST)[1][self._pin_rows]
            return dict(zip(PINS, positions, strict=True))
        pins = self.hydraulic.solve_pins(D)
        return {name: pins[pin] for name, pin in PINS.items()}

    def j0(self, theta: Any) -> np.ndarray:
        """J0(theta) of eq. 5: Qdot = J0 thetadot, rows x, y, z, alpha; columns theta1..theta4
        (eq. 4's columns, the family's closed form)."""
        return self.hydraulic.j0(_vectors(theta, 4, "theta = [theta1, theta2, theta3, theta4]"))

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
        return self._in_blocks(_k, self.validate(D))

    def jc0(self, D: Any) -> np.ndarray:
        """JC0 = J0 K (eq. 8): Qdot = JC0 Ddot."""
        D = np.asarray(D, dtype=float)
        if D.shape == (4,) and (jc0 := self._compiled("jc0", np.empty((4, 4)), D)) is not None:
            return jc0
        return self._in_blocks(_jc0, self.validate(D))

    # ------------------------------------------------------------------ full state (eqs. 3-11)
    def state(self, D: Any, D_dot: Any, D_ddot: Any = None) -> BucketState:
        """Bucket pose, velocity (eq. 8) and acceleration (eqs. 10-11) from cylinder states.

        The acceleration is Qddot = J0 thetaddot + Jdot0 thetadot with thetaddot = K Dddot +
        K1 Ddot^2, i.e. JC0 Dddot plus the velocity-product terms of eq. 11 (see
        :meth:`acceleration_matrices` for the paper's JC1_0 / JC2_0 split of those terms).
        """
        if type(D) is not np.ndarray:
            D = np.asarray(D, dtype=float)
        if (kernel := KERNEL.ready or KERNEL.get()) is not None:
            # The single call (a 1 kHz node calls it per message) and a batch (N, 4), each one
            # call of the kernel into a new table (the caller keeps the views), the arguments as
            # given: the kernel checks shapes and values; the numpy path below raises the error for
            # what it refuses. Written out (no _compiled, no asarray of an array): each Python step
            # costs 0.03-0.2 us of a 1.7 us call, and a batch of one costs what one call does
            # (issue #32).
            try:
                if D.ndim == 1:
                    rows = np.empty((10, 4))
                    given = _NO_ACCELERATION if D_ddot is None else D_ddot
                    if kernel.state(self.packed, D, D_dot, given, rows):
                        return BucketState(rows)
                else:  # a batch (N, 4); other shapes raise TypeError in the kernel
                    rows = np.empty(_ROWS_OF_ONE if len(D) == 1 else (10, len(D), 4))
                    given = _NO_ACCELERATIONS if D_ddot is None else D_ddot
                    if kernel.states(self.packed, D, D_dot, given, rows):
                        return BucketState(rows)
            except TypeError:  # arguments of types the kernel does not take (_warm)
                if (converted := self._state_of_arrays(kernel, D, D_dot, D_ddot)) is not None:
                    return BucketState(converted)
        D = self.validate(D)
        rates = _finite(D_dot, D.shape, "D_dot")
        accelerations = None if D_ddot is None else _finite(D_ddot, D.shape, "D_ddot")
        return BucketState(np.moveaxis(self._in_blocks(_state_rows, D, rates, accelerations), -2, 0))

    def _state_of_arrays(
        self, kernel: ModuleType, D: np.ndarray, D_dot: Any, D_ddot: Any
    ) -> np.ndarray | None:
        """:meth:`state`'s kernel call once more with D, the rates and the accelerations as arrays
        of floats (lists, integers), rates (4,) for every state of a batch as one row; None where
        the kernel still refuses them."""
        D, rates = np.asarray(D, dtype=float), np.asarray(D_dot, dtype=float)
        given = np.zeros(4) if D_ddot is None else np.asarray(D_ddot, dtype=float)
        try:
            if D.ndim == 1:
                rows = np.empty((10, 4))
                return rows if kernel.state(self.packed, D, rates, given, rows) else None
            if D.ndim == 2:
                rows = np.empty((10, len(D), 4))
                rates, given = np.atleast_2d(rates), np.atleast_2d(given)
                return rows if kernel.states(self.packed, D, rates, given, rows) else None
        except TypeError:
            pass
        return None

    def acceleration_matrices(self, D: Any) -> tuple[np.ndarray, np.ndarray]:
        """JC1_0 (..., 4, 4) and JC2_0 (..., 4, 6) of eq. 11.

        Qddot = JC0 Dddot + JC1_0 Ddot^2 + JC2_0 DDdot with Ddot^2 = the squared rates and
        DDdot = [d1 d2, d1 d3, d1 d4, d2 d3, d2 d4, d3 d4] (products of the rates of D).
        Without Dddot, Qddot (eq. 10, the family core's) is the quadratic form Ddot^T H Ddot of
        H = d2Q/dD2: along e_i it is H_ii, JC1_0's column i; along e_i + e_j it adds 2 H_ij,
        JC2_0's column of the pair (i, j).
        """
        D = self.validate(D)
        along = np.broadcast_to(D[..., None, :], D.shape[:-1] + _PROBES.shape)
        Q_ddot = self.hydraulic.solve(along, _PROBES).Q_ddot  # (..., 10, 4): per probe
        i, j = _PAIRS.T
        jc2 = Q_ddot[..., 4:, :] - Q_ddot[..., i, :] - Q_ddot[..., j, :]
        return Q_ddot[..., :4, :].swapaxes(-1, -2), jc2.swapaxes(-1, -2)

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


def _pose(state: HydraulicState) -> np.ndarray:
    return state.Q


def _joints(state: HydraulicState) -> np.ndarray:
    return state.theta[..., 1:]


def _k(state: HydraulicState) -> np.ndarray:
    return state.k


def _jc0(state: HydraulicState) -> np.ndarray:
    return state.jc0


def _state_rows(state: HydraulicState) -> np.ndarray:
    """The rows of a BucketState (..., 10, 4): theta, theta_dot, theta_ddot, Q, Q_dot, Q_ddot,
    then JC0's rows."""
    fields = tuple(state)
    return np.concatenate((np.stack(fields[:6], axis=-2), fields[6]), axis=-2)


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
