"""Console scripts of the SCARA arm: the generic nodes of manipulator_kinematics.nodes.

* ``scara_forward``: joint_states -> tool_pose, tool_twist (the tool point (px, py, 0), heading
  phi about +z; its twist from the geometric Jacobian).
* ``scara_ik_server``: solve_ik (modes ``fixed_phi``, ``phi``, ``position``; branches
  ``elbow_a``, ``elbow_b``) and solve_fk.
"""

from collections.abc import Sequence

from manipulator_kinematics.nodes import forward_main, ik_server_main


def forward(args: Sequence[str] | None = None) -> int:
    return forward_main("scara", "scara_forward", args)


def ik_server(args: Sequence[str] | None = None) -> int:
    return ik_server_main("scara", "scara_ik_server", args)
