"""The SCARA-type arm in the machine registry (entry point ``scara``)."""

from manipulator_kinematics.bag import analysis, synthetic
from manipulator_kinematics.registry import Machine
from manipulator_kinematics.scene import serial_scene
from manipulator_kinematics.urdf import serial_urdf
from scara_kinematics.kinematics import CONFIG_FILE, SCHEMA, Scara

MACHINE = Machine(
    name="scara",
    summary="SCARA-type P-R-R planar arm (paper 002): FK, IK in three modes, Jacobian",
    section="scara",
    config_file=CONFIG_FILE,
    schema=SCHEMA,
    factory=Scara.from_parameters,
    topics={
        "joint_states": "sensor_msgs/msg/JointState",
        "tool_pose": "geometry_msgs/msg/PoseStamped",
        "tool_twist": "geometry_msgs/msg/TwistStamped",
    },
    analyse=analysis.serial,
    synthesize=synthetic.serial_bag,
    forward_node="scara_forward",
    urdf=lambda model: serial_urdf("scara", model),
    scene=serial_scene,
)
