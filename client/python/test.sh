#!/usr/bin/env bash
# Tests the Python binding `dyfos`: installs it into a virtual environment under the
# cargo target dir, then runs its pytest suite against the workspace's debug `dyfosd`
# and `dyfos` binaries.
#
#   client/python/test.sh [pytest args...]            # the extension the workspace build made
#   client/python/test.sh --maturin [pytest args...]  # built and installed by `maturin develop`
#
# By default the extension module is the workspace build's `target/debug/lib_dyfos.so`
# (the same crate, sources and profile maturin builds), installed the way `maturin
# develop` installs it: the package directory with the module beside it, on the venv's
# path through a .pth file. maturin's own build (`cargo rustc` of this crate alone)
# unifies features over fewer packages than the workspace build, so it compiles the
# whole dependency tree a second time: about 4 min of a 2-core CI machine's 20.
# `--maturin` checks that packaging path too (pyproject.toml; what `pip install
# ./client/python` does).
#
# Needs Rust and Python >= 3.9 with pip and venv; installs pytest and numpy (and with
# --maturin, maturin) from PyPI into the venv the first time (later runs skip that).
# Exits non-zero on any failure, and when pytest collects no test.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=scripts/venv.sh
source "$here/../../scripts/venv.sh"
venv="$target/py-venv"
maturin=0
if [ "${1:-}" = "--maturin" ]; then
    maturin=1
    shift
fi

venv_with "$venv" "pytest, numpy" "pytest>=7" numpy
if [ "$maturin" = 1 ] && [ ! -x "$venv/bin/maturin" ]; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "maturin>=1.9.4,<2"
fi

# The daemon and CLI under test.
build_workspace

if [ "$maturin" = 1 ]; then
    # Build the extension module and install the package into the venv (editable).
    (cd "$here" && VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" "$venv/bin/maturin" develop --quiet)
else
    # The package as maturin lays it out: python/dyfos/ plus the module, named for
    # this interpreter. A copy, so that a module `maturin develop` left in the
    # source tree is never the one imported; `dyfos.pth` is the file maturin's
    # editable install writes, so only one of the two is ever on the path.
    site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
    suffix="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')"
    pkg="$target/py-dev"
    rm -rf "$pkg"
    mkdir -p "$pkg"
    cp -R "$here/python/dyfos" "$pkg/dyfos"
    rm -f "$pkg"/dyfos/_dyfos*.so
    cp "$target/debug/lib_dyfos.so" "$pkg/dyfos/_dyfos$suffix"
    echo "$pkg" > "$site/dyfos.pth"
fi

export DYFOSD="$target/debug/dyfosd" DYFOS="$target/debug/dyfos" DYFOS_TEST_DATA="$root/tests/data"
run_pytest client/python/test.sh "$here" "$venv/bin/python" tests "$@"
