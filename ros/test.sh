#!/usr/bin/env bash
# The ROS 2 tests: dyfos_ros against real rclpy and Fast DDS (ros/dyfos_ros/test).
#
#   bash ros/test.sh [pytest args...]
#
# Builds the workspace (a no-op after scripts/test's build), installs ROS 2 jazzy,
# the interfaces, the binding the build made and dyfos_ros into target/ros-venv
# (ros/install.sh; seconds when it is there already), then runs pytest against
# target/debug's dyfosd and dyfos. DDS discovery stays on this machine
# (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST), each test takes a ROS domain id no other
# test holds, and ROS's logs go to target/ros-log.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=scripts/venv.sh
source "$here/../scripts/venv.sh"
venv="$target/ros-venv"

build_workspace
DYFOS_BINDING="$target/debug/lib_dyfos.so" bash "$here/install.sh" "$venv"
if ! "$venv/bin/python" -c "import pytest" 2>/dev/null; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "pytest>=7"
fi

# Another RMW than the one the wheels link exits with 102; a domain id from outside
# would put every test on one domain.
unset RMW_IMPLEMENTATION ROS_DOMAIN_ID ROS_LOCALHOST_ONLY
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ROS_LOG_DIR="$target/ros-log"
export DYFOSD="$target/debug/dyfosd" DYFOS="$target/debug/dyfos" DYFOS_TEST_DATA="$root/tests/data"
export DYFOS_ROS="$venv/bin/dyfos-ros"
run_pytest ros/test.sh "$here/dyfos_ros" "$venv/bin/python" test -p no:cacheprovider "$@"
