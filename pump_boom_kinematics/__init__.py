"""Concrete pump-truck boom (paper 001): plane geometry, region-planning IK, straight-line pours.

numpy core (no rclpy): :mod:`.kinematics` (the boom), :mod:`.regions` (the region table and its
builder), :mod:`.pour` (straight-line pours and paths), :mod:`.plots` (the paper's figures).
"""

from manipulator_kinematics.stopping import install_for

# The first code of ours its console scripts run: a signal during the imports that follow ends
# them with exit 0 (manipulator_kinematics.stopping).
install_for("pump_boom_forward", "pump_boom_ik_server", "pump_boom_regions", "pump_boom_plots")
