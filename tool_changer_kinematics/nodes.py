"""Console scripts of the tool changer: the generic nodes of manipulator_kinematics.nodes.

* ``tool_changer_forward``: joint_states -> tool_pose, tool_twist (gripper frame, J qd).
* ``tool_changer_ik_server``: solve_ik (every closed-form solution; branches
  ``front|back``_``up|down``_``noflip|flip``) and solve_fk.
"""

from collections.abc import Sequence

from manipulator_kinematics.nodes import forward_main, ik_server_main


def forward(args: Sequence[str] | None = None) -> int:
    return forward_main("tool_changer", "tool_changer_forward", args)


def ik_server(args: Sequence[str] | None = None) -> int:
    return ik_server_main("tool_changer", "tool_changer_ik_server", args)
