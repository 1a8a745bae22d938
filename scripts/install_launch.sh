#!/usr/bin/env bash
# Install ROS 2 launch and launch_ros (pure Python) into the project's venv from local checkouts
# of github.com/ros2/launch and github.com/ros2/launch_ros on their jazzy branch, so that
# test/test_launch_service.py runs the launch files through LaunchService (README, "Launch files").
#   bash scripts/install_launch.sh PATH/TO/launch PATH/TO/launch_ros
# e.g. after: git clone -b jazzy https://github.com/ros2/launch; git clone -b jazzy https://github.com/ros2/launch_ros
# Their dependencies outside the venv's lock: osrf_pycommon and lifecycle_msgs (PyPI wheels);
# composition_interfaces has no wheel: test/test_launch_service.py gives launch_ros an empty
# stand-in (composable nodes only, which the launch files do not use).
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: $0 LAUNCH_CHECKOUT LAUNCH_ROS_CHECKOUT" >&2; exit 2; }
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PYV="${MK_VENV:-$REPO/.venv}/bin/python"
LAUNCH="$(cd "$1" && pwd)"; LAUNCH_ROS="$(cd "$2" && pwd)"
for dir in "$LAUNCH/launch" "$LAUNCH/launch_xml" "$LAUNCH/launch_yaml" "$LAUNCH_ROS/launch_ros"; do
    [ -f "$dir/setup.py" ] || { echo "no $dir/setup.py: give the repository roots" >&2; exit 2; }
done
"$PYV" -m pip install -q --disable-pip-version-check osrf-pycommon ros-jazzy-lifecycle-msgs==2.0.3
# --no-deps: their other dependencies (ament_index_python, rclpy, lark, PyYAML) are in the lock.
"$PYV" -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation \
    "$LAUNCH/launch" "$LAUNCH/launch_xml" "$LAUNCH/launch_yaml" "$LAUNCH_ROS/launch_ros"
"$PYV" -c 'import launch, launch_xml; print("launch and launch_ros installed; run: python -m pytest test/test_launch_service.py")'
