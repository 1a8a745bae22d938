"""Palletizing robot ABB IRB460 (Hu, paper 004): D-H chain, closed-form IK, axis angles.

numpy only (no rclpy). SI units; REP 103 base frame (x forward, y left, z up) on the floor under
axis 1. Four actuated axes, five D-H joints: theta1 slew, theta2 lower arm, theta3 upper arm,
theta4 passive (the auxiliary parallelograms keep the flange horizontal), theta5 flange.

Modified (Craig) D-H, the paper's eq. (1) rows (alpha_{i-1}, a_{i-1}, d_i, theta_i)::

    1:   0      0   d1  theta1
    2: -90 deg  a1  0   theta2
    3:   0      a2  0   theta3
    4:   0      a3  0   theta4 = -(theta2 + theta3)   (coupling row [0, -1, -1, 0])
    5: -90 deg  a4  0   theta5
    tool: d6 along z5 (z5 points down): the TCP, frame {6}

The passive joint is a row of the shared chain's coupling matrix (v = C q with
q = [theta1, theta2, theta3, theta5]), so the FK and Jacobian are the shared chain's.
At the home pose P0 (lower arm vertical, upper arm horizontal) theta = (0, -90, 90, 0) deg and the
TCP is at (a1 + a3 + a4, 0, d1 + a2 - d6); eq. (2) then gives the flange yaw theta1 - theta5 and a
TCP frame x6 = (cos yaw, sin yaw, 0), z6 = (0, 0, -1).

Inverse kinematics, eqs. (3)-(8), every solution:

* eq. (3): theta1 = atan2(py, px) ("front"), and theta1 + 180 deg ("back", the arm reaching over
  axis 1: geometrically valid, outside the catalogue's A2 range for almost every target); with
  the TCP on axis 1 theta1 is free and taken as 0;
* eq. (4): theta5 = theta1 - atan2(ny, nx); the flange range exceeds 360 deg, so both turns
  (|theta5| <= 180 deg, and the one 360 deg away: suffix ``_outer``) are candidates;
* eqs. (5)-(6): with the wrist point (frame {4}) at X = rho - a1 - a4, Z = pz + d6 - d1 from axis 2
  (rho = px cos theta1 + py sin theta1 = +-r, r the TCP's distance from axis 1),
  c3 = (X^2 + Z^2 - a2^2 - a3^2) / (2 a2 a3), theta3 = atan2(+-sqrt(1 - c3^2), c3): ``elbow_up``
  (0 <= theta3 <= 180 deg, the home pose's branch: the elbow above the line from axis 2 to the
  wrist) and ``elbow_down``;
* eqs. (7)-(8): (a3 s3) c2 + (a3 c3 + a2) s2 = l2 with l2 = d1 - d6 - pz, solved as
  a cos + b sin = c: theta2 = atan2(b, a) + atan2(+-sqrt(a^2 + b^2 - c^2), c). Here
  a^2 + b^2 - c^2 = X^2, and the horizontal equation b c2 - a s2 = X fixes the sign: the root is
  -X, so theta2 = atan2(b, a) + atan2(-X, l2) with no spurious solution.

That is 2 x 2 x 2 = 8 candidates (:data:`BRANCHES`, preference order). Selection rule: the home
elbow branch (``front_elbow_up``, either flange turn) if one of its candidates is inside the
axis limits and away from a singularity, else any candidate that is; among those the one closest
to the seed (squared distance in the returned angles), without a seed the first in branch order.

Axis angles (what the motors see), eqs. (9)-(11); every one 0 at home, A2 > 0 lower arm tilted
forward, A3 > 0 upper arm tipped down:

* single parallelogram, eq. (9): A = theta - theta_home: A1 = theta1, A2 = theta2 + 90 deg,
  A3 = theta3 - 90 deg (upper arm against the lower arm), A6 = theta5;
* double parallelogram, eqs. (10)-(11): the main parallelogram drives the upper arm from the base,
  so A3 = theta2 + theta3 (upper arm against the base, = A2 + A3 of the single robot); A1, A2,
  A6 as above.

The flange is called axis 6 as in ABB's catalogue (the paper's "axis 5"). A configuration is
singular when |sin theta3| is below ``singular_elbow`` (arm stretched or folded) or the TCP is
within ``singular_radius`` of axis 1 (theta1 undetermined): the 4x4 Jacobian of (x, y, z, yaw)
has det = -r a2 a3 sin(theta3).

The IK is plain numpy on (..., 8, 4) candidate arrays (:meth:`Palletizer._closed_form`: eqs.
(3)-(8) on every branch at once; statuses by the shared
:func:`~manipulator_kinematics.model.limit_status` on the axis angles plus this machine's
SINGULAR/UNREACHABLE/INVALID rules; the shared :func:`~manipulator_kinematics.model.select`), one
target being a batch of one, large batches in blocks (:func:`manipulator_kinematics.row_blocks.in_blocks`).
The same steps run compiled (:mod:`palletizer_kinematics.ik_kernel`, numba, loaded in the
background by the first call: :func:`compiled_kernel`), for one target and, as a loop, for a batch;
numpy is the reference, a test compares the two. Returned angles A2, A3 and theta2, theta3 lie in
(-pi, pi] (as atan2's), A1 =
theta1 in [-pi, pi], the flange in [-2 pi, 2 pi]. Speed: benchmarks/bench_palletizer_ik.py and
docs/palletizer.md.
"""

