# Sourced by the test and install scripts: `make_venv PYTHON VENV` makes VENV with
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
