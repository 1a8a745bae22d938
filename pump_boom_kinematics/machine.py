"""The pump-truck boom in the machine registry (entry point ``pump_boom``): the generic serial
bag hooks (``evaluate`` recomputes the tip from recorded joint states; the golden bag of
``pump_boom_forward`` is made by ``serial_bag``)."""

from manipulator_kinematics.serial_machine import serial_machine
from pump_boom_kinematics.kinematics import CONFIG_FILE, SCHEMA, SECTION, PumpBoom

MACHINE = serial_machine(
    name="pump_boom",
    summary="Five-section concrete pump-truck boom (paper 001): FK, tip Jacobian, region-planning IK, pours",
    section=SECTION,
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=PumpBoom.from_parameters,
)
