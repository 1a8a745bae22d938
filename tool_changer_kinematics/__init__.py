"""TBM tool-changing 6R arm (paper 003): numpy core (kinematics), registry entry, ROS entry points."""

from manipulator_kinematics.stopping import install_for

# The first code of ours its console scripts run: a signal during the imports that follow ends
# them with exit 0 (manipulator_kinematics.stopping).
install_for("tool_changer_forward", "tool_changer_ik_server", "tool_changer_plots")
