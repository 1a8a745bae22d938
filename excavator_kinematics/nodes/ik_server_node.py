"""``excavator_ik_server``: the shared IK/FK server (:mod:`manipulator_kinematics.nodes.ik_server`)
for the excavator, in the actuator coordinates D = [theta1, d2, d3, d4], plus ``plan_path``.

Joint values in requests and answers (seeds, solutions, solve_fk's state, plan_path's positions)
are the sensors' readings, as on ``cylinder_lengths`` / ``joint_states``: the true state D =
reading + zero_offset (the machine file's) is what the kinematics and the stroke box see.

* ``solve_ik``: a bucket pose -> D (joints ``swing_joint`` rad, ``boom_cylinder``,
  ``arm_cylinder``, ``bucket_cylinder`` lengths m),
  closed form (:mod:`excavator_kinematics.core.inverse`). Mode ``pose`` (default with
  ``use_orientation``): the orientation gives the swing heading and the bucket angle alpha;
  mode ``position`` (default without): alpha of the seed, else the widest stroke margin. Branches
  ``front_elbow_up``, ``front_elbow_down``, ``behind_elbow_up``, ``behind_elbow_down``.
* ``solve_fk``: D (and its rates) -> bucket pose (the tip; yaw theta1, then -alpha about y) and
  twist (eq. 8 and the bucket frame's turn).
* ``plan_path`` (manipulator_kinematics_interfaces/srv/PlanPath): straight bucket-tip lines through
  the waypoints at the bucket angle of the seed (else of the first waypoint's solution), timed
  within every actuator's max speed, the tip speed and ``path.acceleration``, at rest at both
  ends (:mod:`excavator_kinematics.core.path`); positions, velocities and accelerations. A path that
  leaves the workspace ends at the farthest reachable point: success false (NO_IK_SOLUTION), the
  reason, ``last_reachable_waypoint`` and the trajectory up to there. A request beyond the bounds
  of every machine's plan (:mod:`manipulator_kinematics.plan_bounds`: waypoints, points, duration,
  the ranges of step, speed and acceleration) is refused before any work, INVALID_GOAL_CONSTRAINTS.
  With ``zones_file`` set, a path on which a monitored point would enter an avoidance zone ends
  before it, with the reason (:mod:`excavator_kinematics.core.path_zones`). Site-frame zones are
  placed by the ``site`` settings (:class:`manipulator_kinematics.nodes.site_pose.SitePoseInput`):
  the fixed pose, or the latest on ``topics.site_pose`` if its stamp is at most
  ``site_pose_max_age`` from now; without a fresh one a plan is refused (FAILURE, the reason):
  a path the zones cannot be checked on is not planned. The planned path's swing changes the
  cab's tilt but not base_link's, so the site pose (its own roll and pitch) is used as it is.

Settings in config/excavator_nodes.yaml (``/**/excavator_ik_server``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from excavator_kinematics.core.monitored import MonitoredPoints
from excavator_kinematics.core.path import BucketPlan
from excavator_kinematics.core.path_zones import plan_clear
from excavator_kinematics.grade.design_surface import read_landxml
from excavator_kinematics.nodes import family
from excavator_kinematics.nodes.node_schemas import NODES_CONFIG, SITE_POSE
from manipulator_kinematics.node_util import ThrottledLog
from manipulator_kinematics.nodes.ik_server import PATH_SETTINGS, SETTINGS, PlanPathServer, Rejected
from manipulator_kinematics.nodes.site_pose import SitePoseInput
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.schema import Number, Schema, Text
from manipulator_kinematics.zone_guard import ZoneGuard
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import PlanPath, SolveFK, SolveIK

NODE = "excavator_ik_server"


class ExcavatorIKServer(PlanPathServer):
    """The shared SolveIK / SolveFK / PlanPath server, settings in the excavator nodes' file."""

    DEFAULTS_FILE = NODES_CONFIG
    SETTINGS: ClassVar[Schema] = {
        **SETTINGS,
        "path": PATH_SETTINGS,
        "zones_file": Text(
            doc="avoidance zone file (docs/zones.md): plan_path ends before a zone; empty: none"
        ),
        "site": SITE_POSE,
        "warning_period": Number(
            min=0.0, max=3600.0, unit="s", doc="the same kind of rejection is logged at most this often"
        ),
        "topics": {
            "site_pose": Text(
                empty=False, doc="input: geometry_msgs/PoseStamped, base_link in the site frame (GNSS)"
            )
        },
    }
    #: IK mode of every path sample: the bucket angle is held, so the pose IK.
    PLAN_MODES = ("pose",)

    def __init__(self, node_name: str, machine: Machine, argv: Sequence[str]) -> None:
        super().__init__(node_name, machine, argv)
        self.path = self.settings["path"]
        path = self.path
        self.points = MonitoredPoints(self.model)
        file = self.settings["zones_file"]
        self.zones = (
            ZoneGuard.from_file(
                file, self.points.names, self.model.limits.max_rates, 1.0, read_landxml, site_pose=True
            ).zones
            if file
            else []
        )
        site = [z.name for z in self.zones if z.frame == "site"]
        # Only a node with site-frame zones listens for the site pose.
        self.site = (
            SitePoseInput(
                self,
                self.settings["site"],
                self.settings["topics"]["site_pose"],
                QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE),
                ThrottledLog(self, self.settings["warning_period"]),
            )
            if site
            else None
        )
        self.site_zones = ", ".join(site)
        self.get_logger().info(
            f"serving plan_path (defaults: step {path['step']:g} m, tip speed "
            f"{path['tip_speed']:g} m/s, acceleration {path['acceleration']:g} m/s^2)"
        )

    # The services speak the sensors' readings (as joint_states / cylinder_lengths carry them);
    # the kinematics true states D = reading + zero_offset (Excavator.true_state / readings).
    def _seed(self, seed: JointState, names: Sequence[str]) -> np.ndarray | None:
        q = super()._seed(seed, names)
        return None if q is None else q + self.model.zero_offset

    def _solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> None:
        super()._solve_ik(request, response)
        for state in (response.solution, *response.solutions):
            state.position = self.model.readings(state.position).tolist()

    def _solve_fk(self, request: SolveFK.Request, response: SolveFK.Response) -> None:
        state = request.joint_state
        if len(state.position) == len(state.name) == len(self.joint_names):
            # By name: the message's order is the sender's. A malformed state goes through as it
            # is, for the shared check to name what is wrong.
            offset = dict(zip(self.joint_names, self.model.zero_offset.tolist(), strict=True))
            state.position = [v + offset.get(n, 0.0) for n, v in zip(state.name, state.position, strict=True)]
        super()._solve_fk(request, response)

    def _plan_path(self, request: PlanPath.Request, response: PlanPath.Response) -> None:
        try:
            super()._plan_path(request, response)
        finally:  # a path that ends short is answered with its trajectory too
            # Not wrapped: a continuous swing's path runs on through +-pi.
            for point in response.trajectory.points:
                point.positions = (np.asarray(point.positions) - self.model.zero_offset).tolist()

    def plan(self, request: PlanPath.Request, waypoints: np.ndarray, seed: np.ndarray | None) -> BucketPlan:
        site = None
        if self.site is not None:
            pose, why = self.site.at(self.get_clock().now().nanoseconds)
            if pose is None:
                raise Rejected(
                    KinematicsErrorCodes.FAILURE,
                    f"no plan: site-frame zone(s) {self.site_zones} cannot be checked: {why}",
                )
            site = (pose.rotation, pose.translation)
        # 0 = the default; anything else (negative, NaN, tiny, huge) the shared bounds check.
        return plan_clear(
            self.model,
            self.points,
            self.zones,
            waypoints,
            request.step or self.path["step"],
            request.tip_speed or self.path["tip_speed"],
            self.path["acceleration"],
            seed,
            site,
        )


def main(args: Sequence[str] | None = None) -> int:
    return family.run(ExcavatorIKServer, NODE, args)  # a family machine file runs the family node


if __name__ == "__main__":
    raise SystemExit(main())
