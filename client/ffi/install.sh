#!/usr/bin/env bash
# Installs the dyfos C API under PREFIX: lib/libdyfos.{so,a}, include/dyfos.h and
# dyfos.hpp, lib/pkgconfig/dyfos.pc and lib/cmake/dyfos/dyfosConfig.cmake.
#
#   client/ffi/install.sh /usr/local        # builds the release library first
#   PKG_CONFIG_PATH=/usr/local/lib/pkgconfig pkg-config --cflags --libs dyfos
#
# DYFOS_LIB_DIR=DIR takes the libraries from DIR instead of building them;
# DYFOS_INSTALL_SYMLINK=1 links them instead of copying (the tests use both).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
prefix=${1:?usage: install.sh PREFIX}
mkdir -p "$prefix"
prefix=$(cd "$prefix" && pwd)
libs=${DYFOS_LIB_DIR:-}
if [ -z "$libs" ]; then
  cargo build --release -p dyfos-ffi --manifest-path "$here/../../Cargo.toml"
  libs="${CARGO_TARGET_DIR:-$here/../../target}/release"
fi
version=$(sed -n 's/^version = "\(.*\)"/\1/p' "$here/../../Cargo.toml" | head -n 1)
mkdir -p "$prefix/lib/pkgconfig" "$prefix/lib/cmake/dyfos" "$prefix/include"
for lib in libdyfos.so libdyfos.a; do
  rm -f "$prefix/lib/$lib"
  if [ "${DYFOS_INSTALL_SYMLINK:-0}" = 1 ]; then
    ln -s "$libs/$lib" "$prefix/lib/$lib"
  else
    cp "$libs/$lib" "$prefix/lib/$lib"
  fi
done
cp "$here/include/dyfos.h" "$here/include/dyfos.hpp" "$prefix/include/"
sed -e "s|@PREFIX@|$prefix|" -e "s|@LIBDIR@|$prefix/lib|" -e "s|@INCLUDEDIR@|$prefix/include|" \
  -e "s|@VERSION@|$version|" "$here/dyfos.pc.in" >"$prefix/lib/pkgconfig/dyfos.pc"
cp "$here/cmake/dyfosConfig.cmake" "$prefix/lib/cmake/dyfos/"
echo "installed the dyfos C API under $prefix"
