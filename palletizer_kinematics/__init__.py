"""ABB IRB460-type palletizing robot (paper 004): single- and double-parallelogram variants.

numpy core in :mod:`palletizer_kinematics.kinematics` (chain, IK, axis angles) and
:mod:`palletizer_kinematics.statics` (axis 2/3 holding torques); no module here imports rclpy
except :mod:`palletizer_kinematics.messages` and :mod:`palletizer_kinematics.nodes`.
"""
