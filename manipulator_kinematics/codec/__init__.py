"""Serialized ROS 2 messages read and written with numpy and struct, without rclpy's conversion."""
