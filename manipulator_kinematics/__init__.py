"""Shared pieces of manipulator_kinematics: serial chains, planar solutions, trajectories,
parameter files, bag I/O and ROS node helpers. Machine packages (excavator_kinematics,
scara_kinematics, ...) build on these. Importing this package does not import rclpy."""
