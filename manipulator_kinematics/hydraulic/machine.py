"""Every machine of the hydraulic family in the machine registry, from its machine file alone.

:func:`family_machine` builds the :class:`~manipulator_kinematics.registry.Machine` record of a
family machine (entry points ``wheel_loader`` and ``knuckle_crane`` in setup.py): no Python per
machine. The record's model is :class:`FamilyArm`, the
:class:`~manipulator_kinematics.model.SerialModel` view of a
:class:`~manipulator_kinematics.hydraulic.model.HydraulicModel` whose joints are the actuators
(D: the swing angle in rad if the machine swings, then the cylinder lengths in m), so that the
generic forward node, IK/FK server, markers and bag tools run it unchanged. Its joint values are
what the machine's sensors read (the values on joint_states and in IK answers): a calibrated machine
file's zero offsets turn them into true states, D = reading + zero_offset (issue 33), before any
geometry, and the IK's D back into readings.

The tool frame (REP 103, base frame x forward, z up): the tool point, turned by the swing theta1
about z and, where Q has the tool angle alpha (counter-clockwise seen from the machine's right,
paper eq. 3), by -alpha about its y axis: R = Rz(theta1) Ry(-alpha). The crane's tool (a hanging
rotator pin) has no angle: R = Rz(theta1). Its twist: the linear rows of JC0 (eq. 8) and
omega = theta1_dot z + alpha_dot (sin theta1, -cos theta1, 0).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.hydraulic.description import SECTION, parse
from manipulator_kinematics.hydraulic.model import HydraulicModel, IKResult
from manipulator_kinematics.model import IKSolutions, IKStatus, RequestError
from manipulator_kinematics.param_files import config_path, load_parameters
from manipulator_kinematics.registry import Hook, Machine
from manipulator_kinematics.schema import Names, Text, Tree
from manipulator_kinematics.serial_chain import JointLimits

__all__ = ["FAMILY_TOPICS", "SCHEMA", "FamilyArm", "FamilyPoints", "family_machine"]

#: The section's keys; the named parts are checked by the family's parser (description.parse),
#: which names the key of anything wrong.
SCHEMA = {
    "name": Text(empty=False, doc="machine name (the URDF's robot name)"),
    "ground": Text(empty=False, doc="the body whose frame is the boom plane (r, z)"),
    "actuators": Names(doc="cylinders in the order of D (after the swing angle, if any)"),
    "assembly": Names(doc="unknown pins in solve order, one dyad each"),
    "joints": Names(doc="main-chain joints in order"),
    "bodies": Tree(doc="body -> pins: pin -> [x, z] in the body's frame (m)"),
    "links": Tree(default=None, doc="rigid two-pin links: from, to, length"),
    "cylinders": Tree(doc="cylinder -> base_pin, rod_pin, min/max/reference_length, max_speed"),
    "swing": Tree(
        default=None, doc="actuator, min/max/reference_angle, max_speed, tail_radius, tail_heights"
    ),
    "prismatic": Tree(default=None, doc="parent, child, cylinder, axis_point, offset"),
    "dyads": Tree(doc="pin -> pivot, first, orientation (+1/-1)"),
    "chain": Tree(doc="joint -> parent, child, limits"),
    "tool": Tree(doc="body, pin, width, angle, velocity_rows, outline"),
}

#: The topics of the family's nodes (manipulator_kinematics.nodes.hydraulic, default names).
FAMILY_TOPICS = {
    "joint_states": "sensor_msgs/msg/JointState",
    "tool_pose": "geometry_msgs/msg/PoseStamped",
    "tool_twist": "geometry_msgs/msg/TwistStamped",
    "urdf_joint_states": "sensor_msgs/msg/JointState",
    "target_twist": "geometry_msgs/msg/TwistStamped",
    "rate_commands": "sensor_msgs/msg/JointState",
    "velocity_ik_status": "diagnostic_msgs/msg/DiagnosticArray",
    "zone_clearance": "diagnostic_msgs/msg/DiagnosticArray",
}

#: The one branch of the family's IK: the solution nearest the seed (HydraulicModel.ik).
BRANCH = "nearest"


class FamilyArm:
    """A family machine as a serial machine whose joints are its actuators (module docstring)."""

    ik_branches = (BRANCH,)
    ik_modes: tuple[str, ...] = ()

    def __init__(self, model: HydraulicModel) -> None:
        self.hydraulic = model
        self.name = model.description.name
        swing = model.swing
        self._offset = model.zero_offset
        self._limits = JointLimits(
            model.actuator_names,
            model.lower - self._offset,
            model.upper - self._offset,
            tuple(not (swing and i == 0) for i in range(model.m)),
        )
        self._last: tuple[Any, Any] | None = None

    def _measured(self, D: np.ndarray) -> Any:
        """``hydraulic.measured(D)``, the last one kept: the forward node asks for the pose and
        the Jacobian of each state in turn, and the solve is the whole cost of both."""
        key = (D.shape, D.tobytes())
        if self._last is None or self._last[0] != key:
            self._last = (key, self.hydraulic.measured(D))
        return self._last[1]

    def true_state(self, q: ArrayLike) -> np.ndarray:
        """D (..., m) of sensor readings q: reading + zero_offset."""
        return np.asarray(q, dtype=float) + self._offset

    @classmethod
    def from_parameters(cls, params: dict[str, Any]) -> FamilyArm:
        """The machine of a validated ``hydraulic_machine`` section (optional parts None: left out)."""
        return cls(HydraulicModel(parse({k: v for k, v in params.items() if v is not None})))

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.hydraulic.actuator_names

    @property
    def limits(self) -> JointLimits:
        return self._limits

    def _rotation(self, D: np.ndarray, Q: np.ndarray) -> np.ndarray:
        h = self.hydraulic
        t1 = D[..., 0] if h.swing else np.zeros(D.shape[:-1])
        a = Q[..., 3] if h.description.has_angle else np.zeros(D.shape[:-1])
        c1, s1, ca, sa = np.cos(t1), np.sin(t1), np.cos(a), np.sin(a)
        zero = np.zeros_like(t1)
        # Rz(t1) @ Ry(-a)
        return np.stack(
            (
                np.stack((c1 * ca, -s1, -c1 * sa), axis=-1),
                np.stack((s1 * ca, c1, -s1 * sa), axis=-1),
                np.stack((sa, zero, ca), axis=-1),
            ),
            axis=-2,
        )

    def fkine(self, q: ArrayLike) -> np.ndarray:
        """Tool pose (..., 4, 4) for sensor readings (..., m) (finite; NaN where it does not close)."""
        D = self.true_state(q)
        Q = self._measured(D).Q
        T = np.zeros(D.shape[:-1] + (4, 4))
        T[..., :3, :3] = self._rotation(D, Q)
        T[..., :3, 3] = Q[..., :3]
        T[..., 3, 3] = 1.0
        return T

    def jacob0(self, q: ArrayLike) -> np.ndarray:
        """(..., 6, m): [v; omega] of the tool frame per actuator rate (module docstring)."""
        D = self.true_state(q)
        h = self.hydraulic
        jc0 = self._measured(D).jc0
        J = np.zeros(D.shape[:-1] + (6, h.m))
        J[..., :3, :] = jc0[..., :3, :]
        if h.description.has_angle:
            t1 = D[..., 0] if h.swing else np.zeros(D.shape[:-1])
            J[..., 3, :] = np.sin(t1)[..., None] * jc0[..., 3, :]
            J[..., 4, :] = -np.cos(t1)[..., None] * jc0[..., 3, :]
        if h.swing:
            J[..., 5, 0] = 1.0
        return J

    def frames(self, q: ArrayLike) -> np.ndarray:
        """(..., k, 4, 4): the base, every main-chain body's frame (x along its x axis, y the
        machine's y turned by the swing) and the tool last."""
        D = self.true_state(q)
        h = self.hydraulic
        placed = h.placements(D)
        t1 = D[..., 0] if h.swing else np.zeros(D.shape[:-1])
        c1, s1 = np.cos(t1), np.sin(t1)
        out = [np.broadcast_to(np.eye(4), D.shape[:-1] + (4, 4))]
        for joint in h.description.joints:
            origin, phi = placed[joint.child]
            T = np.zeros(D.shape[:-1] + (4, 4))
            cp, sp = np.cos(phi), np.sin(phi)
            T[..., 0, :3] = np.stack((c1 * cp, -s1, -c1 * sp), axis=-1)
            T[..., 1, :3] = np.stack((s1 * cp, c1, -s1 * sp), axis=-1)
            T[..., 2, :3] = np.stack((sp, np.zeros_like(sp), cp), axis=-1)
            T[..., :3, 3] = np.stack((origin[..., 0] * c1, origin[..., 0] * s1, origin[..., 1]), axis=-1)
            T[..., 3, 3] = 1.0
            out.append(T)
        out.append(self.fkine(q))
        return np.stack(out, axis=-3)

    def solve_ik(
        self,
        target: ArrayLike,
        *,
        use_orientation: bool = True,
        mode: str | None = None,
        seed: ArrayLike | None = None,
        branch: str | None = None,
    ) -> IKSolutions:
        """D for tool poses (..., 4, 4) by :meth:`HydraulicModel.ik` (closed form): with
        ``use_orientation`` the tool angle alpha of the target's rotation (which must be
        Rz(theta1) Ry(-alpha) of a state: anything else is UNREACHABLE), without it
        :meth:`HydraulicModel.position_ik` (the seed's tool angle held). One candidate, the
        solution nearest the seed (default: the reference state); INVALID where the target is not
        finite, UNREACHABLE where no state in the stroke box reaches it."""
        h = self.hydraulic
        if mode:
            raise RequestError(f"unknown mode {mode!r}: {self.name} has none")
        if branch is not None and branch not in self.ik_branches:
            raise RequestError(f"unknown branch {branch!r}; known: {', '.join(self.ik_branches)}")
        if use_orientation and not h.description.has_angle:
            raise RequestError(
                f"{self.name} has no tool angle (Q = [x, y, z]): set use_orientation false", IKStatus.INVALID
            )
        T = np.asarray(target, dtype=float)
        shape = T.shape[:-2]
        finite = np.all(np.isfinite(T), axis=(-2, -1))
        position = np.where(finite[..., None], T[..., :3, 3], 0.0)
        seed_D = h.reference if seed is None else np.clip(self.true_state(seed), h.lower, h.upper)
        seed_D = np.broadcast_to(seed_D, shape + (h.m,))
        if use_orientation:
            R = np.where(finite[..., None, None], T[..., :3, :3], np.eye(3))
            alpha = np.arctan2(R[..., 2, 0], R[..., 2, 2])
            # The rotation gives alpha modulo a turn; Q's alpha is the joints' plain sum (the
            # CET200's spans more than a turn): the turn nearest the seed's first, then the next.
            near = alpha + 2.0 * np.pi * np.round((h.pose(seed_D)[..., 3] - alpha) / (2.0 * np.pi))
            result = None
            for turn in (0.0, -1.0, 1.0):
                Q = np.concatenate((position, (near + 2.0 * np.pi * turn)[..., None]), axis=-1)
                found = h.ik(Q, seed_D)
                if result is None:
                    result = found
                else:
                    better = found.valid & ~result.valid
                    result = IKResult(
                        np.where(better[..., None], found.D, result.D), result.valid | found.valid
                    )
        else:
            result = h.position_ik(position, seed_D)
        valid = result.valid & finite
        if use_orientation:  # the whole rotation, not only alpha: a heading off the boom plane fails
            reached = self.fkine(np.where(valid[..., None], result.D, h.reference) - self._offset)
            valid &= np.all(np.abs(reached[..., :3, :3] - T[..., :3, :3]) < 1e-9, axis=(-2, -1))
        status = np.where(finite, np.where(valid, IKStatus.SUCCESS, IKStatus.UNREACHABLE), IKStatus.INVALID)
        q = np.where(valid[..., None], result.D - self._offset, np.nan)[..., None, :]
        return IKSolutions(
            q,
            status.astype(np.int8)[..., None],
            self.ik_branches,
            np.where(valid, 0, -1),
            np.zeros(shape, dtype=bool),
        )


