"""The tool changer in the machine registry (entry point ``tool_changer``)."""

from manipulator_kinematics.serial_machine import serial_machine
from tool_changer_kinematics.kinematics import CONFIG_FILE, SCHEMA, SECTION, ToolChanger

MACHINE = serial_machine(
    name="tool_changer",
    summary="TBM tool-changing 6R arm (paper 003): FK, Jacobian, closed-form IK with all 8 solutions",
    section=SECTION,
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=ToolChanger.from_parameters,
)
