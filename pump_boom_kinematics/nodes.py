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

A plan is bounded before it is computed by the rule of every machine
(:mod:`manipulator_kinematics.plan_bounds`: ``MAX_WAYPOINTS``, ``MAX_POINTS``, ``MAX_DURATION``,
the ranges of step, speed and acceleration; waypoints no farther than 1000 x the reach):
anything outside is refused with INVALID_GOAL_CONSTRAINTS and the reason.
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

from manipulator_kinematics.nodes import forward_main, run_node
from manipulator_kinematics.nodes.ik_server import SETTINGS, PlanPathServer, Rejected
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.schema import Number
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import PlanPath, SolveIK
from pump_boom_kinematics.kinematics import MODES, RegionTableError
from pump_boom_kinematics.pour import ACCELERATION_RANGE, PathPlan, plan_path

SERVER_SETTINGS = {
    **SETTINGS,
    "tip_acceleration": Number(
        min=ACCELERATION_RANGE[0],
        max=ACCELERATION_RANGE[1],
        unit="m/s^2",
        doc="bound of the tip's acceleration along a plan_path pour",
    ),
}


class PumpBoomServer(PlanPathServer):
    """The shared IK/FK/PlanPath server of the pump boom: pours by the region IK."""

    SETTINGS = SERVER_SETTINGS
    PLAN_MODES = MODES

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
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

    def plan(self, request: PlanPath.Request, waypoints: np.ndarray, seed: np.ndarray | None) -> PathPlan:
        # 0 = the machine's default; anything else (negative, NaN, tiny, huge) the planner checks.
        step = request.step if request.step != 0.0 else None
        speed = request.tip_speed if request.tip_speed != 0.0 else None
        try:
            return plan_path(self.model, waypoints, step, speed, seed, self.settings["tip_acceleration"])
        except RegionTableError as error:
            raise Rejected(KinematicsErrorCodes.FAILURE, str(error)) from None


def forward(args: Sequence[str] | None = None) -> int:
    return forward_main("pump_boom", "pump_boom_forward", args)


def ik_server(args: Sequence[str] | None = None) -> int:
    return run_node(PumpBoomServer, "pump_boom", "pump_boom_ik_server", args)