from __future__ import annotations

import functools
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
from manipulator_kinematics.planar import wrap_angle
from manipulator_kinematics.row_blocks import in_blocks
from manipulator_kinematics.schema import Names, Number, Numbers, Schema, Text, require, validate
from manipulator_kinematics.serial_chain import JointLimits, SerialChain, revolute, transl
from palletizer_kinematics.statics import MASS_SCHEMA, MassModel

SECTION = "palletizer"
CONFIG_FILE = "irb460.yaml"
VARIANTS = ("single", "double")
#: solve_ik modes: ``axis`` returns the configured variant's axis angles, ``dh`` the D-H angles.
MODES = ("axis", "dh")
DH_NAMES = ("theta1", "theta2", "theta3", "theta5")
ARM_BRANCHES = ("front_elbow_up", "front_elbow_down", "back_elbow_up", "back_elbow_down")
#: The 8 IK candidates in preference order: arm branch, then flange turn (inner first).
BRANCHES = tuple(f"{arm}{turn}" for arm in ARM_BRANCHES for turn in ("", "_outer"))
HOME_BRANCH = ARM_BRANCHES[0]
#: D-H angles [theta1, theta2, theta3, theta5] of the home pose P0.
HOME_DH = np.array([0.0, -math.pi / 2, math.pi / 2, 0.0])
#: theta4 = -(theta2 + theta3): the D-H rows' variables v = C q, q = [theta1, theta2, theta3, theta5].
COUPLING = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, -1, -1, 0], [0, 0, 0, 1]], dtype=float)
#: A = M (theta - theta_home) per variant (eqs. 9-11); M is unimodular, so its inverse is exact.
AXIS_MATRIX = {
    "single": np.eye(4),
    "double": np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 1, 1, 0], [0, 0, 0, 1]], dtype=float),
}
#: Values this close (rad) outside a limit count as on it.
LIMIT_TOL = 1e-10
#: A target's rotation part is a rotation when R^T R = I to this, entry by entry, and det R > 0 ...
ROTATION_TOL = 1e-6
#: ... and its bottom row is [0, 0, 0, 1] to this (sum of the deviations).
BOTTOM_TOL = 1e-12
#: |c3| of eq. (5) up to 1 + this is reachable (the stretched or folded arm, to round-off).
REACH_TOL = 1e-12
_ALL_BRANCHES = np.ones(len(BRANCHES), dtype=bool)
#: The home elbow branch's candidates (either flange turn).
_HOME = np.array([b.startswith(HOME_BRANCH) for b in BRANCHES])
#: Eq. (6)'s sign of sin theta3: elbow up, elbow down.
_ELBOW = np.array([1.0, -1.0])
_NO_SEED = np.zeros(4)
_NO_SEEDS = _NO_SEED.reshape(1, 4)  # a batch's (ik_kernel.solve_batch reads its row, never uses it)
_ONE = ((1, 8, 4), (1, 8), (1, 3))  # _solve_many's shapes for one target
_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_ANGLE = Number(min=-2 * math.tau, max=2 * math.tau, unit="rad")

#: The ``palletizer:`` section of a parameters file (manipulator_kinematics.schema).
SCHEMA: Schema = {
    "name": Text(empty=False, default="palletizer", doc="the machine's name: the robot name of its URDF"),
    "variant": Text(choices=VARIANTS, doc="single or double parallelogram: which axis angles the motors see"),
    "a1": Number(min=0.0, max=10.0, unit="m", doc="D-H a1: axis 1 to axis 2, horizontal"),
    "a2": Number(min=0.0, max=10.0, unit="m", exclusive_min=True, doc="D-H a2: lower arm, axis 2 to 3"),
    "a3": Number(min=0.0, max=10.0, unit="m", exclusive_min=True, doc="D-H a3: upper arm, axis 3 to wrist"),
    "a4": Number(min=0.0, max=10.0, unit="m", doc="D-H a4: wrist pin to flange axis, horizontal"),
    "d1": Number(min=0.0, max=10.0, unit="m", doc="D-H d1: floor to axis 2 height"),
    "d6": Number(min=0.0, max=10.0, unit="m", doc="D-H d6: wrist pin height above the TCP"),
    "joint_names": Names(4, doc="names of axes 1, 2, 3 and the flange (axis 6), in that order"),
    "joint_min": Numbers(4, item=_ANGLE, doc="lower axis limits (rad), order of joint_names"),
    "joint_max": Numbers(4, item=_ANGLE, doc="upper axis limits (rad), order of joint_names"),
    "singular_elbow": Number(min=0.0, max=1.0, doc="singular below this |sin theta3| (arm stretched/folded)"),
    "singular_radius": Number(min=0.0, max=10.0, unit="m", doc="singular within this distance of axis 1"),
    "tilt_tolerance": Number(
        min=0.0,
        max=0.1,
        unit="rad",
        doc="largest tilt of a target's tool z axis from straight down still taken",
    ),
    "masses": MASS_SCHEMA,
}


