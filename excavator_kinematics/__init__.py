"""Hydraulic excavator kinematics (paper 000) and its ROS 2 nodes.

The numpy core is :mod:`excavator_kinematics.core.kinematics` (no rclpy); nodes are thin adapters.
"""

from manipulator_kinematics.stopping import install_for

# The first code of ours its console scripts run: a signal during the imports that follow ends
# them with exit 0 (manipulator_kinematics.stopping).
install_for(
    "excavator_forward",
    "excavator_velocity_ik",
    "excavator_sim",
    "excavator_ik_server",
    "excavator_imu_state",
    "excavator_demo",
    "excavator_slope_example",
    "excavator_working_ranges",
)
