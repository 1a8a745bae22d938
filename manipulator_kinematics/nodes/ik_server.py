"""Generic IK/FK server of a serial machine: ``solve_ik`` and ``solve_fk``.

Services (relative names, so they can be namespaced or remapped), manipulator_kinematics_interfaces:

* ``solve_ik`` (SolveIK): the target pose in ``base_frame`` (empty frame_id = it), its
  orientation used when ``use_orientation``; ``seed`` (joints by name) for the selection rule;
  ``mode`` and ``branch`` names of the machine (empty: its defaults). The response's ``solution``
  is the selected solution, ``solutions`` every valid one, the selected first; ``message`` the
  machine's note (the rule used, a tie, or why no solution is valid).
* ``solve_fk`` (SolveFK): pose of the tool and, with velocities, its twist; stamp = the joint
  state's stamp.

Every bad request (NaN, unreachable, outside the joint limits, singular, unknown mode or branch,
foreign frame) is answered with success = false, an error code (MoveIt's values where they
exist) and a reason; nothing a client sends can stop the server. Finite but absurd values are
refused where they enter: a target farther from the base than 1000 x the machine's reach
(INVALID_GOAL_CONSTRAINTS), a seed further outside the limits than 1000 x a joint's range
(INVALID_ROBOT_STATE). A solution that is not finite is never sent (FAILURE with the reason).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar, Protocol

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import JointState

from manipulator_kinematics.joint_state import (
    PLAUSIBILITY_FACTOR,
    InputError,
    check_plausible_positions,
    joint_values,
)
from manipulator_kinematics.model import IKStatus, RequestError, describe_limits, pose_matrix
from manipulator_kinematics.nodes.base import FRAME_PREFIX, MachineNode
from manipulator_kinematics.nodes.messages import (
    joint_state,
    joint_trajectory,
    pose_array,
    pose_stamped,
    twist_stamped,
)
from manipulator_kinematics.plan_bounds import ACCELERATION_RANGE, MAX_WAYPOINTS, STEP_RANGE, TIP_SPEED_RANGE
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.schema import Number, Text
from manipulator_kinematics.time_scaling import TimeScaling
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import PlanPath, SolveFK, SolveIK

SETTINGS = {
    "base_frame": Text(empty=False, doc="frame of targets and results; an empty target frame_id means it"),
    "frame_prefix": FRAME_PREFIX,
}

#: The ``path`` settings of a server that plans straight tool-point lines
#: (:mod:`manipulator_kinematics.tool_path`): the excavator's and the hydraulic family's.
PATH_SETTINGS = {
    "step": Number(
        min=STEP_RANGE[0],
        max=STEP_RANGE[1],
        unit="m",
        doc="plan_path: sample spacing along each line when the request's step is 0",
    ),
    "tip_speed": Number(
        min=TIP_SPEED_RANGE[0],
        max=TIP_SPEED_RANGE[1],
        unit="m/s",
        doc="plan_path: tip speed limit when the request's tip_speed is 0",
    ),
    "acceleration": Number(
        min=ACCELERATION_RANGE[0],
        max=ACCELERATION_RANGE[1],
        unit="m/s^2",
        doc="plan_path: bound of the tip's acceleration along the path",
    ),
}

CODES = {
    IKStatus.SUCCESS: KinematicsErrorCodes.SUCCESS,
    IKStatus.SINGULAR: KinematicsErrorCodes.SINGULAR,
    IKStatus.JOINT_LIMITS: KinematicsErrorCodes.JOINT_LIMITS_VIOLATED,
    IKStatus.UNREACHABLE: KinematicsErrorCodes.NO_IK_SOLUTION,
    IKStatus.INVALID: KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
}


class Rejected(Exception):
    """A request that gets success = false with ``code`` and ``message``."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


