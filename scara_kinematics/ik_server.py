"""SolveIK / SolveFK services of the SCARA arm: a thin rclpy adapter over scara_kinematics.kinematics.

Services (relative names, so they can be namespaced or remapped):

* ``solve_ik`` (manipulator_kinematics_interfaces/SolveIK): modes ``fixed_phi`` (the paper's
  phi = 90 deg), ``phi`` (heading from the target's orientation), ``position`` (heading by the
  rule of the core: the seed's, else the nearest admissible); empty mode = ``phi`` when
  ``use_orientation`` else ``position``. Branches ``elbow_a`` / ``elbow_b``; empty = closest to
  the seed.
* ``solve_fk`` (SolveFK): pose of the tool point and, with velocities, its twist; output stamp =
  the joint state's stamp.

Every bad request (NaN, unreachable, outside the joint limits, singular, unknown mode or branch,
foreign frame) is answered with success = false, an error code and a reason; nothing a client
sends can stop the server. Parameters: the ``scara.*`` machine (config/scara.yaml) and
``base_frame``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from rclpy.node import Node

from manipulator_kinematics.joint_state import joint_values
from manipulator_kinematics.node_util import machine_parameters, make_node, node_parameters, run
from manipulator_kinematics.planar import quaternion_yaw
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK
from scara_kinematics.kinematics import BRANCHES, CONFIG_FILE, MODES, PAPER_PHI, IKStatus, Scara
from scara_kinematics.messages import joint_state, tool_pose, tool_twist

#: |z| of a target (m) and tilt / heading mismatch of a target orientation (rad) taken as zero.
PLANE_TOL = 1e-6

_CODES = {
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


class ScaraIKServer:
    """Owns the model and answers both services on ``node``."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.scara = Scara.from_parameters(machine_parameters(node, "scara", CONFIG_FILE))
        self.base_frame = str(node_parameters(node, CONFIG_FILE, "scara_ik_server")["base_frame"])
        node.create_service(SolveIK, "solve_ik", self.solve_ik)
        node.create_service(SolveFK, "solve_fk", self.solve_fk)
        node.get_logger().info(
            f"SCARA l1 = {self.scara.l1} m, l2 = {self.scara.l2} m, l3 = {self.scara.l3} m, joints "
            f"{list(self.scara.joint_names)}, frame {self.base_frame!r}: serving solve_ik, solve_fk"
        )

    # ---- SolveIK ------------------------------------------------------------------------------
    def solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> SolveIK.Response:
        return self._answer(self._solve_ik, request, response)

    def _solve_ik(self, request: SolveIK.Request, response: SolveIK.Response) -> None:
        mode = request.mode or ("phi" if request.use_orientation else "position")
        if mode not in MODES:
            raise Rejected(KinematicsErrorCodes.INVALID_MODE,
                           f"unknown mode {mode!r}; known: {', '.join(MODES)}")
        branch = request.branch or None
        if branch is not None and branch not in BRANCHES:
            raise Rejected(KinematicsErrorCodes.INVALID_MODE,
                           f"unknown branch {branch!r}; known: {', '.join(BRANCHES)} "
                           "(empty = closest to the seed)")
        self._check_frame(request.target.header.frame_id)
        p = request.target.pose.position
        if not all(math.isfinite(v) for v in (p.x, p.y, p.z)):
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"target position is not finite: ({p.x}, {p.y}, {p.z})")
        if abs(p.z) > PLANE_TOL:
            raise Rejected(KinematicsErrorCodes.NO_IK_SOLUTION,
                           f"target z = {p.z:.6g} m: the arm moves in the plane z = 0 of {self.base_frame!r}")
        phi = self._target_heading(request, mode)
        seed = None
        if len(request.seed.name) or len(request.seed.position):
            try:
                seed, _ = joint_values(request.seed, self.scara.joint_names, require_position=True)
            except ValueError as error:
                raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"seed: {error}") from None
        result = self.scara.ik([p.x, p.y], mode=mode, phi=phi, seed=seed, branch=branch)
        status = IKStatus(int(result.status))
        response.message = result.reason()
        if status is not IKStatus.SUCCESS:
            raise Rejected(_CODES[status], response.message)
        stamp = self.node.get_clock().now().to_msg()
        chosen = int(result.branch)
        order = [chosen] + [b for b in range(2) if b != chosen and result.valid[b]]
        response.solution = joint_state(stamp, self.scara.joint_names, result.q)
        response.solutions = [joint_state(stamp, self.scara.joint_names, result.candidates[b]) for b in order]
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS

    def _target_heading(self, request: SolveIK.Request, mode: str) -> float | None:
        """phi for mode ``phi``, else None; refuses an orientation that contradicts the mode."""
        if mode == "phi" and not request.use_orientation:
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           "mode 'phi' takes the heading from the target orientation: set use_orientation")
        if not request.use_orientation:
            return None
        if mode == "position":
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           "mode 'position' leaves the heading free: use mode 'phi' to give an orientation")
        o = request.target.pose.orientation
        quaternion = np.array([o.x, o.y, o.z, o.w])
        if not np.all(np.isfinite(quaternion)) or np.linalg.norm(quaternion) < 1e-9:
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"target orientation is not a rotation: {quaternion.tolist()}")
        yaw, tilt = (float(v) for v in quaternion_yaw(quaternion))
        if tilt > PLANE_TOL:
            raise Rejected(KinematicsErrorCodes.NO_IK_SOLUTION,
                           f"target orientation tilts the tool z axis by {math.degrees(tilt):.6g} deg: "
                           "the arm only turns about base z")
        if mode == "fixed_phi" and abs(math.remainder(yaw - PAPER_PHI, 2 * math.pi)) > PLANE_TOL:
            raise Rejected(KinematicsErrorCodes.INVALID_GOAL_CONSTRAINTS,
                           f"mode 'fixed_phi' holds phi = 90 deg but the target heading is "
                           f"{math.degrees(yaw):.6g} deg: use mode 'phi' or clear use_orientation")
        return yaw if mode == "phi" else None

    # ---- SolveFK ------------------------------------------------------------------------------
    def solve_fk(self, request: SolveFK.Request, response: SolveFK.Response) -> SolveFK.Response:
        return self._answer(self._solve_fk, request, response)

    def _solve_fk(self, request: SolveFK.Request, response: SolveFK.Response) -> None:
        self._check_frame(request.frame_id)
        try:
            q, qd = joint_values(request.joint_state, self.scara.joint_names, require_position=True)
        except ValueError as error:
            raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE, f"joint_state: {error}") from None
        if not self.scara.within_limits(q):
            raise Rejected(KinematicsErrorCodes.JOINT_LIMITS_VIOLATED,
                           "joint_state outside the limits: "
                           + self.scara.describe(q, IKStatus.JOINT_LIMITS, 0.0))
        x = self.scara.fk(q)
        xd = np.zeros(3) if qd is None else self.scara.velocity_fk(q, qd)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(xd))):
            raise Rejected(KinematicsErrorCodes.INVALID_ROBOT_STATE,
                           "joint_state gives a non-finite pose or twist")
        stamp = request.joint_state.header.stamp
        response.pose = tool_pose(stamp, self.base_frame, x)
        response.twist = tool_twist(stamp, self.base_frame, xd)
        response.success = True
        response.error_code.val = KinematicsErrorCodes.SUCCESS
        response.message = (f"near the singularity: |cos theta1| = {abs(math.cos(q[1])):.3g}"
                            if self.scara.singular(q) else "")

    # ---- common -------------------------------------------------------------------------------
    def _check_frame(self, frame_id: str) -> None:
        if frame_id not in ("", self.base_frame):
            raise Rejected(KinematicsErrorCodes.FRAME_TRANSFORM_FAILURE,
                           f"frame {frame_id!r} is not the base frame {self.base_frame!r} "
                           "(no TF lookup here)")

    def _answer(self, solve, request, response):
        try:
            solve(request, response)
        except Rejected as rejection:
            response.success = False
            response.error_code.val = rejection.code
            response.message = rejection.message
        except Exception as error:
            self.node.get_logger().error(f"request failed unexpectedly: {error!r}")
            response.success = False
            response.error_code.val = KinematicsErrorCodes.FAILURE
            response.message = f"internal error: {error!r}"
        return response


def _create() -> Node:
    node = make_node("scara_ik_server")
    ScaraIKServer(node)  # the services hold its bound methods, so it lives as long as the node
    return node


def main(args: Sequence[str] | None = None) -> int:
    return run(_create, args)


if __name__ == "__main__":
    raise SystemExit(main())
