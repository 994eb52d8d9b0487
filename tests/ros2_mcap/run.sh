#!/usr/bin/env bash
# The ROS 2 profile of the mission MCAP files, decoded by an independent reader:
# runs `dyfos demo --mcap-profile foxglove,ros2` (the workspace's debug build) and
# checks with Foxglove's `mcap-ros2-support` that each ROS 2 file says what its
# Foxglove twin says (test_ros2_mcap.py).
#
#   tests/ros2_mcap/run.sh [pytest args...]
#
# Needs Python >= 3.9 with venv; installs pytest, mcap and mcap-ros2-support (pure
# Python wheels, about 1 MB) into a venv under the cargo target dir the first time.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=scripts/venv.sh
source "$here/../../scripts/venv.sh"
venv="$target/ros2-mcap-venv"

venv_with "$venv" "pytest, mcap, mcap_ros2" "pytest>=7" "mcap>=1.1,<2" "mcap-ros2-support>=0.5,<1"

# The demo and the processes it starts.
build_workspace

# No __pycache__ in the source tree.
export PYTHONDONTWRITEBYTECODE=1
export DYFOS="$target/debug/dyfos" DYFOS_TEST_DATA="$root/tests/data"
run_pytest tests/ros2_mcap/run.sh "$here" "$venv/bin/python" -p no:cacheprovider "$@"
