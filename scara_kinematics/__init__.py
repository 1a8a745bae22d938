"""SCARA-type planar arm (P-R-R, Fu, Zhang, Qiu 2019): numpy core in ``kinematics``, rclpy nodes
``ik_server`` (SolveIK / SolveFK) and ``forward_node`` (joint_states -> tool pose and twist)."""

from manipulator_kinematics.stopping import install_for

# The first code of ours its console scripts run: a signal during the imports that follow ends
# them with exit 0 (manipulator_kinematics.stopping).
install_for("scara_forward", "scara_ik_server")
