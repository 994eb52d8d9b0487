#!/usr/bin/env bash
# Tests the Python binding `dyfos`: builds it into a virtual environment under the
# cargo target dir (maturin develop, reusing the cargo build), then runs its pytest
# suite against the workspace's debug `dyfosd` and `dyfos` binaries.
#
#   client/python/test.sh [pytest args...]
#
# Needs Rust and Python >= 3.9 with pip and venv; installs maturin, pytest and numpy
# from PyPI into the venv the first time (later runs skip that). Exits non-zero on
# any failure, and when pytest collects no test.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
venv="$target/py-venv"
python="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
if [ ! -x "$venv/bin/maturin" ] || ! "$venv/bin/python" -c "import pytest, numpy" 2>/dev/null; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "maturin>=1.9.4,<2" "pytest>=7" numpy
fi

# The daemon and CLI under test (a no-op after scripts/test's build; --all-targets
# as there, so the features match and nothing is built twice).
(cd "$root" && cargo build --quiet --workspace --all-targets)

# Build the extension module and install the package into the venv (editable).
(cd "$here" && VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" "$venv/bin/maturin" develop --quiet)

export DYFOSD="$target/debug/dyfosd" DYFOS="$target/debug/dyfos" DYFOS_TEST_DATA="$root/tests/data"
status=0
(cd "$here" && "$venv/bin/python" -m pytest tests -q "$@") || status=$?
if [ "$status" -eq 5 ]; then
    echo "client/python/test.sh: pytest collected no tests" >&2
    exit 1
fi
exit "$status"