@dataclass(frozen=True)
class Geometry:
    """The D-H lengths (m)."""

    a1: float
    a2: float
    a3: float
    a4: float
    d1: float
    d6: float


def axis_from_dh(theta: ArrayLike, variant: str) -> np.ndarray:
    """Axis angles [A1, A2, A3, A6] (..., 4) of D-H angles [theta1, theta2, theta3, theta5], eqs. (9)-(11).

    Not wrapped: A is affine in theta. A = M (theta - theta_home) (:data:`AXIS_MATRIX`) written
    out: a matrix product goes through BLAS, whose threads cost milliseconds per call on a loaded
    machine (measured in the IK's batches).
    """
    axis = np.asarray(theta, dtype=float) - HOME_DH  # eq. (9)
    if _variant(variant) == "double":
        axis[..., 2] += axis[..., 1]  # eqs. (10)-(11): A3 = theta2 + theta3, against the base
    return axis


def dh_from_axis(axis: ArrayLike, variant: str) -> np.ndarray:
    """D-H angles [theta1, theta2, theta3, theta5] (..., 4) of axis angles: eqs. (9)-(11) inverted."""
    return np.asarray(axis, dtype=float) @ np.linalg.inv(AXIS_MATRIX[_variant(variant)]).T + HOME_DH


def _variant(variant: str) -> str:
    if variant not in AXIS_MATRIX:
        raise ValueError(f"unknown variant {variant!r}; known: {', '.join(VARIANTS)}")
    return variant


