"""``excavator_ik_server``: the shared IK/FK server (:mod:`manipulator_kinematics.nodes.ik_server`)
for the excavator, in the actuator coordinates D = [theta1, d2, d3, d4], plus ``plan_path``.

* ``solve_ik``: a bucket pose -> D (joints ``swing_joint`` rad, ``boom_cylinder``,
  ``arm_cylinder``, ``bucket_cylinder`` lengths m, as on ``cylinder_lengths`` / ``joint_states``),
  closed form (:mod:`excavator_kinematics.inverse`). Mode ``pose`` (default with
  ``use_orientation``): the orientation gives the swing heading and the bucket angle alpha;
  mode ``position`` (default without): alpha of the seed, else the widest stroke margin. Branches
  ``front_elbow_up``, ``front_elbow_down``, ``behind_elbow_up``, ``behind_elbow_down``.
* ``solve_fk``: D (and its rates) -> bucket pose (the tip; yaw theta1, then -alpha about y) and
  twist (eq. 8 and the bucket frame's turn).
* ``plan_path`` (manipulator_kinematics_interfaces/srv/PlanPath): straight bucket-tip lines through
  the waypoints at the bucket angle of the seed (else of the first waypoint's solution), timed
  within every actuator's max speed, the tip speed and ``path.acceleration``, at rest at both
  ends (:mod:`excavator_kinematics.path`); positions, velocities and accelerations. A path that
  leaves the workspace ends at the farthest reachable point: success false (NO_IK_SOLUTION), the
  reason, ``last_reachable_waypoint`` and the trajectory up to there.

Settings in config/excavator_nodes.yaml (``/**/excavator_ik_server``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from excavator_kinematics.node_settings import NODES_CONFIG
from excavator_kinematics.path import MIN_ACCELERATION, MIN_SPEED, plan_path
from manipulator_kinematics.config import Number, Schema
from manipulator_kinematics.joint_state import PLAUSIBILITY_FACTOR, InputError, joint_values
from manipulator_kinematics.nodes import run_node
from manipulator_kinematics.nodes.ik_server import SETTINGS, IKServerNode, Rejected
from manipulator_kinematics.registry import Machine
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import PlanPath

NODE = "excavator_ik_server"
PATH_SETTINGS = {
    "step": Number(min=0.0, max=100.0, unit="m", exclusive_min=True,
                   doc="plan_path: sample spacing along each line when the request's step is 0"),
    "tip_speed": Number(min=MIN_SPEED, max=10.0, unit="m/s",
                        doc="plan_path: tip speed limit when the request's tip_speed is 0"),
    "acceleration": Number(min=MIN_ACCELERATION, max=100.0, unit="m/s^2",
                           doc="plan_path: bound of the tip's acceleration along the path"),
}
#: IK mode of every path sample: the bucket angle is held, so the pose IK.
PATH_MODES = ("pose",)


class ExcavatorIKServer(IKServerNode):
    """The shared SolveIK / SolveFK server with ``plan_path``, settings in the excavator nodes' file."""

    DEFAULTS_FILE = NODES_CONFIG
    SETTINGS: ClassVar[Schema] = {**SETTINGS, "path": PATH_SETTINGS}

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        self.path = self.settings["path"]
        self.create_service(PlanPath, "plan_path", self.plan_path)
        path = self.path
        self.get_logger().info(f"serving plan_path (defaults: step {path['step']:g} m, tip speed "
                               f"{path['tip_speed']:g} m/s, acceleration {path['acceleration']:g} m/s^2)")

    def plan_path(self, request: PlanPath.Request, response: PlanPath.Response) -> PlanPath.Response:
        response.last_reachable_waypoint = -1
        return self._answer(self._plan_path, request, response)

    def _plan_path(self, request: PlanPath.Request, response: PlanPath.Response) -> None:
        if request.mode not in ("", *PATH_MODES):
            raise Rejected(KinematicsErrorCodes.INVALID_MODE,
                           f"unknown mode {request.mode!r}; known: {', '.join(PATH_MODES)}")
        waypoints = np.array([[p.x, p.y, p.z] for p in request.waypoints], dtype=float).reshape(-1, 3)
        if len(waypoints) == 0 or not np.all(np.isfinite(waypoints)):
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           "waypoints: need at least one, all finite")
        if np.max(np.abs(waypoints)) > self.max_distance:
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"waypoints beyond {PLAUSIBILITY_FACTOR:g} x the machine's reach (|coordinate| <= "
                           f"{self.max_distance:.6g} m): implausible")
        for name, value in (("step", request.step), ("tip_speed", request.tip_speed)):
            if not (np.isfinite(value) and value >= 0.0):
                raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                               f"{name} {value} must be >= 0 (0 = the default)")
        seed = None
        if len(request.seed.name) or len(request.seed.position):
            try:
                seed, _ = joint_values(request.seed, self.joint_names, require_position=True)
            except InputError as error:
                raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"seed: {error}") from None
        try:
            plan = plan_path(self.model, waypoints, request.step or self.path["step"],
                             request.tip_speed or self.path["tip_speed"], self.path["acceleration"], seed)
        except ValueError as error:  # a request the planner refuses (e.g. too many points)
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS, str(error)) from None
        response.message = plan.message
        response.last_reachable_waypoint = plan.last_waypoint
        trajectory = JointTrajectory()
        trajectory.header.frame_id = self.frame
        trajectory.joint_names = list(self.joint_names)
        if plan.timing is not None:
            timing = plan.timing
            for t, q, qd, qdd in zip(timing.t, timing.q, timing.qd, timing.qdd, strict=True):
                nanoseconds = round(t * 1e9)
                stamp = Duration(sec=nanoseconds // 10**9, nanosec=nanoseconds % 10**9)
                trajectory.points.append(JointTrajectoryPoint(
                    positions=q.tolist(), velocities=qd.tolist(), accelerations=qdd.tolist(),
                    time_from_start=stamp))
        response.trajectory = trajectory
        if not plan.ok or plan.truncated:
            raise Rejected(KinematicsErrorCodes.NO_IK_SOLUTION, plan.message)
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS


def main(args: Sequence[str] | None = None) -> int:
    return run_node(ExcavatorIKServer, "excavator", NODE, args)


if __name__ == "__main__":
    raise SystemExit(main())
