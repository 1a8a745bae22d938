"""The registry record of a serial machine, written once: every serial machine of the package runs
the generic forward node (``joint_states`` -> ``tool_pose``, ``tool_twist``), is checked in bags
by the generic analysis and golden bag, and is drawn from its D-H chain and frames."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from manipulator_kinematics.registry import Hook, Machine
from manipulator_kinematics.schema import Schema

#: The topics of the generic forward node (manipulator_kinematics.nodes.forward).
SERIAL_TOPICS = {
    "joint_states": "sensor_msgs/msg/JointState",
    "tool_pose": "geometry_msgs/msg/PoseStamped",
    "tool_twist": "geometry_msgs/msg/TwistStamped",
}


def serial_machine(
    name: str,
    summary: str,
    section: str,
    config_file: str,
    schema: Schema,
    factory: Callable[[dict[str, Any]], Any],
    to_chain: Callable[[Any], Callable[[np.ndarray], np.ndarray]] | None = None,
) -> Machine:
    """The Machine of a SerialModel whose forward node is ``<name>_forward``. ``to_chain(model)``
    maps the model's joints to its D-H chain's (for the URDF) where they differ (the palletizer's
    axis angles)."""

    serial_urdf = Hook("manipulator_kinematics.urdf:serial_urdf")

    def urdf(model: Any) -> str:
        # The robot name is the machine file's ``name`` (several machines, several names).
        return serial_urdf(model.name, model, to_chain=None if to_chain is None else to_chain(model))

    return Machine(
        name=name,
        summary=summary,
        section=section,
        config_file=config_file,
        schema=schema,
        factory=factory,
        topics=SERIAL_TOPICS,
        analyse=Hook("manipulator_kinematics.bag.analysis:serial"),
        synthesize=Hook("manipulator_kinematics.bag.synthetic:serial_bag"),
        forward_node=f"{name}_forward",
        urdf=urdf,
        scene=Hook("manipulator_kinematics.scene:serial_scene"),
    )