def _principal(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to (-pi, pi], the range of atan2 (planar.wrap_angle's [-pi, pi) mirrored)."""
    return math.pi - (math.pi - angle) % math.tau


def _flange_turns(angles: np.ndarray) -> np.ndarray:
    """The 8 candidates (..., 8, 4) of the 4 arm configurations (..., 4, 4): each on its inner
    flange turn and, next, on the one 360 deg away (``_outer``; the flange range exceeds 360 deg)."""
    candidates = np.repeat(angles, 2, axis=-2)
    inner = candidates[..., 1::2, 3]
    candidates[..., 1::2, 3] = np.where(inner < 0.0, inner + math.tau, inner - math.tau)
    return candidates


def _is_pose(target: np.ndarray) -> np.ndarray:
    """(...,) True where the rotation part of poses (..., 4, 4) is a rotation (its columns n, o, a
    orthonormal: R^T R = I to ROTATION_TOL entry by entry; det R = n . (o x a) > 0) and the bottom
    row is [0, 0, 0, 1] (to BOTTOM_TOL, the sum of the deviations)."""
    n, o, a = target[..., :3, 0], target[..., :3, 1], target[..., :3, 2]

    def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.einsum("...i,...i->...", u, v)

    gram = np.stack(
        [dot(n, n) - 1.0, dot(o, o) - 1.0, dot(a, a) - 1.0, dot(n, o), dot(n, a), dot(o, a)], axis=-1
    )
    bottom = np.abs(target[..., 3, :] - _BOTTOM_ROW).sum(axis=-1)
    return (np.abs(gram) < ROTATION_TOL).all(axis=-1) & (dot(n, np.cross(o, a)) > 0.0) & (bottom < BOTTOM_TOL)


def _warm(ik_kernel: ModuleType, packed: np.ndarray) -> None:
    """Run the kernel once (numba loads it from its cache or compiles it)."""
    q, status, extra = np.empty((8, 4)), np.empty(8, dtype=np.int8), np.empty(3)
    home = np.eye(4)
    home[:3, 3] = 1.5, 0.0, 1.4
    home[1:3, 1:3] = -home[1:3, 1:3]  # z down
    ik_kernel.solve(packed, home.reshape(16), _NO_SEED, False, _ALL_BRANCHES, True, True, q, status, extra)
    one = np.ones(1, dtype=bool)
    ik_kernel.solve_batch(
        packed,
        home.reshape(1, 16),
        np.zeros((1, 4)),
        False,
        _ALL_BRANCHES,
        True,
        True,
        q[None],
        status[None],
        extra[None],
        np.empty(1, dtype=np.intp),
        one,
        one.copy(),
    )


#: The single-target kernel (:mod:`palletizer_kinematics.ik_kernel`), see manipulator_kinematics.compiled.
KERNEL = Kernel("palletizer_kinematics.ik_kernel", _warm)


def compiled_kernel(model: Palletizer, wait: bool = False) -> ModuleType | None:
    """The compiled kernel module if ready, else None (:class:`manipulator_kinematics.compiled.Kernel`:
    the first IK call starts loading it, calls take the numpy path meanwhile, the same
    results within 1e-12). ``wait``: load it now (tests, benchmarks)."""
    return KERNEL.get(model._packed, wait=wait)


class Palletizer:
    """The robot: geometry, variant, axis limits, singularity thresholds, mass model.

    Implements :class:`manipulator_kinematics.model.SerialModel` with the configured variant's
    AXIS angles as its joints (``joint_names``, default axis_1, axis_2, axis_3, axis_6): they are
    what the motors, the controller's joint states and the catalogue's limits use. The D-H angles
    are available through the ``*_dh`` methods, :func:`axis_from_dh`/:func:`dh_from_axis` and the
    IK mode ``dh``.
    """

    ik_branches = BRANCHES
    ik_modes = MODES

    def __init__(
        self,
        geometry: Geometry,
        variant: str,
        limits: JointLimits,
        *,
        masses: MassModel,
        singular_elbow: float = 0.01,
        singular_radius: float = 0.01,
        tilt_tolerance: float = 1e-6,
        name: str = "palletizer",
    ) -> None:
        self.name = name
        self.geometry = geometry
        self.variant = _variant(variant)
        if len(limits.names) != 4:
            raise ValueError("the palletizer has four axes: 1, 2, 3 and the flange")
        self._limits = limits
        self.masses = masses
        self.singular_elbow = float(singular_elbow)
        self.singular_radius = float(singular_radius)
        self.tilt_tolerance = float(tilt_tolerance)
        self._to_dh = np.linalg.inv(AXIS_MATRIX[self.variant])
        self._lean_min = math.cos(self.tilt_tolerance)  # cos of the largest tilt taken
        # The compiled kernel's constants (palletizer_kinematics.ik_kernel), in its order.
        self._packed = np.array(
            [
                geometry.a1,
                geometry.a2,
                geometry.a3,
                geometry.a4,
                geometry.d1,
                geometry.d6,
                *(limits.lower - LIMIT_TOL),
                *(limits.upper + LIMIT_TOL),
                self.singular_elbow,
                self.singular_radius,
                self._lean_min,
                float(self.variant == "double"),
                ROTATION_TOL,
                BOTTOM_TOL,
                REACH_TOL,
                TIE_TOLERANCE,
            ],
            dtype=float,
        )

    # ---- construction -------------------------------------------------------------------------
    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], prefix: str = SECTION) -> Palletizer:
        """From the nested ``palletizer:`` section; ConfigError names a bad key."""
        p = validate(params, SCHEMA, prefix)
        names, lower, upper = p["joint_names"], p["joint_min"], p["joint_max"]
        for i in range(4):
            require(
                lower[i] < upper[i],
                f"{prefix}.joint_min[{i}]",
                f"{lower[i]} must be below {prefix}.joint_max[{i}] = {upper[i]} ({names[i]})",
            )
        # The IK returns A1..A3 in [-pi, pi] and the flange in [-2 pi, 2 pi]: wider limits would
        # hide solutions.
        for i in range(3):
            for key, value in (("joint_min", lower[i]), ("joint_max", upper[i])):
                require(
                    abs(value) <= math.pi,
                    f"{prefix}.{key}[{i}]",
                    f"{value} rad ({names[i]}) is outside [-pi, pi]",
                )
        for key, value in (("joint_min", lower[3]), ("joint_max", upper[3])):
            require(
                abs(value) <= math.tau,
                f"{prefix}.{key}[3]",
                f"{value} rad ({names[3]}) is outside [-2 pi, 2 pi]",
            )
        geometry = Geometry(*(p[k] for k in ("a1", "a2", "a3", "a4", "d1", "d6")))
        limits = JointLimits(tuple(names), np.array(lower), np.array(upper))
        return cls(
            geometry,
            p["variant"],
            limits,
            masses=MassModel.from_parameters(p["masses"]),
            singular_elbow=p["singular_elbow"],
            singular_radius=p["singular_radius"],
            tilt_tolerance=p["tilt_tolerance"],
            name=p["name"],
        )

    @classmethod
    def default(cls, variant: str | None = None) -> Palletizer:
        """The IRB460 of ``config/irb460.yaml`` (optionally as the other variant)."""
        params = dict(load_parameters(config_path(CONFIG_FILE))[SECTION])
        if variant is not None:
            params["variant"] = variant
        return cls.from_parameters(params)

    def with_variant(self, variant: str) -> Palletizer:
        """The same machine with the other parallelogram type (same limits, same masses)."""
        return Palletizer(
            self.geometry,
            variant,
            self._limits,
            masses=self.masses,
            singular_elbow=self.singular_elbow,
            singular_radius=self.singular_radius,
            tilt_tolerance=self.tilt_tolerance,
        )

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._limits.names

    @property
    def limits(self) -> JointLimits:
        """Axis limits, in the configured variant's axis angles."""
        return self._limits

    def joint_names_for(self, mode: str | None) -> tuple[str, ...]:
        """Names of the values :meth:`solve_ik` returns in ``mode``."""
        return DH_NAMES if self._mode(mode) == "dh" else self.joint_names

    @cached_property
    def chain(self) -> SerialChain:
        """The 5-row modified D-H chain of eq. (1), q = [theta1, theta2, theta3, theta5]."""
        g = self.geometry
        rows = [
            revolute(d=g.d1),
            revolute(a=g.a1, alpha=-math.pi / 2),
            revolute(a=g.a2),
            revolute(a=g.a3),
            revolute(a=g.a4, alpha=-math.pi / 2),
        ]
        return SerialChain(rows, modified=True, tool=transl(0.0, 0.0, g.d6), coupling=COUPLING)

    # ---- axis angles ----------------------------------------------------------------------------
    def axis_angles(self, theta: ArrayLike) -> np.ndarray:
        """The configured variant's axis angles (..., 4) of D-H angles (..., 4)."""
        return axis_from_dh(theta, self.variant)

    def dh_angles(self, axis: ArrayLike) -> np.ndarray:
        """D-H angles (..., 4) of the configured variant's axis angles (..., 4)."""
        return np.asarray(axis, dtype=float) @ self._to_dh.T + HOME_DH

    # ---- forward kinematics (SerialModel: axis angles) -----------------------------------------
    def fkine(self, q: ArrayLike) -> np.ndarray:
        """TCP pose (..., 4, 4) of axis angles (..., 4)."""
        return self.chain.fkine(self.dh_angles(q))

    def frames(self, q: ArrayLike) -> np.ndarray:
        """(..., 7, 4, 4): base, frames {1}..{5}, TCP {6}."""
        frames = self.chain.fkine(self.dh_angles(q), all_frames=True)
        return np.concatenate([frames, (frames[..., -1, :, :] @ self.chain.tool)[..., None, :, :]], axis=-3)

    def jacob0(self, q: ArrayLike) -> np.ndarray:
        """Geometric Jacobian (..., 6, 4) of the TCP with respect to the axis angles: J_theta dtheta/dA."""
        return self.chain.jacob0(self.dh_angles(q)) @ self._to_dh

    def fkine_dh(self, theta: ArrayLike) -> np.ndarray:
        """TCP pose (..., 4, 4) of D-H angles [theta1, theta2, theta3, theta5] (eq. 2)."""
        return self.chain.fkine(theta)

    def jacob0_dh(self, theta: ArrayLike) -> np.ndarray:
        """Geometric Jacobian (..., 6, 4) with respect to the D-H angles."""
        return self.chain.jacob0(theta)

    def singular(self, theta: ArrayLike) -> np.ndarray:
        """(...,) True where D-H angles (..., 4) are within the singularity thresholds (module docstring)."""
        theta = np.asarray(theta, dtype=float)
        elbow = np.abs(np.sin(theta[..., 2])) < self.singular_elbow
        radius = np.abs(self._radius(theta)) < self.singular_radius
        return elbow | radius

    def _radius(self, theta: np.ndarray) -> np.ndarray:
        """Signed horizontal TCP distance from axis 1 along the arm's plane."""
        g = self.geometry
        return g.a1 + g.a2 * np.cos(theta[..., 1]) + g.a3 * np.cos(theta[..., 1] + theta[..., 2]) + g.a4

    # ---- inverse kinematics ---------------------------------------------------------------------
    def ik_dh(self, position: ArrayLike, yaw: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Every D-H solution for TCP positions (..., 3) and flange yaws (...,), eqs. (3)-(8).

        Returns ``theta`` (..., 8, 4) in :data:`BRANCHES` order (theta1..theta3 in [-pi, pi],
        theta5 in [-2 pi, 2 pi]; NaN where the arm cannot reach) and ``c3`` (..., 2) of eq. (5)
        for the front and back arm (|c3| > 1: out of reach).
        """
        p = np.asarray(position, dtype=float)
        yaw = np.asarray(yaw, dtype=float)
        shape = np.broadcast_shapes(p.shape[:-1], yaw.shape)
        with np.errstate(invalid="ignore", over="ignore"):  # junk (non-finite inputs) gives NaN
            theta, c3, _, _ = self._closed_form(np.broadcast_to(p, shape + (3,)), np.broadcast_to(yaw, shape))
        return _flange_turns(theta), c3

    def _closed_form(self, p: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, ...]:
        """Eqs. (3)-(8) for TCP positions p (..., 3) and flange yaws (...,): theta (..., 4, 4) of
        the arm configurations (front/back x elbow up/down) on the inner flange turn (NaN where
        the arm cannot reach; :func:`_flange_turns` gives the 8 candidates), c3 (..., 2) of eq. (5)
        and |sin theta3| (..., 2) for the front and back arm, and r (...,) the TCP's distance from
        axis 1.
        """
        g = self.geometry
        px, py, pz = p[..., 0], p[..., 1], p[..., 2]
        # eq. (3): theta1 = atan2(py, px), the back arm 180 deg further; on axis 1 (r = 0) theta1
        # is free: 0 by rule.
        r = np.hypot(px, py)
        front = np.where(r == 0.0, 0.0, np.arctan2(py, px))
        theta1 = np.stack([front, front - np.copysign(math.pi, front)], axis=-1)
        # eq. (5): the wrist point (frame {4}) at X = rho - a1 - a4, Z = pz + d6 - d1 from axis 2,
        # rho = +-r the signed radius along the arm's plane.
        X = np.stack([r, -r], axis=-1) - g.a1 - g.a4
        l2 = (g.d1 - g.d6 - pz)[..., None]  # eq. (7)'s right-hand side, = -Z
        c3 = (X * X + l2 * l2 - g.a2 * g.a2 - g.a3 * g.a3) / (2.0 * g.a2 * g.a3)
        cos3 = np.clip(c3, -1.0, 1.0)
        sin3 = np.sqrt(1.0 - cos3 * cos3)
        # eq. (6): theta3 = atan2(+-sqrt(1 - c3^2), c3), elbow up then down: (..., arm, elbow)
        s3 = sin3[..., None] * _ELBOW
        theta3 = np.arctan2(s3, cos3[..., None])
        # eqs. (7)-(8): (a3 s3) c2 + (a3 c3 + a2) s2 = l2 as a c2 + b s2 = l2, whose root with
        # the horizontal equation b c2 - a s2 = X is theta2 = atan2(b, a) + atan2(-X, l2): one
        # atan2 of the product (a + i b)(l2 - i X), in (-pi, pi].
        a, b = g.a3 * s3, g.a3 * cos3[..., None] + g.a2
        X, l2 = X[..., None], l2[..., None]
        theta2 = np.arctan2(b * l2 - a * X, a * l2 + b * X)
        # eq. (4): theta5 = theta1 - yaw (the inner turn, in (-pi, pi]).
        theta5 = _principal(theta1 - yaw[..., None])
        theta = np.empty(c3.shape + (2, 4))  # (..., arm, elbow, angle)
        theta[..., 0] = theta1[..., None]
        theta[..., 1] = theta2
        theta[..., 2] = theta3
        theta[..., 3] = theta5[..., None]
        theta[~(np.abs(c3) <= 1.0 + REACH_TOL)] = np.nan
        return theta.reshape(c3.shape[:-1] + (4, 4)), c3, sin3, r

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
        """Every candidate for TCP target poses (..., 4, 4) (module docstring: solutions, rule).

        ``use_orientation``: the yaw comes from the target's x axis (its z axis must point down
        within ``tilt_tolerance``); otherwise the seed's flange yaw A1 - A6 is kept, or the home
        yaw 0 without a seed. ``mode`` ``axis`` (default: the configured variant's axis angles)
        or ``dh``; ``seed`` (4,) or (..., 4) in the mode's angles; ``branch`` one of
        :data:`BRANCHES` or of :data:`ARM_BRANCHES` (either flange turn). One target (4, 4) runs
        the compiled kernel (:func:`compiled_kernel`), a batch its loop over the targets (0.45 us
        per target, 1.6-2x numpy's), unless not ``compiled``; until the kernel is loaded, the
        numpy code (:meth:`_solve_block`), the reference.
        """
        mode = self._mode(mode)
        allowed = self._allowed(branch)
        target = np.asarray(target, dtype=float)
        if target.ndim < 2 or target.shape[-2:] != (4, 4):
            raise RequestError(f"targets must have shape (..., 4, 4), got {target.shape}", IKStatus.INVALID)
        shape = target.shape[:-2]
        seeds: np.ndarray | None = None
        if seed is not None:
            seed = seeds = np.asarray(seed, dtype=float)
            if seed.ndim == 0 or seed.shape[-1] != 4 or not np.all(np.isfinite(seed)):
                raise RequestError(f"seed must be 4 finite angles, got {seed.tolist()}", IKStatus.INVALID)
            if seed.shape != shape + (4,):
                seed = np.broadcast_to(seed, shape + (4,))
                # One seed for a batch: the kernel's loop reads its one row for every target.
                seeds = seeds.reshape(1, 4) if seeds.shape == (4,) else seed
        kernel = compiled_kernel(self) if compiled else None
        if kernel is not None and shape == ():
            q, status, selected, tie, home, lean, c3 = self._solve_one(
                kernel, target, seed, allowed, use_orientation, mode
            )
        elif kernel is not None:
            seeds = None if seeds is None else seeds.reshape(-1, 4)
            flat = self._solve_many(kernel, target.reshape(-1, 16), seeds, allowed, use_orientation, mode)
            if len(shape) == 1:  # (N,): the kernel's outputs as they are
                q, status, selected, tie, home, lean, c3 = flat
            else:
                q, status, selected, tie, home, lean, c3 = (
                    out.reshape(shape + out.shape[1:]) for out in flat
                )
        else:
            block = functools.partial(
                self._solve_block, allowed=allowed, use_orientation=use_orientation, mode=mode
            )
            flat = in_blocks(block, target.reshape(-1, 4, 4), None if seed is None else seed.reshape(-1, 4))
            q, status, selected, tie, home, lean, c3 = (out.reshape(shape + out.shape[1:]) for out in flat)
        context = {
            "lean": lean,
            "c3": c3,
            "oriented": use_orientation,
            "mode": mode,
            "seeded": seed is not None,
            "branch": branch,
            "home": home,
        }
        return IKSolutions(
            q=q,
            status=status,
            branches=BRANCHES,
            selected=selected,
            tie=tie,
            explain=lambda solutions, index: self._explain(solutions, index, context),
        )

    def _solve_block(
        self,
        target: np.ndarray,
        seed: np.ndarray | None,
        *,
        allowed: np.ndarray,
        use_orientation: bool,
        mode: str,
    ) -> tuple[np.ndarray, ...]:
        """Targets (N, 4, 4), seeds (N, 4) or None: eqs. (3)-(8), the statuses and the selection
        rule (module docstring). Returns q (N, 8, 4) in the ``mode``'s angles (NaN where
        UNREACHABLE or INVALID), status (N, 8), selected (N,), tie (N,), whether the home elbow
        branch was selected (N,), cos(tilt) (N,) and c3 (N, 2) of eq. (5).
        """
        rotation, p = target[:, :3, :3], target[:, :3, 3]
        finite = np.isfinite(target).all(axis=(-2, -1))
        lean = -rotation[:, 2, 2]  # cos of the tool z axis' tilt from straight down
        with np.errstate(invalid="ignore", over="ignore"):  # junk (non-finite targets) gives NaN
            if use_orientation:
                invalid = ~(finite & _is_pose(target))
                blocked = invalid | (lean < self._lean_min)
                yaw = np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0])  # eq. (4)'s atan2(ny, nx)
            else:
                invalid = blocked = ~finite
                yaw = np.zeros(len(target)) if seed is None else seed[:, 0] - seed[:, 3]
            theta, c3, sin3, r = self._closed_form(p, yaw)
        axis = axis_from_dh(theta, self.variant)
        axis[..., 1:3] = _principal(axis[..., 1:3])  # A1 = theta1 is one already
        axis = _flange_turns(axis)  # A6 = theta5
        # Statuses: the shared limit rule on the axis angles; SINGULAR inside the limits within
        # the thresholds (module docstring); UNREACHABLE for a tilted target; INVALID for junk.
        status = limit_status(axis, self._limits, LIMIT_TOL)
        singular = (np.repeat(sin3, 4, axis=-1) < self.singular_elbow) | (r < self.singular_radius)[:, None]
        status[(status == IKStatus.SUCCESS) & singular] = IKStatus.SINGULAR
        status[blocked] = IKStatus.UNREACHABLE
        status[invalid] = IKStatus.INVALID
        # D-H angles of the wrapped axis angles: whole turns from atan2's, so axis_from_dh of an
        # answer gives the axis angles the limits were checked on.
        q = axis if mode == "axis" else dh_from_axis(axis, self.variant)
        q[status >= IKStatus.UNREACHABLE] = np.nan
        # The shared selection rule over the home elbow branch if it has a valid candidate the
        # request allows, else over every allowed candidate.
        home = ((status == IKStatus.SUCCESS) & allowed & _HOME).any(axis=-1)
        choice = allowed & (_HOME | ~home[:, None])
        selected, tie = select(q, np.where(choice, status, IKStatus.UNREACHABLE), seed=seed)
        return q, status, selected, tie, home, lean, c3

    def _solve_one(
        self,
        kernel: ModuleType,
        target: np.ndarray,
        seed: np.ndarray | None,
        allowed: np.ndarray,
        use_orientation: bool,
        mode: str,
    ) -> tuple[np.ndarray, ...]:
        """:meth:`_solve_block`'s outputs for one target (4, 4) through the compiled kernel."""
        q, status, extra = np.empty((8, 4)), np.empty(8, dtype=np.int8), np.empty(3)
        selected, tie, home = kernel.solve(
            self._packed,
            np.ascontiguousarray(target).reshape(16),
            _NO_SEED if seed is None else np.ascontiguousarray(seed),
            seed is not None,
            allowed,
            bool(use_orientation),
            mode == "axis",
            q,
            status,
            extra,
        )
        selection = np.array(selected, dtype=np.intp), np.array(tie), np.array(home)
        return q, status, *selection, extra[0], extra[1:]

    def _solve_many(
        self,
        kernel: ModuleType,
        poses: np.ndarray,
        seeds: np.ndarray | None,
        allowed: np.ndarray,
        use_orientation: bool,
        mode: str,
    ) -> tuple[np.ndarray, ...]:
        """:meth:`_solve_block`'s outputs for targets (N, 16) through the kernel's loop, seeds (N, 4)
        or (1, 4) for every target."""
        n = len(poses)
        # A batch of one's shapes made once: a tuple made per call costs 0.05 us (issue #32).
        shape, candidates, more = _ONE if n == 1 else ((n, 8, 4), (n, 8), (n, 3))
        q, status, extra = np.empty(shape), np.empty(candidates, dtype=np.int8), np.empty(more)
        selected, tie, home = np.empty(n, dtype=np.intp), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        seeded = seeds is not None
        kernel.solve_batch(
            self._packed,
            np.ascontiguousarray(poses),
            np.ascontiguousarray(seeds) if seeded else _NO_SEEDS,
            seeded,
            allowed,
            bool(use_orientation),
            mode == "axis",
            q,
            status,
            extra,
            selected,
            tie,
            home,
        )
        return q, status, selected, tie, home, extra[:, 0], extra[:, 1:]

    def _mode(self, mode: str | None) -> str:
        if mode is None:
            return "axis"
        if mode not in MODES:
            raise RequestError(f"unknown IK mode {mode!r}; known: {', '.join(MODES)}")
        return mode

    @staticmethod
    def _allowed(branch: str | None) -> np.ndarray:
        """(8,) the candidates a requested branch leaves to the selection."""
        if branch is None:
            return _ALL_BRANCHES
        if branch in BRANCHES:
            return np.array([b == branch for b in BRANCHES])
        if branch in ARM_BRANCHES:
            return np.array([b in (branch, f"{branch}_outer") for b in BRANCHES])
        raise RequestError(f"unknown branch {branch!r}; known: {', '.join(ARM_BRANCHES + BRANCHES[1::2])}")

    def _explain(self, solutions: IKSolutions, index: tuple[int, ...], context: dict[str, Any]) -> str:
        chosen = int(solutions.selected[index])
        if chosen >= 0:
            if context["branch"] is not None:
                rule = f"the requested branch {context['branch']}"
            else:
                rule = "the home elbow branch" if context["home"][index] else "the home elbow branch has none"
            seed = "closest to the seed" if context["seeded"] else "no seed: inner flange turn first"
            tie = "; tie: another valid solution is as close to the seed" if solutions.tie[index] else ""
            return f"branch {BRANCHES[chosen]} ({rule}, inside the axis limits, {seed}){tie}"
        outcome = IKStatus(int(solutions.outcome[index]))
        if outcome is IKStatus.INVALID:
            return "target is not finite or its rotation part is not a rotation matrix"
        lean = float(context["lean"][index])
        if context["oriented"] and lean < self._lean_min:
            tilt = math.acos(max(lean, -1.0))
            return (
                f"the flange stays horizontal (tool z axis straight down): the target's z axis is tilted "
                f"{math.degrees(tilt):.6g} deg (tolerance {math.degrees(self.tilt_tolerance):.3g} deg)"
            )
        g = self.geometry
        if outcome is IKStatus.UNREACHABLE:
            c3 = float(context["c3"][index][0])
            where = "beyond the stretched arm" if c3 > 1 else "inside the folded arm"
            return (
                f"no solution: the wrist point is {where} (reach of lower + upper arm: "
                f"{abs(g.a2 - g.a3):.6g} to {g.a2 + g.a3:.6g} m from axis 2)"
            )
        valid_branches = [i for i in range(len(BRANCHES)) if int(solutions.status[index][i]) == outcome]
        parts = []
        for i in valid_branches[:2]:
            axis = solutions.q[index][i]
            if context["mode"] == "dh":
                axis = self.axis_angles(axis)
                axis[:3] = wrap_angle(axis[:3])
            if outcome is IKStatus.JOINT_LIMITS:
                parts.append(f"{BRANCHES[i]}: {describe_limits(axis, self._limits)}")
            else:
                parts.append(f"{BRANCHES[i]}: singular (arm stretched or folded, or the TCP on axis 1)")
        what = "outside the axis limits" if outcome is IKStatus.JOINT_LIMITS else "singular"
        return f"every solution is {what}; " + "; ".join(parts)
