"""Console scripts of the pump boom: the generic nodes of manipulator_kinematics.nodes, plus plan_path.

* ``pump_boom_forward``: joint_states -> tool_pose (the pour point, x along section 5),
  tool_twist (from the geometric Jacobian).
* ``pump_boom_ik_server``: solve_ik (mode ``region``, position only: ``use_orientation`` must be
  false), solve_fk, and ``plan_path`` (manipulator_kinematics_interfaces/srv/PlanPath): straight
  lines through the waypoints, interpolated every ``step`` and solved by the region IK, timed by
  the constant tip speed (:mod:`pump_boom_kinematics.pour`).

Both nodes run any valid geometry (``-p pump_boom.lengths:=[...]``): FK needs no region table.
When the table named by ``regions.table_file`` was built for another geometry (or is missing),
the server says so at start-up and answers solve_ik and plan_path with FAILURE and the fix
(regenerate the table with ``pump_boom_regions``); solve_fk keeps working.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from manipulator_kinematics.joint_state import InputError, joint_values
from manipulator_kinematics.nodes import forward_main, run_node
from manipulator_kinematics.nodes.ik_server import IKServerNode, Rejected
from manipulator_kinematics.registry import Machine
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import PlanPath, SolveIK
from pump_boom_kinematics.kinematics import MODES, RegionTableError
from pump_boom_kinematics.pour import plan_path


class PumpBoomServer(IKServerNode):
    """The generic IK/FK server of the pump boom with the pour planning service ``plan_path``."""

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        self.create_service(PlanPath, "plan_path", self.plan_path)
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
        waypoints = np.array([[p.x, p.y, p.z] for p in request.waypoints], dtype=float).reshape(-1, 3)
        if len(waypoints) == 0 or not np.all(np.isfinite(waypoints)):
            raise Rejected(
                KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, "waypoints: need at least one, all finite"
            )
        if not (
            np.isfinite(request.step)
            and request.step >= 0.0
            and np.isfinite(request.tip_speed)
            and request.tip_speed >= 0.0
        ):
            raise Rejected(
                KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                f"step {request.step} m and tip_speed {request.tip_speed} m/s must be >= 0 (0 = default)",
            )
        seed = None
        if len(request.seed.name) or len(request.seed.position):
            try:
                seed, _ = joint_values(request.seed, self.joint_names, require_position=True)
            except InputError as error:
                raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"seed: {error}") from None
        try:
            plan = plan_path(self.model, waypoints, request.step or None, request.tip_speed or None, seed)
        except RegionTableError as error:
            raise Rejected(KinematicsErrorCodes.FAILURE, str(error)) from None
        except ValueError as error:  # a request the planner refuses (e.g. too many points)
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, str(error)) from None
        response.message = plan.message
        response.last_reachable_waypoint = plan.last_waypoint
        trajectory = JointTrajectory()
        trajectory.header.frame_id = self.frame
        trajectory.joint_names = list(self.joint_names)
        for t, q in zip(plan.t, plan.q):
            nanoseconds = round(t * 1e9)
            stamp = Duration(sec=nanoseconds // 10**9, nanosec=nanoseconds % 10**9)
            trajectory.points.append(JointTrajectoryPoint(positions=q.tolist(), time_from_start=stamp))
        response.trajectory = trajectory
        if not plan.ok or plan.truncated:
            raise Rejected(KinematicsErrorCodes.NO_IK_SOLUTION, plan.message)
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS


def forward(args: Sequence[str] | None = None) -> int:
    return forward_main("pump_boom", "pump_boom_forward", args)


def ik_server(args: Sequence[str] | None = None) -> int:
    return run_node(PumpBoomServer, "pump_boom", "pump_boom_ik_server", args)
