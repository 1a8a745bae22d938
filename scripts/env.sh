# Sourced by scripts/test.sh and scripts/demo.sh after bootstrap: puts the project's venv first.
# Nothing ROS-specific is needed at run time: the venv's python finds rclpy, the message types
# and manipulator_kinematics_interfaces by itself (the ros-wheels-bootstrapper .pth re-executes
# python with LD_LIBRARY_PATH covering <venv>/lib and the wheels' libraries), so no setup.bash,
# AMENT_PREFIX_PATH or LD_LIBRARY_PATH is set here on purpose: `<venv>/bin/python` alone works
# the same way as these commands.
MK_REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
MK_VENV_DIR="${MK_VENV:-$MK_REPO/.venv}"
MK_VENV_DIR="$(cd "$MK_VENV_DIR" && pwd)"
export VIRTUAL_ENV="$MK_VENV_DIR"
export PATH="$MK_VENV_DIR/bin:$PATH"
unset PYTHONHOME
# Commands started by hand (the README's examples) stay on this machine, in the project's own
# domain, unless you set these yourself (manipulator_kinematics/ros_domain.py: EXAMPLES_DOMAIN).
# The demo and the tests each reserve a free domain of their own instead.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-101}"
