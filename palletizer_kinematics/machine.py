"""The palletizer in the machine registry (entry point ``palletizer``).

Its joints are the configured variant's axis angles (axis_1, axis_2, axis_3, axis_6 by default):
what the motors and the controller's joint states report, and what the catalogue's limits are
given in. The bag hooks are the shared serial-machine ones (``evaluate`` recomputes tool_pose and
tool_twist from joint_states; golden bag test/data/palletizer_forward_golden).
"""

from manipulator_kinematics.serial_machine import serial_machine
from palletizer_kinematics.kinematics import CONFIG_FILE, SCHEMA, SECTION, Palletizer

MACHINE = serial_machine(
    name="palletizer",
    summary="ABB IRB460-type palletizer (paper 004): single/double parallelogram, closed-form IK in "
    "axis angles, door trajectory, axis 2/3 statics",
    section=SECTION,
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=Palletizer.from_parameters,
    to_chain=lambda model: model.dh_angles,
)
