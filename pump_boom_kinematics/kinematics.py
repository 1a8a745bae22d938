"""Five-section concrete pump-truck boom of Liu et al. (paper 001): FK, tip Jacobian, region IK.

numpy only (no rclpy). SI units, REP 103: base frame on the slew axis at ground level, x
forward, z up. Joints, angles in the paper's convention (radians):

* ``slew_joint``       theta1  slew about +z;
* ``section_1_joint``  theta2  elevation of section 1 from the horizontal;
* ``section_k_joint``  theta_{k+1} (k = 2..5) unfolding angle of section k against section k - 1:
  0 = folded back onto it, pi = straight on; counter-clockwise positive in the boom plane.

Plane geometry (the paper's eqs. 1-2 written in the vertical boom plane, r horizontal out from the
slew axis, z up): section k points at phi_1 = theta2, phi_k = phi_{k-1} + theta_{k+1} - pi; the
joints are P_0 = root pin (r_root, z_root), P_k = P_{k-1} + L_k (cos phi_k, sin phi_k); the tip
P_5 is the pour point, in the base frame (r cos theta1, r sin theta1, z).

The same boom as a standard D-H chain on the shared :class:`SerialChain`: row 1 (a = r_root,
alpha = 90 deg, d = z_root) turns z_1 horizontal, so rows 2-6 rotate in the boom plane; rows
3-6 carry the paper's 180 deg convention as offset -pi (row variable = theta_k, D-H angle
theta_k - pi). The chain's joint variables are exactly the paper's angles.

Inverse kinematics by region planning (section 2; only the tip position is given, 2-3 redundant
DOF), mode ``region``:

1. theta1 = atan2(y, x) (eq. 3): the pour point is always put in front of the slew axis
   (r = hypot(x, y) >= 0); the mirrored solution theta1 + pi with the tip behind the slew axis
   (r < 0) is never returned (the positive envelope is undefined there). With a seed, theta1 is
   the turn of atan2(y, x) + 2 pi k nearest the seed's slew angle inside the slew limits (a pour
   passing behind the truck does not spin the boom round); on the slew axis itself (x = y = 0)
   theta1 is the seed's (else 0).
2. (theta2, theta3, theta4) from the region table at (r, z), blended in the transition bands
   (:mod:`.regions`).
3. theta5, theta6 from the planar 2R of sections 4 and 5 in closed form (eq. 4), on the
   elbow-over branch (theta6 <= pi: section 5 bends down from section 4, the positive-envelope
   branch).

Positive envelope (section 2.2, Figs. 3-4): no section joint P_1..P_4 below the chord from the
root pin to the tip, measured as the signed distance to the left of the directed chord (above it,
for a tip in front of the root pin); a pour point behind the root pin (r < r_root) is outside the
automatic pour workspace.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cached_property
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.model import IKSolutions, IKStatus, RequestError, describe_limits
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters
from manipulator_kinematics.plan_bounds import STEP_RANGE, TIP_SPEED_RANGE
from manipulator_kinematics.planar import ELBOW_NEGATIVE, two_link_ik, wrap_angle
from manipulator_kinematics.schema import Names, Number, Numbers, Schema, Text, require, validate
from manipulator_kinematics.serial_chain import JointLimits, SerialChain, revolute
from pump_boom_kinematics.regions import Grid, RegionTable

CONFIG_FILE = "pump_boom.yaml"
SECTION = "pump_boom"
BRANCHES = ("positive_envelope",)
MODES = ("region",)
#: Joint values this close (rad) outside a limit count as on it.
LIMIT_TOL = 1e-10
#: A joint this close (m) below the chord still counts as positive envelope (round-off).
ENVELOPE_TOL = 1e-9
#: The paper's example (section 2.2, Fig. 5), deg: fixed theta1..theta4, ranges of theta5, theta6.
PAPER_EXAMPLE: dict[str, tuple[float, ...]] = {
    "fixed": (0.0, 75.0, 165.0, 160.0),
    "theta5": (160.0, 240.0),
    "theta6": (30.0, 170.0),
}


SCHEMA: Schema = {
    "name": Text(empty=False, default="pump_boom", doc="the machine's name: the robot name of its URDF"),
    "root": Numbers(2, Number(min=-20.0, max=20.0, unit="m")),
    "lengths": Numbers(5, Number(min=0.0, max=100.0, unit="m", exclusive_min=True)),
    "joint_names": Names(6),
    "joint_min": Numbers(6, Number(min=-4 * math.pi, max=4 * math.pi, unit="rad")),
    "joint_max": Numbers(6, Number(min=-4 * math.pi, max=4 * math.pi, unit="rad")),
    "joint_max_speed": Numbers(6, Number(min=0.0, max=10.0, unit="rad/s", exclusive_min=True)),
    "regions": {
        "table_file": Text(empty=False),
        "origin": Numbers(2, Number(min=-100.0, max=100.0, unit="m")),
        "size": Number(min=0.0, max=100.0, unit="m", exclusive_min=True),
        "band": Number(min=0.0, max=100.0, unit="m", exclusive_min=True),
    },
    "pour": {
        "step": Number(min=STEP_RANGE[0], max=STEP_RANGE[1], unit="m"),
        "tip_speed": Number(min=TIP_SPEED_RANGE[0], max=TIP_SPEED_RANGE[1], unit="m/s"),
    },
}


class RegionTableError(ConfigError):
    """The region table cannot serve this machine: its file is missing, invalid, or built for
    another geometry or grid. FK and the Jacobian do not need it; region IK and pours do."""


class Failure(IntEnum):
    """Why the region IK has no solution for a pour point (0: it has one)."""

    NONE = 0
    NOT_FINITE = 1
    BEYOND_REACH = 2  # farther from the root pin than the stretched boom
    BEHIND_ROOT = 3  # r < r_root: behind the root pin
    NOT_IN_TABLE = 4  # the point's square is not in the region table
    TWO_LINK = 5  # the blended triple leaves the point out of reach of sections 4-5
    JOINT_LIMITS = 6
    ENVELOPE = 7  # a joint below the root-tip chord


_STATUS = {
    Failure.NONE: IKStatus.SUCCESS,
    Failure.NOT_FINITE: IKStatus.INVALID,
    Failure.BEYOND_REACH: IKStatus.UNREACHABLE,
    Failure.BEHIND_ROOT: IKStatus.UNREACHABLE,
    Failure.NOT_IN_TABLE: IKStatus.UNREACHABLE,
    Failure.TWO_LINK: IKStatus.UNREACHABLE,
    Failure.JOINT_LIMITS: IKStatus.JOINT_LIMITS,
    Failure.ENVELOPE: IKStatus.JOINT_LIMITS,
}
_STATUS_OF = np.array([_STATUS[f] for f in Failure], dtype=np.int8)
_FAILURES = tuple(Failure)  # by code: indexing is 10 times cheaper than Failure(code)


#: The seeds of a batch without one (ik_kernel.region_ik_batch reads its row, never uses it).
_NO_SEEDS = np.zeros((1, 6))


def _warm(ik_kernel: ModuleType, *lookup: np.ndarray) -> None:
    """Run the kernel once (numba loads it from its cache or compiles it)."""
    ik_kernel.region_ik(*lookup, 10.0, 0.0, 10.0, 0.0, True, np.empty(6))
    status, selected = np.empty((1, 1), dtype=np.int8), np.empty(1, dtype=np.intp)
    points = np.array([[10.0, 0.0, 10.0]])
    ik_kernel.region_ik_batch(
        *lookup, points, _NO_SEEDS, False, _STATUS_OF, np.empty((1, 1, 6)), status, selected
    )
    # The batch takes only these types: another (a read-only view, say) raises TypeError and the
    # call takes the numpy path, instead of compiling for seconds inside the call.
    ik_kernel.region_ik_batch.disable_compile()


#: The single-point kernel (:mod:`pump_boom_kinematics.ik_kernel`), see manipulator_kinematics.compiled.
KERNEL = Kernel("pump_boom_kinematics.ik_kernel", _warm)


def compiled_kernel(boom: PumpBoom, wait: bool = False) -> ModuleType | None:
    """The compiled kernel module if ready, else None (:class:`manipulator_kinematics.compiled.Kernel`:
    the first call of solve_ik or region_ik_point starts loading it, calls take the numpy path
    meanwhile, the same results within 1e-12). ``wait``: load it now (tests, benchmarks). Needs
    the boom's region table."""
    return KERNEL.get(*boom._kernel_args, wait=wait)


