"""``excavator_ik_server``: the shared IK/FK server (:mod:`manipulator_kinematics.nodes.ik_server`)
for the excavator, in the actuator coordinates D = [theta1, d2, d3, d4].

* ``solve_ik``: a bucket pose -> D (joints ``swing_joint`` rad, ``boom_cylinder``,
  ``arm_cylinder``, ``bucket_cylinder`` lengths m, as on ``cylinder_lengths`` / ``joint_states``),
  closed form (:mod:`excavator_kinematics.inverse`). Mode ``pose`` (default with
  ``use_orientation``): the orientation gives the swing heading and the bucket angle alpha;
  mode ``position`` (default without): alpha of the seed, else the widest stroke margin. Branches
  ``front_elbow_up``, ``front_elbow_down``, ``behind_elbow_up``, ``behind_elbow_down``.
* ``solve_fk``: D (and its rates) -> bucket pose (the tip; yaw theta1, then -alpha about y) and
  twist (eq. 8 and the bucket frame's turn).

Settings in config/excavator_nodes.yaml (``/**/excavator_ik_server``).
"""

from __future__ import annotations

from collections.abc import Sequence

from excavator_kinematics.node_settings import NODES_CONFIG
from manipulator_kinematics.nodes import run_node
from manipulator_kinematics.nodes.ik_server import IKServerNode

NODE = "excavator_ik_server"


class ExcavatorIKServer(IKServerNode):
    """The shared SolveIK / SolveFK server, its settings in the excavator nodes' file."""

    DEFAULTS_FILE = NODES_CONFIG


def main(args: Sequence[str] | None = None) -> int:
    return run_node(ExcavatorIKServer, "excavator", NODE, args)


if __name__ == "__main__":
    raise SystemExit(main())