class IKServerNode(MachineNode):
    """SolveIK / SolveFK of a registered serial machine (module docstring)."""

    SETTINGS = SETTINGS

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        self.frame = self.settings["frame_prefix"] + self.settings["base_frame"]
        self.joint_names = machine.joint_names(self.model)
        self.limits = machine.limits(self.model)
        self.max_distance = PLAUSIBILITY_FACTOR * max(self._reach(), 1.0)
        self.create_service(SolveIK, "solve_ik", self.solve_ik)
        self.create_service(SolveFK, "solve_fk", self.solve_fk)
        self.get_logger().info(
            f"{machine.name}: joints {list(self.joint_names)}, frame {self.frame!r}, modes "
            f"{list(self.model.ik_modes)}, branches {list(self.model.ik_branches)}: "
            "serving solve_ik, solve_fk"
        )

    # ---- SolveIK ------------------------------------------------------------------------------
    def solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> SolveIK.Response:
        return self._answer(self._solve_ik, request, response)

    def _solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> None:
        self._check_frame(request.target.header.frame_id)
        position, quaternion = pose_array(request.target.pose)
        if not np.all(np.isfinite(position)):
            raise Rejected(
                KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                f"target position is not finite: ({', '.join(map(str, position))})",
            )
        distance = float(np.max(np.abs(position)))
        if distance > self.max_distance:
            raise Rejected(
                KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                f"target position {position.tolist()} is beyond {PLAUSIBILITY_FACTOR:g} x the "
                f"machine's reach (|coordinate| <= {self.max_distance:.6g} m): implausible",
            )
        # The norm of a finite quaternion can still overflow (1e308): that is not a rotation either.
        with np.errstate(over="ignore"):  # inf: refused below, not a RuntimeWarning on stderr
            norm = float(np.linalg.norm(quaternion))
        if request.use_orientation and not (np.isfinite(norm) and norm >= 1e-9):
            raise Rejected(
                KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                f"target orientation is not a rotation: {quaternion.tolist()}",
            )
        mode = request.mode or None
        try:
            # A machine may answer some modes in other joints (the palletizer's D-H angles).
            names_for = getattr(self.model, "joint_names_for", None)
            names = self.joint_names if names_for is None else tuple(names_for(mode))
            seed = self._seed(request.seed, names)
            target = pose_matrix(position, quaternion if request.use_orientation else None)
            result = self.model.solve_ik(
                target,
                use_orientation=request.use_orientation,
                mode=mode,
                seed=seed,
                branch=request.branch or None,
            )
        except RequestError as error:
            code = KinematicsErrorCodes.INVALID_MODE if error.status is None else CODES[error.status]
            raise Rejected(code, str(error)) from None
        response.message = result.note()
        if not bool(result.ok):
            # A valid candidate can exist without a selection (the requested branch is not valid):
            # the code is then that branch's failure, never SUCCESS with success = false.
            raise Rejected(CODES[result.failure(branch=request.branch or None)], response.message)
        ordered = result.ordered()
        if not (np.all(np.isfinite(result.solution)) and np.all(np.isfinite(result.q[ordered]))):
            raise Rejected(
                KinematicsErrorCodes.FAILURE,
                f"the solver gave a non-finite solution for {position.tolist()}: not sent",
            )
        stamp = self.get_clock().now().to_msg()
        response.solution = joint_state(stamp, names, result.solution)
        response.solutions = [joint_state(stamp, names, result.q[i]) for i in ordered]
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS

    # ---- SolveFK ------------------------------------------------------------------------------
    def solve_fk(self, request: SolveFK.Request, response: SolveFK.Response) -> SolveFK.Response:
        return self._answer(self._solve_fk, request, response)

    def _solve_fk(self, request: SolveFK.Request, response: SolveFK.Response) -> None:
        self._check_frame(request.frame_id)
        try:
            q, qd = joint_values(request.joint_state, self.joint_names, require_position=True)
        except InputError as error:
            raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"joint_state: {error}") from None
        if not self.limits.within(q):
            raise Rejected(
                KinematicsErrorCodes.JOINT_LIMITS_VIOLATED,
                f"joint_state outside the limits: {describe_limits(q, self.limits)}",
            )
        with np.errstate(all="ignore"):  # overflow shows as a non-finite result, checked below
            pose = self.model.fkine(q)
            twist = np.zeros(6) if qd is None else self.model.jacob0(q) @ qd
        if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(twist))):
            raise Rejected(
                KinematicsErrorCodes.INVALID_ROBOT_STATE, "joint_state gives a non-finite pose or twist"
            )
        stamp = request.joint_state.header.stamp
        response.pose = pose_stamped(stamp, self.frame, pose)
        response.twist = twist_stamped(stamp, self.frame, twist)
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS
        note = getattr(self.model, "state_note", None)
        response.message = note(q) if note is not None else ""

    # ---- common -------------------------------------------------------------------------------
    def _reach(self) -> float:
        """Largest distance of the tool from the base over a seeded sample of the joint box (m)."""
        lower, upper = self.limits.lower, self.limits.upper
        q = np.random.default_rng(0).uniform(lower, upper, (4096, len(lower)))
        return float(np.max(np.linalg.norm(self.model.fkine(q)[..., :3, 3], axis=-1)))

    def _seed(self, seed: JointState, names: Sequence[str]) -> np.ndarray | None:
        """The seed's positions in ``names`` (None: no seed given); INVALID_ROBOT_STATE when it
        lacks a joint or is further outside the limits than 1000 x a joint's range."""
        if not (len(seed.name) or len(seed.position)):
            return None
        try:
            q, _ = joint_values(seed, names, require_position=True)
            if tuple(names) == tuple(self.limits.names):  # limits are known in these joints
                check_plausible_positions(q, names, self.limits.lower, self.limits.upper)
        except InputError as error:
            raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"seed: {error}") from None
        return q

    def _check_frame(self, frame_id: str) -> None:
        if frame_id not in ("", self.frame):
            raise Rejected(
                KinematicsErrorCodes.FRAME_TRANSFORM_FAILURE,
                f"frame {frame_id!r} is not the base frame {self.frame!r} (no TF lookup here)",
            )

    def _answer(self, solve: Callable[[Any, Any], None], request: Any, response: Any) -> Any:
        try:
            solve(request, response)
        except Rejected as rejection:
            response.success = False
            response.error_code.val = rejection.code
            response.message = rejection.message
        except Exception as error:  # a bug must cost one answer, not the server
            self.get_logger().error(f"request failed unexpectedly: {error!r}")
            response.success = False
            response.error_code.val = KinematicsErrorCodes.FAILURE
            response.message = f"internal error: {error!r}"
        return response


