"""Console scripts of the palletizer: the generic nodes of manipulator_kinematics.nodes.

* ``palletizer_forward``: joint_states (axis angles) -> tool_pose, tool_twist of the TCP.
* ``palletizer_ik_server``: solve_ik (modes ``axis``, ``dh``; branches of
  :data:`palletizer_kinematics.kinematics.BRANCHES`) and solve_fk.
"""

from collections.abc import Sequence

from manipulator_kinematics.nodes import forward_main, ik_server_main


def forward(args: Sequence[str] | None = None) -> int:
    return forward_main("palletizer", "palletizer_forward", args)


def ik_server(args: Sequence[str] | None = None) -> int:
    return ik_server_main("palletizer", "palletizer_ik_server", args)
