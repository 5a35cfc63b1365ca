#!/bin/sh
# Create or refresh .venv with gait_nodes and its test dependencies. Run from the repository root:
#
#     sh tools/venv.sh                      # .venv with '.[test]'
#     GAIT_NODES_ROBOTS=1 sh tools/venv.sh  # also '.[robots]' (example-robot-data)
#     JAZZY_STACK=1 sh tools/venv.sh        # .venv-jazzy: ROS 2 Jazzy's Python stack (below)
#
# Safe to run again: an existing working .venv is reused and gait_nodes is reinstalled from the
# current sources. On Debian/Ubuntu without python3-venv it installs that package with apt-get
# (through sudo when not root). Exits non-zero on any error.
#
# JAZZY_STACK=1 makes .venv-jazzy with Python 3.12 (python3.12 on PATH, else pyenv's) and the
# versions of tools/jazzy-stack-constraints.txt: Ubuntu 24.04's numpy, scipy, pyyaml and jsonschema,
# and matplotlib 3.7. Pinocchio's wheels declare numpy >= 2 but run on numpy 1.26.4, so pin, the
# packages that need cmeel-boost and example-robot-data are installed with --no-deps, after their
# other dependencies; the script then checks that every pinned version is the installed one.
set -eu

say() {
    printf 'venv.sh: %s\n' "$*"
}

die() {
    printf 'venv.sh: error: %s\n' "$*" >&2
    exit 1
}

JAZZY=${JAZZY_STACK:-0}
CONSTRAINTS=tools/jazzy-stack-constraints.txt
# pin's dependencies that do not ask for numpy, installed first with theirs (cmeel-*)...
PIN_DEPENDENCIES='cmeel cmeel-assimp cmeel-octomap cmeel-qhull cmeel-urdfdom jrl-cmakemodules'
# ...then these, with --no-deps: cmeel-boost asks for numpy >= 2 and the others for cmeel-boost.
NO_DEPS='cmeel-boost eigenpy libcoal coal libpinocchio pin example-robot-data'

# The first Python 3.12 that runs: python3.12 on PATH (pyenv's shim fails unless 3.12 is selected),
# else one installed by pyenv.
find_python312() {
    for candidate in python3.12 "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.12*/bin/python3.12; do
        if "$candidate" -c '' >/dev/null 2>&1; then
            echo "$candidate"
            return
        fi
    done
}

if [ "$JAZZY" = 1 ]; then
    VENV=.venv-jazzy
    PYTHON=${PYTHON:-$(find_python312)}
    [ -n "$PYTHON" ] || die "JAZZY_STACK=1 needs Python 3.12: no working python3.12 on PATH and" \
        "none in ${PYENV_ROOT:-$HOME/.pyenv}/versions/3.12*; install it (Ubuntu 24.04:" \
        "apt-get install python3.12-venv; elsewhere: pyenv install 3.12) or set PYTHON"
else
    VENV=.venv
    PYTHON=${PYTHON:-python3}
fi

if [ ! -f setup.py ] || [ ! -f package.xml ]; then
    die "run me from the gait_nodes repository root (no setup.py/package.xml in $(pwd))"
fi

command -v "$PYTHON" >/dev/null 2>&1 || die "$PYTHON not found; install Python >= 3.10"
"$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 10))' \
    || die "Python >= 3.10 required, $PYTHON is $("$PYTHON" -c 'import sys; print(sys.version.split()[0])')"
if [ "$JAZZY" = 1 ]; then
    "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))' \
        || die "JAZZY_STACK=1 needs Python 3.12, $PYTHON is not"
fi

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
if [ "$JAZZY" = 1 ]; then
    # gait_nodes' requirements (from pip's report on $target) less $NO_DEPS, one per line.
    requirements=$("$VENV/bin/python" -m pip install -q --dry-run --no-deps --report - "$target" \
        | "$VENV/bin/python" -c '
import json, re, sys
for requirement in json.load(sys.stdin)["install"][0]["metadata"]["requires_dist"]:
    spec, _, marker = requirement.partition(";")
    name = re.match(r"[\w.-]+", spec)[0].lower()
    if name not in sys.argv[1:] and (not marker or "test" in marker):
        print(spec.strip())
' $NO_DEPS)
    # Word splitting on purpose: each requirement and package name is one word.
    "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" $requirements $PIN_DEPENDENCIES
    "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" --no-deps $NO_DEPS
else
    "$VENV/bin/python" -m pip install -q "$target"
fi

# pip skips a package whose version is already installed, so reinstall gait_nodes itself to pick
# up the current sources (dependencies stay as they are).
say 'reinstalling gait_nodes from the current sources'
"$VENV/bin/python" -m pip install -q --upgrade --force-reinstall --no-deps .

if [ "$JAZZY" = 1 ]; then
    say "checking the versions pinned in $CONSTRAINTS"
    "$VENV/bin/python" -c '
import sys
from importlib.metadata import version
import numpy, pinocchio  # pin loads on this numpy
pins = dict(line.strip().split("==") for line in open(sys.argv[1]) if line[0] not in "#\n")
wrong = [f"{name} {version(name)} (pinned {want})" for name, want in pins.items()
         if version(name) != want]
wrong += [f"numpy.__version__ {numpy.__version__}"] * (numpy.__version__ != pins["numpy"])
if wrong:
    sys.exit("venv.sh: error: not the pinned versions: " + ", ".join(wrong))
' "$CONSTRAINTS"
fi

say "done: $VENV/bin/python -m pytest -q -n auto --dist loadgroup test"