class Plan(Protocol):
    """What a machine's planner returns to :class:`PlanPathServer`: ``timing`` (None without a
    point), ``ok`` (the first waypoint is solvable), ``truncated`` (the path ends short of the
    last waypoint), ``last_waypoint`` (-1: none) and ``message``."""

    timing: TimeScaling | None
    ok: bool
    truncated: bool
    last_waypoint: int
    message: str


class PlanPathServer(IKServerNode):
    """The IK/FK server plus ``plan_path`` (manipulator_kinematics_interfaces/srv/PlanPath): one
    request check and one answer for every machine; the machine gives :attr:`PLAN_MODES`,
    :attr:`MAX_WAYPOINTS` and :meth:`plan`.

    Refused before any work, with success = false, ``last_reachable_waypoint`` -1 and no points:
    an unknown mode (INVALID_MODE); no waypoint, more than MAX_WAYPOINTS, one not finite or
    beyond 1000 x the reach (INVALID_GOAL_CONSTRAINTS); a seed as in solve_ik
    (INVALID_ROBOT_STATE); a request the planner refuses, ValueError (INVALID_GOAL_CONSTRAINTS).
    A plan that ends short answers NO_IK_SOLUTION with the reason, ``last_reachable_waypoint``
    and the trajectory up to there. plan_path runs in a callback group of its own on two threads
    (``THREADS``), so solve_ik and solve_fk are answered while a plan is computed."""

    # plan_path (a group of its own) served beside solve_ik/solve_fk (the default group): the
    # largest plans take seconds (the pump boom's 20,000 points 2-3 s; the excavator allows more).
    THREADS = 2
    #: Modes plan_path takes ("" is always the default).
    PLAN_MODES: ClassVar[tuple[str, ...]] = ()
    #: Most waypoints of one request: the rule of every machine (plan_bounds).
    MAX_WAYPOINTS: ClassVar[int] = MAX_WAYPOINTS

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        self.create_service(
            PlanPath, "plan_path", self.plan_path, callback_group=MutuallyExclusiveCallbackGroup()
        )

    def plan(self, request: PlanPath.Request, waypoints: np.ndarray, seed: np.ndarray | None) -> Plan:
        """The machine's plan through ``waypoints`` (K, 3) (checked finite and plausible) from
        ``seed`` (joints, or None); raises :class:`Rejected`, or ValueError for a request out of
        the planner's bounds."""
        raise NotImplementedError

    def plan_path(self, request: PlanPath.Request, response: PlanPath.Response) -> PlanPath.Response:
        response.last_reachable_waypoint = -1
        return self._answer(self._plan_path, request, response)

    def _plan_path(self, request: PlanPath.Request, response: PlanPath.Response) -> None:
        if request.mode not in ("", *self.PLAN_MODES):
            raise Rejected(
                KinematicsErrorCodes.INVALID_MODE,
                f"unknown mode {request.mode!r}; known: {', '.join(self.PLAN_MODES)}",
            )
        count, most = len(request.waypoints), self.MAX_WAYPOINTS
        if not 1 <= count <= most:
            raise Rejected(
                KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, f"waypoints: need 1 to {most}, got {count}"
            )
        waypoints = np.array([[p.x, p.y, p.z] for p in request.waypoints], dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(waypoints)):
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, "waypoints must be finite")
        far = np.flatnonzero(np.max(np.abs(waypoints), axis=1) > self.max_distance)
        if len(far):
            raise Rejected(
                KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                f"waypoint {far[0]} {waypoints[far[0]].tolist()} is beyond "
                f"{PLAUSIBILITY_FACTOR:g} x the machine's reach (|coordinate| <= "
                f"{self.max_distance:.6g} m): implausible",
            )
        seed = self._seed(request.seed, self.joint_names)
        try:
            plan = self.plan(request, waypoints, seed)
        except ValueError as error:  # a request out of the planner's bounds
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, str(error)) from None
        response.message = plan.message
        response.last_reachable_waypoint = plan.last_waypoint
        response.trajectory.header.frame_id = self.frame
        response.trajectory.joint_names = list(self.joint_names)
        if plan.timing is not None:
            try:
                response.trajectory = joint_trajectory(self.frame, self.joint_names, plan.timing.trajectory)
            except ValueError as error:
                raise Rejected(KinematicsErrorCodes.FAILURE, f"the plan cannot be sent: {error}") from None
        if not plan.ok or plan.truncated:
            raise Rejected(KinematicsErrorCodes.NO_IK_SOLUTION, plan.message)
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS
