"""Console scripts of the pump boom: the generic nodes of manipulator_kinematics.nodes, plus plan_path.

* ``pump_boom_forward``: joint_states -> tool_pose (the pour point, x along section 5),
  tool_twist (from the geometric Jacobian).
* ``pump_boom_ik_server``: solve_ik (mode ``region``, position only: ``use_orientation`` must be
  false), solve_fk, and ``plan_path`` (manipulator_kinematics_interfaces/srv/PlanPath): straight
  lines through the waypoints, interpolated every ``step`` and solved by the region IK, timed by
  the shared time scaling (:mod:`pump_boom_kinematics.pour`): the trajectory has positions,
  velocities and accelerations, is at rest at both ends, keeps every joint within
  ``pump_boom.joint_max_speed`` and the tip at ``tip_speed`` wherever the joints allow it, with the
  tip's acceleration along the path bounded by the setting ``tip_acceleration``.

A plan is bounded before it is computed (``pour.MAX_WAYPOINTS``, ``MAX_POINTS``,
``MAX_DURATION``, the ranges of step, speed and acceleration; waypoints no farther than
1000 x the reach): anything outside is refused with INVALID_GOAL_CONSTRAINTS and the reason.
plan_path runs in a callback group of its own on a multi-threaded executor (``THREADS``), so
solve_ik and solve_fk are answered while a plan (up to about a second) is computed.

Both nodes run any valid geometry (``-p pump_boom.lengths:=[...]``): FK needs no region table.
When the table named by ``regions.table_file`` was built for another geometry (or is missing),
the server says so at start-up and answers solve_ik and plan_path with FAILURE and the fix
(regenerate the table with ``pump_boom_regions``); solve_fk keeps working.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

from manipulator_kinematics.config import Number
from manipulator_kinematics.joint_state import (
    PLAUSIBILITY_FACTOR,
    InputError,
    check_plausible_positions,
    joint_values,
)
from manipulator_kinematics.nodes import forward_main, run_node
from manipulator_kinematics.nodes.ik_server import SETTINGS, IKServerNode, Rejected
from manipulator_kinematics.nodes.messages import joint_trajectory
from manipulator_kinematics.registry import Machine
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import PlanPath, SolveIK
from pump_boom_kinematics.kinematics import MODES, RegionTableError
from pump_boom_kinematics.pour import ACCELERATION_RANGE, MAX_WAYPOINTS, plan_path

SERVER_SETTINGS = {
    **SETTINGS,
    "tip_acceleration": Number(min=ACCELERATION_RANGE[0], max=ACCELERATION_RANGE[1], unit="m/s^2",
                               doc="bound of the tip's acceleration along a plan_path pour"),
}


class PumpBoomServer(IKServerNode):
    """The generic IK/FK server of the pump boom with the pour planning service ``plan_path``."""

    SETTINGS = SERVER_SETTINGS
    # plan_path in a group of its own, served beside solve_ik/solve_fk (the default group).
    THREADS = 2

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        self.create_service(PlanPath, "plan_path", self.plan_path,
                            callback_group=MutuallyExclusiveCallbackGroup())
        problem = self.model.table_problem()
        if problem is None:
            self.get_logger().info(f"region table: {len(self.model.table)} squares; serving plan_path")
        else:
            self.get_logger().warning(f"solve_ik and plan_path will fail, solve_fk works: {problem}")

    def _solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> None:
        try:
            super()._solve_ik(request, response)
        except RegionTableError as error:
            raise Rejected(KinematicsErrorCodes.FAILURE, str(error)) from None

    def plan_path(self, request: PlanPath.Request, response: PlanPath.Response) -> PlanPath.Response:
        response.last_reachable_waypoint = -1
        return self._answer(self._plan_path, request, response)

    def _plan_path(self, request: PlanPath.Request, response: PlanPath.Response) -> None:
        if request.mode not in ("", *MODES):
            raise Rejected(
                KinematicsErrorCodes.INVALID_MODE, f"unknown mode {request.mode!r}; known: {', '.join(MODES)}"
            )
        if not 1 <= len(request.waypoints) <= MAX_WAYPOINTS:
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"waypoints: need 1 to {MAX_WAYPOINTS}, got {len(request.waypoints)}")
        waypoints = np.array([[p.x, p.y, p.z] for p in request.waypoints], dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(waypoints)):
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, "waypoints must be finite")
        far = np.flatnonzero(np.max(np.abs(waypoints), axis=1) > self.max_distance)
        if len(far):
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"waypoint {far[0]} {waypoints[far[0]].tolist()} is beyond "
                           f"{PLAUSIBILITY_FACTOR:g} x the machine's reach (|coordinate| <= "
                           f"{self.max_distance:.6g} m): implausible")
        seed = None
        if len(request.seed.name) or len(request.seed.position):
            try:
                seed, _ = joint_values(request.seed, self.joint_names, require_position=True)
                check_plausible_positions(seed, self.joint_names, self.limits.lower, self.limits.upper)
            except InputError as error:
                raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"seed: {error}") from None
        # 0 = the machine's default; anything else (negative, NaN, tiny, huge) the planner checks.
        step = request.step if request.step != 0.0 else None
        speed = request.tip_speed if request.tip_speed != 0.0 else None
        try:
            plan = plan_path(self.model, waypoints, step, speed, seed, self.settings["tip_acceleration"])
        except RegionTableError as error:
            raise Rejected(KinematicsErrorCodes.FAILURE, str(error)) from None
        except ValueError as error:  # a request out of the planner's bounds
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, str(error)) from None
        response.message = plan.message
        response.last_reachable_waypoint = plan.last_waypoint
        if plan.timing is not None:
            try:
                response.trajectory = joint_trajectory(self.frame, self.joint_names, plan.timing.trajectory)
            except ValueError as error:
                raise Rejected(KinematicsErrorCodes.FAILURE, f"the plan cannot be sent: {error}") from None
        else:
            response.trajectory.header.frame_id = self.frame
            response.trajectory.joint_names = list(self.joint_names)
        if not plan.ok or plan.truncated:
            raise Rejected(KinematicsErrorCodes.NO_IK_SOLUTION, plan.message)
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS


def forward(args: Sequence[str] | None = None) -> int:
    return forward_main("pump_boom", "pump_boom_forward", args)


def ik_server(args: Sequence[str] | None = None) -> int:
    return run_node(PumpBoomServer, "pump_boom", "pump_boom_ik_server", args)
