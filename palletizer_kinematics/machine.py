"""The palletizer in the machine registry (entry point ``palletizer``).

Its joints are the configured variant's axis angles (axis_1, axis_2, axis_3, axis_6 by default):
what the motors and the controller's joint states report, and what the catalogue's limits are
given in. The bag hooks are the shared serial-machine ones (``evaluate`` recomputes tool_pose and
tool_twist from joint_states; golden bag test/data/palletizer_forward_golden).
"""

from manipulator_kinematics.bag import analysis, synthetic
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.scene import serial_scene
from manipulator_kinematics.urdf import serial_urdf
from palletizer_kinematics.kinematics import CONFIG_FILE, SCHEMA, SECTION, Palletizer

MACHINE = Machine(
    name="palletizer",
    summary="ABB IRB460-type palletizer (paper 004): single/double parallelogram, closed-form IK in "
    "axis angles, door trajectory, axis 2/3 statics",
    section=SECTION,
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=Palletizer.from_parameters,
    topics={
        "joint_states": "sensor_msgs/msg/JointState",
        "tool_pose": "geometry_msgs/msg/PoseStamped",
        "tool_twist": "geometry_msgs/msg/TwistStamped",
    },
    analyse=analysis.serial,
    synthesize=synthetic.serial_bag,
    forward_node="palletizer_forward",
    # axis angles -> D-H angles (affine); the passive flange joint becomes two mimic joints
    urdf=lambda model: serial_urdf("palletizer", model, to_chain=model.dh_angles),
    scene=serial_scene,
)
