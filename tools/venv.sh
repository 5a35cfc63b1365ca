#!/bin/sh
# Create or refresh .venv with gait_nodes and its test dependencies. Run from the repository root:
#
#     sh tools/venv.sh                      # .venv with '.[test]'
#     GAIT_NODES_ROBOTS=1 sh tools/venv.sh  # also '.[robots]' (example-robot-data)
#
# Safe to run again: an existing working .venv is reused and gait_nodes is reinstalled from the
# current sources. On Debian/Ubuntu without python3-venv it installs that package with apt-get
# (through sudo when not root). Exits non-zero on any error.
set -eu

VENV=.venv
PYTHON=${PYTHON:-python3}

say() {
    printf 'venv.sh: %s\n' "$*"
}

die() {
    printf 'venv.sh: error: %s\n' "$*" >&2
    exit 1
}

if [ ! -f setup.py ] || [ ! -f package.xml ]; then
    die "run me from the gait_nodes repository root (no setup.py/package.xml in $(pwd))"
fi

command -v "$PYTHON" >/dev/null 2>&1 || die "$PYTHON not found; install Python >= 3.10"
"$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 10))' \
    || die "Python >= 3.10 required, $PYTHON is $("$PYTHON" -c 'import sys; print(sys.version.split()[0])')"

venv_works() {
    [ -x "$VENV/bin/python" ] && "$VENV/bin/python" -m pip --version >/dev/null 2>&1
}

install_venv_package() {
    command -v apt-get >/dev/null 2>&1 \
        || die "'$PYTHON -m venv' failed and apt-get is missing: install the venv module of $PYTHON"
    if [ "$(id -u)" -eq 0 ]; then
        as_root=''
    elif command -v sudo >/dev/null 2>&1; then
        as_root='sudo'
    else
        die "'$PYTHON -m venv' failed: install python3-venv as root (apt-get install python3-venv)"
    fi
    say "'$PYTHON -m venv' is unavailable; installing python3-venv:"
    say "  ${as_root:+$as_root }apt-get update && ${as_root:+$as_root }apt-get install -y python3-venv"
    $as_root env DEBIAN_FRONTEND=noninteractive apt-get update
    $as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y python3-venv
}

create_venv() {
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
}

if venv_works; then
    say "reusing $VENV"
else
    say "creating $VENV with $PYTHON -m venv"
    if ! create_venv; then
        # Debian and Ubuntu ship the venv module without ensurepip unless python3-venv is
        # installed; the failed attempt leaves a half-made .venv behind, which create_venv removes.
        install_venv_package
        say "retrying: $PYTHON -m venv $VENV"
        create_venv || die "'$PYTHON -m venv $VENV' failed even with python3-venv installed"
    fi
    venv_works || die "$VENV was created but has no working pip"
fi

say 'upgrading pip'
"$VENV/bin/python" -m pip install -q --upgrade pip

target='.[test]'
if [ "${GAIT_NODES_ROBOTS:-0}" = 1 ]; then
    target='.[test,robots]'
fi
# setuptools builds into build/lib and never deletes from it: a module removed or renamed in the
# sources would still be installed. Build from an empty one.
rm -rf build/lib build/bdist.*

say "installing $target and its dependencies"
"$VENV/bin/python" -m pip install -q "$target"

# pip skips a package whose version is already installed, so reinstall gait_nodes itself to pick
# up the current sources (dependencies stay as they are).
say 'reinstalling gait_nodes from the current sources'
"$VENV/bin/python" -m pip install -q --upgrade --force-reinstall --no-deps .

say "done: $VENV/bin/python -m pytest -q test"
