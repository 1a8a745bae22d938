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

Speed (benchmarks/bench_palletizer_ik.py): the IK runs on scalar parts, Python floats for one
target and (N,) arrays for a batch (:func:`evaluate_angle_parts`, one code path), every angle kept as a
(sine, cosine)-like pair until one numpy arctan2 over all of them, so one target and a batch give
the same bits (the math and numpy arctan2 differ in the last bit). numpy on the (8, 4) candidate
arrays of one target would cost several times the arithmetic in per-call overhead. Returned
angles A1..A3 and theta1..theta3 lie in [-pi, pi], the flange in [-2 pi, 2 pi].
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.config import Names, Number, Numbers, Text, require, validate
from manipulator_kinematics.model import (
    IKSolutions,
    IKStatus,
    RequestError,
    describe_limits,
    select_parts,
)
from manipulator_kinematics.params import config_path, load_parameters
from manipulator_kinematics.planar import wrap_angle
from manipulator_kinematics.serial_chain import (
    JointLimits,
    SerialChain,
    evaluate_angle_parts,
    evaluate_parts,
    parts_clip,
    parts_pose_checks,
    parts_rows,
    parts_sqrt,
    parts_where,
    revolute,
    transl,
)
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
# Plain ints for the scalar parts (an IntEnum member costs a lookup and a conversion per use).
_SUCCESS, _SINGULAR, _JOINT_LIMITS, _UNREACHABLE, _INVALID = (int(s) for s in IKStatus)
_ALL_BRANCHES = (True,) * len(BRANCHES)
# The home elbow branch's candidates (either flange turn) lead BRANCHES.
_HOME_COUNT = sum(b.startswith(HOME_BRANCH) for b in BRANCHES)
_ANGLE = Number(min=-2 * math.tau, max=2 * math.tau, unit="rad")

