# Sourced by the test and install scripts: sets `root` (the workspace) and `target`
# (the cargo target dir), and defines the helpers below.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"

# `build_workspace`: the workspace's debug build, --all-targets as scripts/test
# builds, so the features match and nothing is built twice (a no-op after it).
build_workspace() {
    (cd "$root" && cargo build --quiet --workspace --all-targets)
}

# `run_pytest NAME DIR PYTHON [ARGS...]`: PYTHON's pytest in DIR with ARGS, quiet;
# exits with its status, or with 1 (saying so for NAME) when it collects no test.
run_pytest() {
    local name="$1" dir="$2" python="$3" status=0
    shift 3
    (cd "$dir" && "$python" -m pytest -q "$@") || status=$?
    if [ "$status" -eq 5 ]; then
        echo "$name: pytest collected no tests" >&2
        exit 1
    fi
    exit "$status"
}

# `make_venv PYTHON VENV` makes VENV with PYTHON unless it is there and has pip. A venv whose creation was cut short (a full
# disk, Ctrl-C) has a python but no pip; it is made again rather than failing every
# later `pip install`.
make_venv() {
    local python="$1" venv="$2"
    if "$venv/bin/python" -m pip --version >/dev/null 2>&1; then
        return 0
    fi
    "$python" -m venv --clear "$venv"
}

# `venv_with VENV IMPORTS PKG...`: VENV made with $PYTHON (default python3) as
# `make_venv` does, then PKG... pip-installed into it unless its python can already
# `import IMPORTS` (later runs skip the install).
venv_with() {
    local venv="$1" imports="$2"
    shift 2
    make_venv "${PYTHON:-python3}" "$venv"
    if ! "$venv/bin/python" -c "import $imports" 2>/dev/null; then
        "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "$@"
    fi
}