class FamilyPoints:
    """The registry's ``monitored`` hook of a family machine: the points its avoidance zones
    watch (:meth:`HydraulicModel.monitored`, docs/zones.md) for sensor readings."""

    def __init__(self, arm: FamilyArm) -> None:
        self.arm = arm
        h = arm.hydraulic
        self.names: list[str] = h.monitored(h.reference, np.zeros(h.m))[0]

    def positions(self, q: ArrayLike) -> np.ndarray:
        """Positions (..., P, 3) in the base frame for sensor readings q (..., m)."""
        D = self.arm.true_state(q)
        return self.arm.hydraulic.monitored(D, np.zeros_like(D))[1]


@cache
def _file_name(config_file: str) -> str | None:
    """The ``name`` of a shipped machine file (what tells the family's machines apart)."""
    section = load_parameters(config_path(config_file)).get(SECTION, {})
    return section.get("name") if isinstance(section, dict) else None


def family_machine(name: str, config_file: str, summary: str) -> Machine:
    """The registry record of the family machine shipped as ``config/<config_file>``."""
    return Machine(
        name=name,
        summary=summary,
        section=SECTION,
        config_file=config_file,
        schema=SCHEMA,
        factory=FamilyArm.from_parameters,
        topics=FAMILY_TOPICS,
        analyse=Hook("manipulator_kinematics.bag.analysis:serial"),
        synthesize=Hook("manipulator_kinematics.bag.synthetic:serial_bag"),
        forward_node="hydraulic_forward",
        urdf=Hook("manipulator_kinematics.hydraulic.drawing:family_urdf"),
        scene=Hook("manipulator_kinematics.hydraulic.drawing:family_scene"),
        describes=lambda values: values.get("name") == _file_name(config_file),
        node_arguments=("--params-file", str(config_path(config_file))),
        monitored=FamilyPoints,
        read_surface=Hook("manipulator_kinematics.landxml:read_landxml"),
    )


#: The machines shipped as files (registered in setup.py; nothing else is written for them).
WHEEL_LOADER = family_machine(
    "wheel_loader",
    "wheel_loader_wl20.yaml",
    "20 t wheel loader WL20, Z-bar linkage (hydraulic family, paper 000): lift and tilt cylinders "
    "-> cutting edge and bucket angle",
)
KNUCKLE_CRANE = family_machine(
    "knuckle_crane",
    "knuckle_crane_kc100.yaml",
    "knuckle-boom crane KC100 (hydraulic family, paper 000): swing, lift, fold (four-bar) and "
    "telescope -> rotator pin",
)
