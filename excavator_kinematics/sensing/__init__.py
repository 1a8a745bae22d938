"""Machine state from IMUs and the gravity-aligned level frame: the numpy model (``imu``), the
forward node's level pose (``level_pose``) and the IMU figure. Imports ``core`` only."""
