# Sourced by the test and install scripts. `make_venv PYTHON VENV` makes VENV with
# PYTHON unless it is there and has pip. A venv whose creation was cut short (a full
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
