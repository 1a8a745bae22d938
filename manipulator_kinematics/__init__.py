"""Shared pieces of manipulator_kinematics: serial chains, planar solutions, trajectories,
parameter files, bag I/O and ROS node helpers. Machine packages (excavator_kinematics,
scara_kinematics, ...) build on these. Importing this package does not import rclpy."""

from manipulator_kinematics.stopping import install_for

# The first code of ours its console scripts run: a signal during the imports that follow ends
# them with exit 0 (manipulator_kinematics.stopping).
install_for(
    "mk_record",
    "mk_replay",
    "mk_evaluate",
    "mk_asbuilt",
    "mk_urdf",
    "machine_markers",
    "mk_machine_check",
    "mk_calibrate",
    "hydraulic_forward",
    "hydraulic_velocity_ik",
    "hydraulic_sim",
    "hydraulic_ik_server",
)
