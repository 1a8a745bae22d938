"""The excavator's executables as the hydraulic family's: ``excavator_forward``,
``excavator_velocity_ik``, ``excavator_sim`` and ``excavator_ik_server`` given a family machine
file (its ``--params-file`` files hold a ``hydraulic_machine`` section and no ``excavator``
section, e.g. config/wheel_loader_wl20.yaml) run the family's node of that role
(:mod:`manipulator_kinematics.nodes.hydraulic`: ``hydraulic_forward`` and so on, under that name
and with its settings, config/hydraulic_nodes.yaml); anything else, a file with both sections
(config/excavator_cet200.yaml) included, runs the excavator's node (issue 31). The one place
the old names are dispatched."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

from excavator_kinematics.core.machine_file import SECTION
from manipulator_kinematics.hydraulic.description import SECTION as FAMILY_SECTION
from manipulator_kinematics.nodes import MachineNode, run_node
from manipulator_kinematics.param_files import ConfigError, given_parameters


def family_file(argv: Sequence[str]) -> bool:
    """Whether the params files of ``argv`` give a family machine and no excavator (a file that
    cannot be read is not: the excavator's node refuses it with the reason)."""
    try:
        given = given_parameters(argv)
    except (ConfigError, OSError, ValueError):
        return False
    return FAMILY_SECTION in given and SECTION not in given


def run(node_class: type[MachineNode], node_name: str, args: Sequence[str] | None) -> int:
    """The excavator's ``node_class`` as ``node_name``, or the family node of the same role
    (``excavator_x`` -> ``hydraulic_x``) for a family machine file (module docstring)."""
    argv = list(sys.argv if args is None else args)
    if family_file(argv):
        from manipulator_kinematics.nodes import hydraulic  # only a family run pays for its import

        role: Callable[[Sequence[str] | None], int] = getattr(hydraulic, node_name.removeprefix("excavator_"))
        return role(argv)
    return run_node(node_class, "excavator", node_name, args)
