"""TBM tool-changing 6R arm (paper 003): numpy core (kinematics), registry entry, ROS entry points."""
