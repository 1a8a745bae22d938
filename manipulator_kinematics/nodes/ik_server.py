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
from typing import Any

import numpy as np

from manipulator_kinematics.config import Text
from manipulator_kinematics.joint_state import (
    PLAUSIBILITY_FACTOR,
    InputError,
    check_plausible_positions,
    joint_values,
)
from manipulator_kinematics.model import IKStatus, RequestError, describe_limits, pose_matrix
from manipulator_kinematics.nodes.base import FRAME_PREFIX, MachineNode
from manipulator_kinematics.nodes.messages import joint_state, pose_array, pose_stamped, twist_stamped
from manipulator_kinematics.registry import Machine
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK

SETTINGS = {
    "base_frame": Text(empty=False, doc="frame of targets and results; an empty target frame_id means it"),
    "frame_prefix": FRAME_PREFIX,
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
            "serving solve_ik, solve_fk")

    # ---- SolveIK ------------------------------------------------------------------------------
    def solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> SolveIK.Response:
        return self._answer(self._solve_ik, request, response)

    def _solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> None:
        self._check_frame(request.target.header.frame_id)
        position, quaternion = pose_array(request.target.pose)
        if not np.all(np.isfinite(position)):
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"target position is not finite: ({', '.join(map(str, position))})")
        distance = float(np.max(np.abs(position)))
        if distance > self.max_distance:
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"target position {position.tolist()} is beyond {PLAUSIBILITY_FACTOR:g} x the "
                           f"machine's reach (|coordinate| <= {self.max_distance:.6g} m): implausible")
        # The norm of a finite quaternion can still overflow (1e308): that is not a rotation either.
        with np.errstate(over="ignore"):  # inf: refused below, not a RuntimeWarning on stderr
            norm = float(np.linalg.norm(quaternion))
        if request.use_orientation and not (np.isfinite(norm) and norm >= 1e-9):
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"target orientation is not a rotation: {quaternion.tolist()}")
        mode = request.mode or None
        try:
            # A machine may answer some modes in other joints (the palletizer's D-H angles).
            names_for = getattr(self.model, "joint_names_for", None)
            names = self.joint_names if names_for is None else tuple(names_for(mode))
            seed = None
            if len(request.seed.name) or len(request.seed.position):
                try:
                    seed, _ = joint_values(request.seed, names, require_position=True)
                    if tuple(names) == tuple(self.limits.names):  # limits are known in these joints
                        check_plausible_positions(seed, names, self.limits.lower, self.limits.upper)
                except InputError as error:
                    raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"seed: {error}") from None
            target = pose_matrix(position, quaternion if request.use_orientation else None)
            result = self.model.solve_ik(target, use_orientation=request.use_orientation, mode=mode,
                                         seed=seed, branch=request.branch or None)
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
            raise Rejected(KinematicsErrorCodes.FAILURE,
                           f"the solver gave a non-finite solution for {position.tolist()}: not sent")
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
            raise Rejected(KinematicsErrorCodes.JOINT_LIMITS_VIOLATED,
                           f"joint_state outside the limits: {describe_limits(q, self.limits)}")
        with np.errstate(all="ignore"):  # overflow shows as a non-finite result, checked below
            pose = self.model.fkine(q)
            twist = np.zeros(6) if qd is None else self.model.jacob0(q) @ qd
        if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(twist))):
            raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE,
                           "joint_state gives a non-finite pose or twist")
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

    def _check_frame(self, frame_id: str) -> None:
        if frame_id not in ("", self.frame):
            raise Rejected(KinematicsErrorCodes.FRAME_TRANSFORM_FAILURE,
                           f"frame {frame_id!r} is not the base frame {self.frame!r} (no TF lookup here)")

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

