#!/usr/bin/env bash
# Tests of the C and C++ API: installs what they need (a C and a C++ compiler and
# pkg-config, from Debian's packages, only if missing), then runs the crate's tests,
# which compile the examples and check programs and run them against a real dyfosd.
# Idempotent; fast when everything is there. Run from anywhere.
#
#   client/ffi/test.sh            # cargo test -p dyfos-ffi (its tests build dyfosd and dyfos if missing)
#   client/ffi/test.sh --deps     # only install the system tools (before `cargo test --workspace`)
#   client/ffi/test.sh --cmake    # also install cmake and test the CMake package (slower)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
missing=()
command -v cc >/dev/null || missing+=(gcc)
command -v c++ >/dev/null || missing+=(g++)
command -v pkg-config >/dev/null || missing+=(pkg-config)
[ "${1:-}" = "--cmake" ] && { command -v cmake >/dev/null || missing+=(cmake); }
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing ${missing[*]}"
  apt-get update -qq
  apt-get install -y -qq "${missing[@]}"
fi
[ "${1:-}" = "--deps" ] && exit 0
cd "$here/../.."
cargo test -p dyfos-ffi
if [ "${1:-}" = "--cmake" ]; then
  cargo test -p dyfos-ffi --test c_and_cpp -- --ignored the_cmake_package_finds_the_library
fi
