#!/usr/bin/env bash
# Installs the dyfos C API under PREFIX:
#   lib/libdyfos.so.<ABI> (the SONAME), lib/libdyfos.so -> it, lib/libdyfos.a,
#   include/dyfos.h and dyfos.hpp, lib/pkgconfig/dyfos.pc (relocatable: its prefix
#   is where the file lies), lib/cmake/dyfos/dyfosConfig.cmake and
#   dyfosConfigVersion.cmake (`find_package(dyfos 0.1)`).
#
# Usage: client/ffi/install.sh [--lib-dir DIR] [--symlink] PREFIX
#
# Which library it installs:
#   --lib-dir DIR    the libdyfos.so and libdyfos.a in DIR (also: DYFOS_LIB_DIR=DIR);
#   otherwise        the workspace's release build, target/release (or
#                    $CARGO_TARGET_DIR/release), as it is, if it holds both: run
#                    `cargo build --release` first if the sources changed since;
#   if there is none it builds it with `cargo build --release -p dyfos-ffi`.
# It never rebuilds a library that is there, so the installed library is the one
# the workspace's tests and binaries use.
#   --symlink        link the libraries instead of copying them (also:
#                    DYFOS_INSTALL_SYMLINK=1); the tests use it.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
usage="usage: client/ffi/install.sh [--lib-dir DIR] [--symlink] PREFIX"
libs=${DYFOS_LIB_DIR:-}
symlink=${DYFOS_INSTALL_SYMLINK:-0}
prefix=
while [ $# -gt 0 ]; do
  case "$1" in
    --lib-dir) libs=${2:?$usage}; shift 2 ;;
    --lib-dir=*) libs=${1#--lib-dir=}; shift ;;
    --symlink) symlink=1; shift ;;
    -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
    -*) echo "install.sh: unknown option $1; $usage" >&2; exit 2 ;;
    *) [ -z "$prefix" ] || { echo "install.sh: one PREFIX only; $usage" >&2; exit 2; }; prefix=$1; shift ;;
  esac
done
[ -n "$prefix" ] || { echo "$usage" >&2; exit 2; }

abi=$(sed -n 's/^pub const DYFOS_ABI_VERSION: u32 = \([0-9]*\)u32;/\1/p' "$here/src/version.rs")
version=$(sed -n 's/^version = "\(.*\)"/\1/p' "$here/../../Cargo.toml" | head -n 1)
[ -n "$abi" ] && [ -n "$version" ] || { echo "install.sh: cannot read the ABI version or the version" >&2; exit 1; }

if [ -n "$libs" ]; then
  for lib in libdyfos.so libdyfos.a; do
    [ -f "$libs/$lib" ] || { echo "install.sh: $libs/$lib does not exist" >&2; exit 1; }
  done
else
  libs="${CARGO_TARGET_DIR:-$here/../../target}/release"
  if [ -f "$libs/libdyfos.so" ] && [ -f "$libs/libdyfos.a" ]; then
    echo "installing the built library from $libs (run \`cargo build --release\` first if the sources changed)"
  else
    echo "no built library in $libs: building it"
    cargo build --release -p dyfos-ffi --manifest-path "$here/../../Cargo.toml"
  fi
fi
libs=$(cd "$libs" && pwd)

mkdir -p "$prefix"
prefix=$(cd "$prefix" && pwd)
mkdir -p "$prefix/lib/pkgconfig" "$prefix/lib/cmake/dyfos" "$prefix/include"
put() { # put SOURCE DEST: copy, or link with --symlink
  rm -f "$2"
  if [ "$symlink" = 1 ]; then ln -s "$1" "$2"; else cp "$1" "$2"; fi
}
put "$libs/libdyfos.so" "$prefix/lib/libdyfos.so.$abi"
rm -f "$prefix/lib/libdyfos.so"
ln -s "libdyfos.so.$abi" "$prefix/lib/libdyfos.so"
put "$libs/libdyfos.a" "$prefix/lib/libdyfos.a"
cp "$here/include/dyfos.h" "$here/include/dyfos.hpp" "$prefix/include/"
sed -e "s|@VERSION@|$version|" "$here/dyfos.pc.in" >"$prefix/lib/pkgconfig/dyfos.pc"
sed -e "s|@ABI@|$abi|" "$here/cmake/dyfosConfig.cmake.in" >"$prefix/lib/cmake/dyfos/dyfosConfig.cmake"
sed -e "s|@VERSION@|$version|" "$here/cmake/dyfosConfigVersion.cmake.in" \
  >"$prefix/lib/cmake/dyfos/dyfosConfigVersion.cmake"
echo "installed the dyfos C API $version (ABI $abi) under $prefix"
