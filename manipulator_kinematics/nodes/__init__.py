"""The package's node bases and the generic nodes of serial machines (see base.py for the style).

A machine package's console scripts are two-line entry points::

    def forward(args=None) -> int:
        return forward_main("scara", "scara_forward", args)
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from manipulator_kinematics.node_util import run
from manipulator_kinematics.nodes.base import MachineNode
from manipulator_kinematics.nodes.help import help_text, wants_help
from manipulator_kinematics.registry import machine


def run_node(
    node_class: type[MachineNode], machine_name: str, node_name: str, args: Sequence[str] | None
) -> int:
    """Run ``node_class`` for the registered machine ``machine_name`` until SIGINT/SIGTERM;
    with ``-h``/``--help`` print what it does, its parameters, topics and services, and exit 0."""
    argv = list(sys.argv if args is None else args)
    if wants_help(argv):
        print(help_text(node_class, machine(machine_name), node_name, node_class.DEFAULTS_FILE))
        return 0
    return run(lambda: node_class(node_name, machine(machine_name), argv), argv)


def forward_main(machine_name: str, node_name: str, args: Sequence[str] | None = None) -> int:
    """joint_states -> tool_pose + tool_twist (:mod:`manipulator_kinematics.nodes.forward`)."""
    from manipulator_kinematics.nodes.forward import ForwardNode

    return run_node(ForwardNode, machine_name, node_name, args)


def ik_server_main(machine_name: str, node_name: str, args: Sequence[str] | None = None) -> int:
    """solve_ik + solve_fk (:mod:`manipulator_kinematics.nodes.ik_server`)."""
    from manipulator_kinematics.nodes.ik_server import IKServerNode

    return run_node(IKServerNode, machine_name, node_name, args)


__all__ = ["MachineNode", "forward_main", "ik_server_main", "run_node"]
