"""Registry entry of the tool changer (manipulator_kinematics.registry); bag hooks to come."""

from manipulator_kinematics.bag import analysis, synthetic
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.scene import serial_scene
from manipulator_kinematics.urdf import serial_urdf
from tool_changer_kinematics.kinematics import CONFIG_FILE, SCHEMA, SECTION, ToolChanger

MACHINE = Machine(
    name="tool_changer",
    summary="TBM tool-changing 6R arm (paper 003): FK, Jacobian, closed-form IK with all 8 solutions",
    section=SECTION,
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=ToolChanger.from_parameters,
    topics={
        "joint_states": "sensor_msgs/msg/JointState",
        "tool_pose": "geometry_msgs/msg/PoseStamped",
        "tool_twist": "geometry_msgs/msg/TwistStamped",
    },
    analyse=analysis.serial,
    synthesize=synthetic.serial_bag,
    forward_node="tool_changer_forward",
    urdf=lambda model: serial_urdf("tool_changer", model),
    scene=serial_scene,
)
