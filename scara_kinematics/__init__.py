"""SCARA-type planar arm (P-R-R, Fu, Zhang, Qiu 2019): numpy core in ``kinematics``, rclpy nodes
``ik_server`` (SolveIK / SolveFK) and ``forward_node`` (joint_states -> tool pose and twist)."""
