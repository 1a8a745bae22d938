"""Hydraulic excavator kinematics (paper 000) and its ROS 2 nodes.

The numpy core is :mod:`excavator_kinematics.kinematics` (no rclpy); nodes are thin adapters.
"""
