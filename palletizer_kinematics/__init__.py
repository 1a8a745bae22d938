"""ABB IRB460-type palletizing robot (paper 004): single- and double-parallelogram variants.

numpy core in :mod:`palletizer_kinematics.kinematics` (chain, IK, axis angles) and
:mod:`palletizer_kinematics.statics` (axis 2/3 holding torques); no module here imports rclpy
except :mod:`palletizer_kinematics.trajectory_message` and :mod:`palletizer_kinematics.nodes`.
"""

from manipulator_kinematics.stopping import install_for

# The first code of ours its console scripts run: a signal during the imports that follow ends
# them with exit 0 (manipulator_kinematics.stopping).
install_for("palletizer_forward", "palletizer_ik_server", "palletizer_plots")