#: The ``palletizer:`` section of a parameters file (manipulator_kinematics.config).
SCHEMA = {
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

    Not wrapped: A is affine in theta.
    """
    return (np.asarray(theta, dtype=float) - HOME_DH) @ AXIS_MATRIX[_variant(variant)].T


def dh_from_axis(axis: ArrayLike, variant: str) -> np.ndarray:
    """D-H angles [theta1, theta2, theta3, theta5] (..., 4) of axis angles: eqs. (9)-(11) inverted."""
    return np.asarray(axis, dtype=float) @ np.linalg.inv(AXIS_MATRIX[_variant(variant)]).T + HOME_DH


def _variant(variant: str) -> str:
    if variant not in AXIS_MATRIX:
        raise ValueError(f"unknown variant {variant!r}; known: {', '.join(VARIANTS)}")
    return variant


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
        # Plain floats for the scalar parts of the IK (numpy scalars cost more than the arithmetic).
        self._lengths = tuple(float(v) for v in (geometry.a1, geometry.a2, geometry.a3, geometry.a4,
                                                 geometry.d1, geometry.d6))
        self._bounds = limits.bounds(LIMIT_TOL)
        self._lean_min = math.cos(self.tilt_tolerance)  # cos of the largest tilt taken

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
        pose = np.zeros(shape + (16,))
        pose[..., 3:12:4] = p
        pose[..., 15] = 1.0
        turn = parts_rows(np.stack([np.cos(yaw), np.sin(yaw)], axis=-1))
        # Junk (non-finite inputs) gives NaN, not warnings.
        with np.errstate(invalid="ignore", over="ignore"):
            y, x, extra = evaluate_parts(self._closed_form, [parts_rows(pose), turn], ((4, 6), (4, 6), (8,)))
            angles = np.arctan2(y, x).reshape(shape + (4, 6))
        extra = extra.reshape(shape + (8,))
        theta = np.repeat(angles[..., :4], 2, axis=-2)
        theta[..., 1::2, 3] -= np.copysign(math.tau, theta[..., 1::2, 3])
        theta[~np.repeat(np.abs(extra[..., 4:6]) <= 1.0 + REACH_TOL, 4, axis=-1)] = np.nan
        return theta, extra[..., 4:6]

    def solve_ik(
        self,
        target: ArrayLike,
        *,
        use_orientation: bool = True,
        mode: str | None = None,
        seed: ArrayLike | None = None,
        branch: str | None = None,
    ) -> IKSolutions:
        """Every candidate for TCP target poses (..., 4, 4) (module docstring: solutions, rule).

        ``use_orientation``: the yaw comes from the target's x axis (its z axis must point down
        within ``tilt_tolerance``); otherwise the seed's flange yaw A1 - A6 is kept, or the home
        yaw 0 without a seed. ``mode`` ``axis`` (default: the configured variant's axis angles)
        or ``dh``; ``seed`` (4,) or (..., 4) in the mode's angles; ``branch`` one of
        :data:`BRANCHES` or of :data:`ARM_BRANCHES` (either flange turn).
        """
        mode = self._mode(mode)
        allowed = self._allowed(branch)
        target = np.asarray(target, dtype=float)
        if target.ndim < 2 or target.shape[-2:] != (4, 4):
            raise RequestError(f"targets must have shape (..., 4, 4), got {target.shape}", IKStatus.INVALID)
        shape = target.shape[:-2]
        pose = target.reshape(shape + (16,))
        if seed is not None:
            seed = np.asarray(seed, dtype=float)
            if seed.ndim == 0 or seed.shape[-1] != 4 or not np.all(np.isfinite(seed)):
                raise RequestError(f"seed must be 4 finite angles, got {seed.tolist()}", IKStatus.INVALID)
            if seed.shape != shape + (4,):
                seed = np.broadcast_to(seed, shape + (4,))
        if use_orientation:
            turn = pose[..., 0:5:4]  # (R00, R10): the TCP x axis, eq. (2)'s flange yaw
        else:
            yaw = np.zeros(shape) if seed is None else seed[..., 0] - seed[..., 3]
            turn = np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)
        judge = functools.partial(self._judge, allowed=allowed, use_orientation=use_orientation, mode=mode)
        extra, q, status, choice = evaluate_angle_parts(
            self._closed_form, [parts_rows(pose), parts_rows(turn)], ((4, 6), (4, 6), (8,)),
            judge, [] if seed is None else [parts_rows(seed)], ((8, 4), (8,), (3,)),
        )
        if len(shape) > 1:  # evaluate_angle_parts' batches are flat
            extra, q, status, choice = (out.reshape(shape + out.shape[1:])
                                        for out in (extra, q, status, choice))
        q[status >= _UNREACHABLE] = np.nan
        context = {
            "lean": extra[..., 2],
            "c3": extra[..., 4:6],
            "oriented": use_orientation,
            "mode": mode,
            "seeded": seed is not None,
            "branch": branch,
            "home": choice[..., 2] != 0.0,
        }
        return IKSolutions(
            q=q,
            status=status.astype(np.int8),
            branches=BRANCHES,
            selected=choice[..., 0].astype(np.intp),
            tie=choice[..., 1] != 0.0,
            explain=lambda solutions, index: self._explain(solutions, index, context),
        )

    def _closed_form(self, pose: Sequence, turn: Sequence) -> tuple[list, list, list]:
        """Eqs. (3)-(8) on scalar parts (floats for one target, (N,) arrays for a batch:
        :func:`evaluate_angle_parts`), every angle as a pair (y, x) for one arctan2 afterwards: sums of
        angles are products of pairs, so no trigonometry runs here and one target and a batch give
        the same bits.

        ``pose`` the 16 entries of the TCP pose, row-major; ``turn`` (cos, sin) of the flange yaw
        times any positive number. Returns y (24) and x (24): per configuration (front/back arm x
        elbow up/down) [theta1, theta2, theta3, theta5, A2, A3] (A3 of the configured variant;
        A1 = theta1, A6 = theta5); and [finite, rigid, cos(tilt), r, c3 front, c3 back, |sin theta3|
        front, back] with r the TCP's distance from axis 1.
        """
        px, py, az, pz = pose[3], pose[7], pose[10], pose[11]
        cy, sy = turn
        a1, a2, a3, a4, d1, d6 = self._lengths
        finite, rigid = parts_pose_checks(pose, ROTATION_TOL, BOTTOM_TOL)
        # eq. (3): theta1 = atan2(py, px); on axis 1 (r = 0) theta1 is free: 0 by rule.
        r = parts_sqrt(px * px + py * py)
        on_axis = r == 0.0
        c1, s1 = parts_where(on_axis, 1.0, px), parts_where(on_axis, 0.0, py)
        l2 = d1 - d6 - pz  # eq. (7)'s right-hand side
        y, x, c3s, s3s = [], [], [], []
        for arm in (1.0, -1.0):  # front, back (theta1 + pi: the signed radius rho = -r)
            c1k, s1k = arm * c1, arm * s1
            wrist = arm * r - a1 - a4  # X of the wrist point from axis 2
            c3 = (wrist * wrist + l2 * l2 - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)  # eq. (5)
            c3e = parts_clip(c3)
            s3 = parts_sqrt(1.0 - c3e * c3e)
            c3s.append(c3)
            s3s.append(s3)
            # eq. (4): theta5 = theta1 - yaw
            y5, x5 = s1k * cy - c1k * sy, c1k * cy + s1k * sy
            for elbow in (1.0, -1.0):  # up (the home pose's branch), down
                s = elbow * s3  # eq. (6)
                # eqs. (7)-(8): theta2 = atan2(b, a) + atan2(-X, l2), a = a3 s3, b = a3 c3 + a2
                a, b = a3 * s, a3 * c3e + a2
                y2, x2 = b * l2 - a * wrist, a * l2 + b * wrist
                # A2 = theta2 + 90 deg; A3 = theta3 - 90 deg (single) or theta2 + theta3 (double).
                if self.variant == "double":
                    y3, x3 = y2 * c3e + x2 * s, x2 * c3e - y2 * s
                else:
                    y3, x3 = -c3e, s
                y += [s1k, y2, s, y5, x2, y3]
                x += [c1k, x2, c3e, x5, -y2, x3]
        return y, x, [finite, rigid, -az, r, *c3s, *s3s]

    def _judge(self, angles: Sequence, extra: Sequence, seed: Sequence | None = None, *,
               allowed: tuple[bool, ...], use_orientation: bool, mode: str) -> tuple[list, list, list]:
        """Statuses and the selection rule (module docstring) on scalar parts, like
        :meth:`_closed_form`: one target in floats, a batch in arrays, the same bits.

        ``angles`` and ``extra`` from :meth:`_closed_form` (after the arctan2); ``seed`` 4 of the
        ``mode``'s angles or None; ``allowed`` the 8 candidates a requested branch leaves.
        Returns the 8 candidates' angles, their statuses and [selected, tie, the home elbow branch
        was selected].
        """
        finite, rigid, lean, r, *arms = extra
        invalid = (finite == 0.0) | ((rigid == 0.0) if use_orientation else False)
        blocked = invalid | ((lean < self._lean_min) if use_orientation else False)
        failure = _UNREACHABLE + invalid * (_INVALID - _UNREACHABLE)
        bounds = self._bounds
        candidates, status = [], []
        # Statuses by arithmetic on booleans (kind = JOINT_LIMITS - inside (JOINT_LIMITS - singular)
        # is SUCCESS, SINGULAR or JOINT_LIMITS): parts_where per candidate would cost more than the
        # rest of the IK for one target.
        for config in range(4):
            arm = config // 2
            reach = (abs(arms[arm]) <= 1.0 + REACH_TOL) & (blocked == 0)
            singular = (arms[2 + arm] < self.singular_elbow) | (r < self.singular_radius)
            theta1, theta2, theta3, a6, a2, a3 = angles[6 * config : 6 * config + 6]
            a1 = theta1
            base = ((a1 >= bounds[0]) & (a1 <= bounds[1]) & (a2 >= bounds[2]) & (a2 <= bounds[3])
                    & (a3 >= bounds[4]) & (a3 <= bounds[5]))
            # The other flange turn, 360 deg away (A6 = theta5 in every mode and variant).
            outer = a6 - (1.0 - 2.0 * (a6 < 0.0)) * math.tau
            q1, q2, q3 = (a1, a2, a3) if mode == "axis" else (theta1, theta2, theta3)
            for flange in (a6, outer):
                inside = base & (flange >= bounds[6]) & (flange <= bounds[7])
                kind = _JOINT_LIMITS - inside * (_JOINT_LIMITS - singular)
                candidates += [q1, q2, q3, flange]
                status.append(failure + reach * (kind - failure))
        home_choice, home_tie = select_parts(candidates, status, seed=seed, allowed=allowed[:_HOME_COUNT])
        other_choice, other_tie = select_parts(candidates, status, seed=seed, allowed=allowed)
        home = home_choice >= 0
        choice = [parts_where(home, home_choice, other_choice), parts_where(home, home_tie, other_tie), home]
        return candidates, status, choice

    def _mode(self, mode: str | None) -> str:
        if mode is None:
            return "axis"
        if mode not in MODES:
            raise RequestError(f"unknown IK mode {mode!r}; known: {', '.join(MODES)}")
        return mode

    @staticmethod
    def _allowed(branch: str | None) -> tuple[bool, ...]:
        if branch is None:
            return _ALL_BRANCHES
        if branch in BRANCHES:
            return tuple(b == branch for b in BRANCHES)
        if branch in ARM_BRANCHES:
            return tuple(b.startswith(branch) and b[len(branch) :] in ("", "_outer") for b in BRANCHES)
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
