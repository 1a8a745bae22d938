"""The pump-truck boom in the machine registry (entry point ``pump_boom``): the generic serial
bag hooks (``evaluate`` recomputes the tip from recorded joint states; the golden bag of
``pump_boom_forward`` is made by ``serial_bag``)."""

from manipulator_kinematics.bag import analysis, synthetic
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.scene import serial_scene
from manipulator_kinematics.urdf import serial_urdf
from pump_boom_kinematics.kinematics import CONFIG_FILE, SCHEMA, SECTION, PumpBoom

MACHINE = Machine(
    name="pump_boom",
    summary="Five-section concrete pump-truck boom (paper 001): FK, tip Jacobian, region-planning IK, pours",
    section=SECTION,
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=PumpBoom.from_parameters,
    topics={
        "joint_states": "sensor_msgs/msg/JointState",
        "tool_pose": "geometry_msgs/msg/PoseStamped",
        "tool_twist": "geometry_msgs/msg/TwistStamped",
    },
    analyse=analysis.serial,
    synthesize=synthetic.serial_bag,
    forward_node="pump_boom_forward",
    urdf=lambda model: serial_urdf("pump_boom", model),
    scene=serial_scene,
)
