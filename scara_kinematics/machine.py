"""The SCARA-type arm in the machine registry (entry point ``scara``)."""

from manipulator_kinematics.serial_machine import serial_machine
from scara_kinematics.kinematics import CONFIG_FILE, SCHEMA, Scara

MACHINE = serial_machine(
    name="scara",
    summary="SCARA-type P-R-R planar arm (paper 002): FK, IK in three modes, Jacobian",
    section="scara",
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=Scara.from_parameters,
)