@dataclass(frozen=True)
class RegionIK:
    """Region-planning IK of a batch of pour points (leading shape ``...``).

    ``q`` (..., 6) joint values (NaN where ``failure`` != 0); ``failure`` (...,) :class:`Failure`;
    ``r``, ``z`` the pour point in the boom plane; ``blended`` (...,) True where a transition band
    set the triple (False: the square's own triple).
    """

    q: np.ndarray
    failure: np.ndarray
    r: np.ndarray
    z: np.ndarray
    blended: np.ndarray
    boom: PumpBoom = field(repr=False, compare=False)
    table: RegionTable = field(repr=False, compare=False)  # the table the points were solved with
    raw: np.ndarray = field(repr=False, compare=False)  # q before the failure mask, for reasons

    @property
    def ok(self) -> np.ndarray:
        return self.failure == Failure.NONE

    @property
    def status(self) -> np.ndarray:
        return _STATUS_OF[self.failure]

    def reason(self, index: tuple[int, ...] | int = ()) -> str:
        """Human-readable outcome of one pour point."""
        return self.boom.explain_failure(
            Failure(int(self.failure[index])),
            float(self.r[index]),
            float(self.z[index]),
            self.raw[index],
            bool(self.blended[index]),
            self.table,
        )


class PumpBoom:
    """The boom: root pin (m), five section lengths (m), joint limits (paper convention, rad),
    the region grid and table, and the pour defaults (step m, tip speed m/s).

    The region table is ``table`` if given, else read from ``table_file`` at its first use
    (:attr:`table`) and checked against this geometry: FK, the Jacobian and everything drawn from
    them work for any valid geometry; region IK and pours need a table built for it.
    """

    ik_branches = BRANCHES
    ik_modes = MODES

    def __init__(
        self,
        root: ArrayLike,
        lengths: ArrayLike,
        limits: JointLimits,
        grid: Grid,
        table: RegionTable | None = None,
        pour_step: float = 0.1,
        tip_speed: float = 0.2,
        table_file: str | Path | None = None,
        joint_speed: ArrayLike | None = None,
        name: str = "pump_boom",
    ) -> None:
        self.name = name
        self.root = np.asarray(root, dtype=float)
        self.lengths = np.asarray(lengths, dtype=float)
        if self.root.shape != (2,) or self.lengths.shape != (5,) or not np.all(self.lengths > 0.0):
            raise ValueError(
                f"need a root pin (r, z) and five positive lengths, got {self.root.tolist()}, "
                f"{self.lengths.tolist()}"
            )
        if len(limits.names) != 6:
            raise ValueError("the pump boom has six joints: slew and five sections")
        self.limits = limits
        self.grid = grid
        self._table = table
        self._table_error: RegionTableError | None = None
        self.table_file = None if table_file is None else Path(table_file)
        self.pour_step = float(pour_step)
        self.tip_speed = float(tip_speed)
        #: Joint speed limits (6,) rad/s (inf: none), which pours respect (:mod:`.pour`).
        self.joint_speed = np.full(6, np.inf) if joint_speed is None else np.asarray(joint_speed, dtype=float)
        if self.joint_speed.shape != (6,) or not np.all(self.joint_speed > 0.0):
            raise ValueError(f"need six joint speed limits > 0 (inf: none), got {self.joint_speed.tolist()}")
        self.reach = float(self.lengths.sum())

    # ---- construction -------------------------------------------------------------------------
    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], prefix: str = SECTION) -> PumpBoom:
        """From the nested ``pump_boom:`` section of a parameters file; ConfigError names a bad key.

        The region table named by ``regions.table_file`` (an absolute path, or a file name in the
        package's config directory) is read when the region IK first needs it (:attr:`table`).
        """
        p = validate(params, SCHEMA, prefix)
        names, lower, upper = p["joint_names"], p["joint_min"], p["joint_max"]
        for i in range(6):
            require(
                lower[i] < upper[i],
                f"{prefix}.joint_min[{i}]",
                f"{lower[i]} must be below {prefix}.joint_max[{i}] = {upper[i]} ({names[i]})",
            )
        require(
            lower[1] >= -math.pi / 2 and upper[1] <= math.pi / 2,
            f"{prefix}.joint_min[1]",
            "theta2 is the elevation of section 1 from the horizontal: keep it in [-pi/2, pi/2]",
        )
        for i in range(2, 6):
            require(
                lower[i] >= 0.0 and upper[i] <= 2 * math.pi,
                f"{prefix}.joint_max[{i}]",
                f"unfolding angles are in [0, 2 pi] (pi = straight on); {names[i]}: [{lower[i]}, {upper[i]}]",
            )
        regions = p["regions"]
        require(
            regions["band"] < regions["size"],
            f"{prefix}.regions.band",
            f"{regions['band']} m must be narrower than the squares ({regions['size']} m)",
        )
        limits = JointLimits(tuple(names), np.array(lower), np.array(upper))
        grid = Grid(tuple(regions["origin"]), regions["size"], regions["band"])
        return cls(
            p["root"],
            p["lengths"],
            limits,
            grid,
            pour_step=p["pour"]["step"],
            tip_speed=p["pour"]["tip_speed"],
            table_file=regions["table_file"],
            joint_speed=p["joint_max_speed"],
            name=p["name"],
        )

    @classmethod
    def default(cls) -> PumpBoom:
        """The default machine of ``config/pump_boom.yaml`` (its region table read on first use)."""
        return cls.from_parameters(load_parameters(config_path(CONFIG_FILE)).get(SECTION, {}))

    @property
    def table(self) -> RegionTable:
        """The region table, read from ``table_file`` at the first use and checked against this
        geometry and grid; RegionTableError (saying how to regenerate it) if it cannot serve."""
        if self._table is None:
            if self._table_error is None:
                try:
                    self._table = RegionTable.load(self.table_path(), self.table_key())
                except ConfigError as error:
                    # Remembered: a node asked again and again does not re-read the file.
                    self._table_error = RegionTableError(
                        f"no region table for this machine ({error}); region IK and pours need one "
                        "built for its geometry: run pump_boom_regions --config <machine file> "
                        "--output <table file> and point regions.table_file at it"
                    )
            if self._table is None:
                assert self._table_error is not None  # set with the table's absence above
                raise self._table_error
        return self._table

    def table_problem(self) -> str | None:
        """Why the region table cannot serve this machine (None: it can)."""
        try:
            table = self.table
        except RegionTableError as error:
            return str(error)
        return None if len(table) else "the region table has no square: region IK solves no point"

    def table_path(self) -> Path:
        """The region table file this machine file names (config/ relative, or absolute)."""
        if self.table_file is None:
            raise ConfigError(f"{SECTION}.regions.table_file: no region table given")
        if self.table_file.is_absolute():
            if not self.table_file.is_file():
                raise ConfigError(f"{SECTION}.regions.table_file: {self.table_file} does not exist")
            return self.table_file
        try:
            return config_path(str(self.table_file))
        except FileNotFoundError as error:
            raise ConfigError(f"{SECTION}.regions.table_file: {error}") from None

    def table_key(self) -> dict[str, Any]:
        """The values a region table depends on (it records them as ``built_for``)."""
        return {
            "root": self.root.tolist(),
            "lengths": self.lengths.tolist(),
            "joint_min": self.limits.lower.tolist(),
            "joint_max": self.limits.upper.tolist(),
            "origin": list(self.grid.origin),
            "size": self.grid.size,
            "band": self.grid.band,
        }

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.limits.names

    # ---- forward kinematics (eqs. 1-2) --------------------------------------------------------
    def section_angles(self, q: ArrayLike) -> np.ndarray:
        """Absolute angles phi_1..phi_5 (..., 5) of the sections from the horizontal."""
        q = _joints(q)
        relative = np.concatenate([q[..., 1:2], q[..., 2:] - np.pi], axis=-1)
        return np.cumsum(relative, axis=-1)

    def plane_points(self, q: ArrayLike) -> np.ndarray:
        """(r, z) (..., 6, 2) of the root pin, the section joints P_1..P_4 and the tip, in the
        boom plane (theta1 does not enter)."""
        phi = self.section_angles(q)
        steps = self.lengths[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        start = np.broadcast_to(self.root, phi.shape[:-1] + (1, 2))
        return np.concatenate([start, start + np.cumsum(steps, axis=-2)], axis=-2)

    def points(self, q: ArrayLike) -> np.ndarray:
        """Root pin, section joints and tip (..., 6, 3) in the base frame (to draw the boom)."""
        q = _joints(q)
        plane = self.plane_points(q)
        c, s = np.cos(q[..., 0])[..., None], np.sin(q[..., 0])[..., None]
        return np.stack([plane[..., 0] * c, plane[..., 0] * s, plane[..., 1]], axis=-1)

    def tip(self, q: ArrayLike) -> np.ndarray:
        """Pour point (..., 3) in the base frame (eq. 2)."""
        return self.points(q)[..., -1, :]

    def tip_jacobian(self, q: ArrayLike) -> np.ndarray:
        """d tip / d q (..., 3, 6) in closed form (base frame).

        Slew: (-y, x, 0). Section joint j (theta_{j+1}) turns sections j..5 about its axis, so
        d(r, z) = sum_{k >= j} L_k (-sin phi_k, cos phi_k), and the plane velocity maps to
        (dr cos theta1, dr sin theta1, dz).
        """
        q = _joints(q)
        phi = self.section_angles(q)
        plane = self.plane_points(q)
        tip_r = plane[..., -1, 0]
        dr = np.cumsum((-self.lengths * np.sin(phi))[..., ::-1], axis=-1)[..., ::-1]
        dz = np.cumsum((self.lengths * np.cos(phi))[..., ::-1], axis=-1)[..., ::-1]
        c, s = np.cos(q[..., 0]), np.sin(q[..., 0])
        slew = np.stack([-tip_r * s, tip_r * c, np.zeros_like(c)], axis=-1)
        sections = np.stack([dr * c[..., None], dr * s[..., None], dz], axis=-2)
        return np.concatenate([slew[..., :, None], sections], axis=-1)

    @cached_property
    def chain(self) -> SerialChain:
        """The boom as a standard D-H chain whose joint variables are the paper's angles."""
        r_root, z_root = self.root
        rows = [revolute(a=r_root, alpha=math.pi / 2, d=z_root), revolute(a=self.lengths[0])]
        rows += [revolute(a=length, offset=-math.pi) for length in self.lengths[1:]]
        return SerialChain(rows)

    def fkine(self, q: ArrayLike) -> np.ndarray:
        """Tip frame (..., 4, 4): origin the pour point, x along section 5, z along the joint
        axes (horizontal, -y of the slewed base)."""
        return self.chain.fkine(_joints(q))

    def frames(self, q: ArrayLike) -> np.ndarray:
        """(..., 7, 4, 4): base, root pin (slew frame), the four section joints, the tip."""
        return self.chain.fkine(_joints(q), all_frames=True)

    def jacob0(self, q: ArrayLike) -> np.ndarray:
        """Geometric Jacobian (..., 6, 6) of the tip in the base frame, linear rows first."""
        return self.chain.jacob0(_joints(q))

    # ---- positive envelope ---------------------------------------------------------------------
    def envelope_margin(self, q: ArrayLike) -> np.ndarray:
        """(...,) m: the smallest signed distance of P_1..P_4 to the left of the chord root -> tip
        (>= 0: positive envelope, Fig. 4); -inf where the tip is behind the root pin."""
        plane = self.plane_points(q)
        chord = plane[..., -1, :] - plane[..., 0, :]
        joints = plane[..., 1:-1, :] - plane[..., :1, :]
        length = np.linalg.norm(chord, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cross = (chord[..., None, 0] * joints[..., 1] - chord[..., None, 1] * joints[..., 0]).min(axis=-1)
            margin = cross / length
        # A tip on the root pin's vertical (r = r_root) counts as in front, up to round-off.
        return np.where(chord[..., 0] >= -ENVELOPE_TOL, margin, -np.inf)

    def positive_envelope(self, q: ArrayLike) -> np.ndarray:
        """(...,) True where the boom arches over its tip (Fig. 4)."""
        return self.envelope_margin(q) >= -ENVELOPE_TOL

    def example_sweep(self, n: int = 201) -> np.ndarray:
        """Joint states (n, n, 6) of the paper's Fig. 5 example: theta1..theta4 fixed, theta5 and
        theta6 over their ranges (n values each, ends included)."""
        (first5, last5), (first6, last6) = PAPER_EXAMPLE["theta5"], PAPER_EXAMPLE["theta6"]
        theta5 = np.radians(np.linspace(first5, last5, n))
        theta6 = np.radians(np.linspace(first6, last6, n))
        q = np.empty((n, n, 6))
        q[..., :4] = np.radians(PAPER_EXAMPLE["fixed"])
        q[..., 4], q[..., 5] = np.meshgrid(theta5, theta6, indexing="ij")
        return q

    # ---- inverse kinematics (section 2) --------------------------------------------------------
    def region_ik(
        self, points: ArrayLike, seed: ArrayLike | None = None, table: RegionTable | None = None
    ) -> RegionIK:
        """Region-planning IK of pour points (..., 3) in the base frame (module docstring).

        ``seed`` (6,) or (..., 6): only its slew angle is used (the turn of theta1). ``table``
        replaces the boom's own region table (the builder tries drafts with it). Raises
        RegionTableError if the boom's own table is missing or was built for another geometry.
        """
        table = self.table if table is None else table
        p = np.asarray(points, dtype=float)
        if p.ndim == 0 or p.shape[-1] != 3:
            raise ValueError(f"pour points must have shape (..., 3), got {p.shape}")
        x, y, z = p[..., 0], p[..., 1], p[..., 2]
        finite = np.isfinite(p).all(axis=-1)
        r = np.hypot(x, y)
        theta1 = self._slew(x, y, r, seed)
        triple, inside = table.blend(r, z)
        own = table.own_triple(r, z)
        blended = inside & np.any(triple != own, axis=-1)
        q, reachable, _, envelope = self.complete(triple, r, z)
        q[..., 0] = theta1
        within = self.limits.within(q, LIMIT_TOL)  # the slew turn as well
        q = np.where(within[..., None], self.limits.clip(q), q)
        distance = np.hypot(r - self.root[0], z - self.root[1])
        failure = np.select(
            [
                ~finite,
                distance > self.reach + 1e-9,
                r < self.root[0],
                ~inside,
                ~reachable,
                ~within,
                ~envelope,
            ],
            [
                Failure.NOT_FINITE,
                Failure.BEYOND_REACH,
                Failure.BEHIND_ROOT,
                Failure.NOT_IN_TABLE,
                Failure.TWO_LINK,
                Failure.JOINT_LIMITS,
                Failure.ENVELOPE,
            ],
            Failure.NONE,
        ).astype(np.int8)
        solved = np.where((failure == Failure.NONE)[..., None], q, np.nan)
        return RegionIK(q=solved, failure=failure, r=r, z=z, blended=blended, boom=self, table=table, raw=q)

    def complete(
        self, triple: ArrayLike, r: ArrayLike, z: ArrayLike
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Step 3 of the region IK: theta5, theta6 of sections 4-5 (eq. 4, elbow-over 2R) for the
        triples (..., 3) and plane points (r, z). Returns q (..., 6) with theta1 = 0 (joints within
        LIMIT_TOL of a limit moved onto it) and where the 2R reaches, the joints are inside the
        limits, the shape is positive envelope (all (...,))."""
        triple = np.asarray(triple, dtype=float)
        # Section 4's shoulder: the end P_3 of section 3 under the triple (eq. 4's constants).
        phi3 = triple.sum(axis=-1) - 2.0 * np.pi
        phi1, phi2 = triple[..., 0], triple[..., 0] + triple[..., 1] - np.pi
        l1, l2, l3, l4, l5 = self.lengths
        shoulder_r = self.root[0] + l1 * np.cos(phi1) + l2 * np.cos(phi2) + l3 * np.cos(phi3)
        shoulder_z = self.root[1] + l1 * np.sin(phi1) + l2 * np.sin(phi2) + l3 * np.sin(phi3)
        arm = two_link_ik(r - shoulder_r, z - shoulder_z, l4, l5, tol=1e-9)
        phi4 = arm.theta1[..., ELBOW_NEGATIVE]
        theta5 = wrap_angle(phi4 - phi3) + np.pi
        theta6 = arm.theta2[..., ELBOW_NEGATIVE] + np.pi
        q = np.concatenate(
            [
                np.zeros(theta5.shape + (1,)),
                np.broadcast_to(triple, theta5.shape + (3,)),
                theta5[..., None],
                theta6[..., None],
            ],
            axis=-1,
        )
        within = self.limits.within(q, LIMIT_TOL)
        q = np.where(within[..., None], self.limits.clip(q), q)
        return q, arm.reachable, within, self.positive_envelope(q)

    def region_ik_point(
        self, x: float, y: float, z: float, seed_slew: float | None = None
    ) -> tuple[tuple[float, ...] | None, Failure]:
        """:meth:`region_ik` of ONE pour point, for a controller that solves a point per cycle:
        the compiled kernel (:mod:`.ik_kernel`, the same steps and order of checks, equal to
        :meth:`region_ik` to 1e-12, tested over the whole table), once loaded in the background
        (:func:`compiled_kernel`); until then, or with ``MK_COMPILED=0``, :meth:`region_ik` on a
        batch of one.

        ``seed_slew``: the current slew angle (the turn of theta1). Returns (q, Failure.NONE) or
        (None, failure); :meth:`region_ik` of the same point gives the reason in words.
        """
        kernel = compiled_kernel(self)
        if kernel is None:
            seed = None if seed_slew is None else np.array([seed_slew, 0.0, 0.0, 0.0, 0.0, 0.0])
            result = self.region_ik(np.array([x, y, z], dtype=float), seed)
            failure = Failure(int(result.failure))
            return (tuple(result.q.tolist()) if failure is Failure.NONE else None), failure
        q = np.empty(6)
        slew = 0.0 if seed_slew is None else float(seed_slew)
        failure, _ = kernel.region_ik(
            *self._kernel_args, float(x), float(y), float(z), slew, seed_slew is not None, q
        )
        return (None if failure else tuple(q.tolist())), _FAILURES[failure]

    @cached_property
    def _kernel_args(self) -> tuple[np.ndarray, ...]:
        """The kernel's machine constants and the region table's lookup arrays (:mod:`.ik_kernel`)."""
        constants, owner, squares = self.table.lookup
        machine = [
            *self.root,
            *self.lengths,
            self.reach,
            LIMIT_TOL,
            ENVELOPE_TOL,
            *self.limits.lower,
            *self.limits.upper,
        ]
        return np.array([*machine, *constants], dtype=float), owner, squares

    def solve_ik(
        self,
        target: ArrayLike,
        *,
        use_orientation: bool = True,
        mode: str | None = None,
        seed: ArrayLike | None = None,
        branch: str | None = None,
    ) -> IKSolutions:
        """SerialModel IK: the pour point of target poses (..., 4, 4), mode ``region`` only.

        Position only: the hose hangs free, so a request with ``use_orientation`` is refused
        (RequestError), as is an unknown mode or branch. One candidate (``positive_envelope``).
        RegionTableError if the region table cannot serve this geometry (:attr:`table`).
        """
        if mode not in (None, *MODES):
            raise RequestError(f"unknown IK mode {mode!r} for the pump boom; known: {', '.join(MODES)}")
        if branch not in (None, *BRANCHES):
            raise RequestError(f"unknown branch {branch!r} for the pump boom; known: {', '.join(BRANCHES)}")
        if use_orientation:
            raise RequestError(
                "the pump boom's IK is position only (region mode places the pour point; "
                "its orientation is free): send use_orientation = false",
                IKStatus.INVALID,
            )
        target = np.asarray(target, dtype=float)
        if target.ndim < 2 or target.shape[-2:] != (4, 4):
            raise ValueError(f"targets must have shape (..., 4, 4), got {target.shape}")
        if seed is not None:
            seed = np.asarray(seed, dtype=float)
            if seed.ndim == 0 or seed.shape[-1] != 6 or not np.all(np.isfinite(seed)):
                raise RequestError(
                    f"seed must be finite joint values of shape (..., 6), got {seed.shape}", IKStatus.INVALID
                )
        if target.shape == (4, 4) and (seed is None or seed.shape == (6,)):
            kernel = compiled_kernel(self)
            if kernel is not None:
                return self._solve_one(kernel, target[:3, 3], seed)
        elif target.ndim == 3 and (seed is None or seed.shape in ((6,), (len(target), 6))):
            kernel = compiled_kernel(self)
            if kernel is not None and (many := self._solve_many(kernel, target[:, :3, 3], seed)) is not None:
                return many
        result = self.region_ik(target[..., :3, 3], seed)
        ok = result.ok

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            return result.reason(index)

        return IKSolutions(
            q=result.q[..., None, :],
            status=result.status[..., None],
            branches=BRANCHES,
            selected=np.where(ok, 0, -1),
            tie=np.zeros(ok.shape, dtype=bool),
            explain=explain,
        )

    def _solve_many(
        self, kernel: ModuleType, points: np.ndarray, seed: np.ndarray | None
    ) -> IKSolutions | None:
        """:meth:`solve_ik` of pour points (N, 3), seed (6,) or (N, 6), through the kernel's loop
        (ik_kernel.region_ik_batch), None for arguments of types the loop does not take
        (:func:`_warm`); a point's text is :meth:`region_ik`'s, made when asked for.
        Issue #32: a batch on the numpy path cost tens of single calls up to tens of points."""
        n = len(points)
        q, status, selected = np.empty((n, 1, 6)), np.empty((n, 1), dtype=np.int8), np.empty(n, dtype=np.intp)
        seeded = seed is not None
        try:
            kernel.region_ik_batch(
                *self._kernel_args,
                np.ascontiguousarray(points),
                _NO_SEEDS if seed is None else np.ascontiguousarray(seed.reshape(-1, 6)),
                seeded,
                _STATUS_OF,
                q,
                status,
                selected,
            )
        except TypeError:
            return None

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            return self.region_ik(
                points[index], seed if seed is None or seed.ndim == 1 else seed[index]
            ).reason()

        return IKSolutions(
            q=q,
            status=status,
            branches=BRANCHES,
            selected=selected,
            tie=np.zeros(n, dtype=bool),
            explain=explain,
        )

    def _solve_one(self, kernel: ModuleType, point: np.ndarray, seed: np.ndarray | None) -> IKSolutions:
        """:meth:`solve_ik` of one pour point through the compiled kernel; the reason in words from
        :meth:`region_ik` of the point, when asked for."""
        q = np.empty(6)
        seeded = seed is not None
        failure, _ = kernel.region_ik(
            *self._kernel_args, *point.tolist(), float(seed[0]) if seed is not None else 0.0, seeded, q
        )
        if failure:
            q[:] = np.nan

        def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
            return self.region_ik(point, seed).reason(index)

        return IKSolutions(
            q=q[None],
            status=_STATUS_OF[[failure]],
            branches=BRANCHES,
            selected=np.array(-1 if failure else 0),
            tie=np.zeros((), dtype=bool),
            explain=explain,
        )

    def explain_failure(
        self, failure: Failure, r: float, z: float, q: np.ndarray, blended: bool, table: RegionTable
    ) -> str:
        """Text of one region-IK outcome with ``table`` (:class:`RegionIK.reason`)."""
        where = f"pour point at r = {r:.4g} m, z = {z:.4g} m"
        if failure is Failure.NONE:
            how = "blended in a transition band" if blended else "its square's triple"
            i, j, level = (int(v) for v in table.square(r, z))
            return (
                f"region mode: square ({i}, {j}) of level {level} ({float(table.grid.side(level)):g} m), "
                f"theta2..theta4 {how}; theta5, theta6 closed form"
            )
        if failure is Failure.NOT_FINITE:
            return "pour point is not finite"
        if failure is Failure.BEYOND_REACH:
            distance = math.hypot(r - self.root[0], z - self.root[1])
            return (
                f"{where} is {distance:.4g} m from the root pin, beyond the boom's reach {self.reach:.4g} m"
                f"{_nearest(table, r, z)}"
            )
        if failure is Failure.BEHIND_ROOT:
            return (
                f"{where} is behind the boom root pin (r = {self.root[0]:.4g} m): the positive "
                "envelope is undefined there and it is outside the automatic pour workspace"
                f"{_nearest(table, r, z)}"
            )
        if failure is Failure.NOT_IN_TABLE:
            i, j = table.grid.square(r, z)
            r0, z0 = table.grid.corner(i, j)
            s = table.grid.size
            return (
                f"{where} is outside the region table: no square covers it (its {s:g} m square ({i}, {j}), "
                f"r {r0:.4g}-{r0 + s:.4g} m, z {z0:.4g}-{z0 + s:.4g} m, is not wholly in the automatic pour "
                f"workspace; {len(table)} squares, {table.covered_area:.0f} m^2){_nearest(table, r, z)}"
            )
        if failure is Failure.TWO_LINK:
            return f"{where}: the last two sections cannot reach it from the blended triple"
        if failure is Failure.JOINT_LIMITS:
            return f"{where}: {describe_limits(q, self.limits)}"
        return f"{where}: a section joint is {-float(self.envelope_margin(q)):.3g} m below the root-tip chord"

    def _slew(self, x: np.ndarray, y: np.ndarray, r: np.ndarray, seed: ArrayLike | None) -> np.ndarray:
        heading = np.arctan2(y, x)
        if seed is None:
            return np.where(r > 0.0, heading, 0.0)
        start = np.broadcast_to(np.asarray(seed, dtype=float)[..., 0], heading.shape)
        theta1 = heading + 2.0 * np.pi * np.round((start - heading) / (2.0 * np.pi))
        lower, upper = self.limits.lower[0], self.limits.upper[0]
        theta1 = np.where(
            theta1 > upper, theta1 - 2.0 * np.pi, np.where(theta1 < lower, theta1 + 2.0 * np.pi, theta1)
        )
        return np.where(r > 0.0, theta1, start)


def _nearest(table: RegionTable, r: float, z: float) -> str:
    """The reason's tail: the nearest covered point in the boom plane (the pour point's heading)."""
    if not len(table):
        return ""
    near_r, near_z = table.nearest(r, z)
    return (
        f"; the nearest covered point is r = {near_r:.4g} m, z = {near_z:.4g} m "
        f"({math.hypot(near_r - r, near_z - z):.3g} m away, same slew angle)"
    )


def _joints(q: ArrayLike) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 6:
        raise ValueError(f"joint values must have shape (..., 6), got {q.shape}")
    return q
