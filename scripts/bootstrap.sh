#!/usr/bin/env bash
# Create or refresh the project's virtual environment, then install everything into it:
#   1. the venv itself (default <repo>/.venv, override with MK_VENV; interpreter MK_PYTHON or python3.11),
#   2. exactly requirements.lock (pip, setuptools, ROS 2 Jazzy wheels, numpy, colcon, ...),
#   3. the interface package manipulator_kinematics_interfaces, built with cmake INTO the venv,
#   4. the repo itself, editable (`pip install --no-deps -e .`): console scripts in <venv>/bin,
#   5. numba's cache of every compiled kernel (scripts/warm_kernels.py), so no first run compiles.
# Idempotent: <venv>/.mk_bootstrap.stamp records a hash of each step's inputs and a step whose
# inputs are unchanged is skipped, so a run with nothing to do takes well under a second.
# MK_FRESH=1 deletes and recreates the venv. Works from any cwd. Output: short progress lines.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${MK_VENV:-$REPO/.venv}"
mkdir -p "$(dirname "$VENV")"
VENV="$(cd "$(dirname "$VENV")" && pwd)/$(basename "$VENV")"
LOCK="$REPO/requirements.lock"
IFACE="$REPO/manipulator_kinematics_interfaces"
STAMP="$VENV/.mk_bootstrap.stamp"
LOG_DIR="$VENV/.mk_bootstrap_logs"
T0=$SECONDS

say() { printf '[bootstrap] %s\n' "$*"; }
die() { printf '[bootstrap] ERROR: %s\n' "$*" >&2; exit 1; }

# Run a long step quietly; on failure show the end of its log.
run_logged() {
    local name=$1; shift
    mkdir -p "$LOG_DIR"
    if ! "$@" >"$LOG_DIR/$name.log" 2>&1; then
        tail -n 40 "$LOG_DIR/$name.log" >&2
        die "step '$name' failed; full log: $LOG_DIR/$name.log"
    fi
}

# ---------------------------------------------------------------- system prerequisites
APT_UPDATED=0
apt_install() {
    command -v apt-get >/dev/null 2>&1 || die "missing system packages ($*) and no apt-get to install them"
    local sudo=""
    if [ "$(id -u)" -ne 0 ]; then
        command -v sudo >/dev/null 2>&1 || die "missing system packages ($*); install them as root"
        sudo="sudo"
    fi
    say "installing Debian packages: $*"
    if [ "$APT_UPDATED" -eq 0 ]; then
        run_logged apt-update $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -q
        APT_UPDATED=1
    fi
    run_logged apt-install $sudo env DEBIAN_FRONTEND=noninteractive \
        apt-get install -y -q --no-install-recommends "$@"
}

pick_python() {
    local cand
    for cand in ${MK_PYTHON:-} python3.11 python3; do
        if command -v "$cand" >/dev/null 2>&1 \
            && "$cand" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
            command -v "$cand"
            return 0
        fi
    done
    return 1
}

check_system() {
    local missing=()
    command -v cmake >/dev/null 2>&1 || missing+=(cmake)
    command -v make >/dev/null 2>&1 || missing+=(make)
    { command -v c++ >/dev/null 2>&1 || command -v g++ >/dev/null 2>&1; } || missing+=(g++)
    PY="$(pick_python)" || missing+=(python3 python3-dev python3-venv)
    if [ -n "${PY:-}" ]; then
        # Debian splits ensurepip (python3-venv) and Python.h (python3-dev) out of python3.
        "$PY" -c 'import ensurepip, venv' 2>/dev/null || missing+=(python3-venv)
        "$PY" -c 'import os, sysconfig, sys
sys.exit(not os.path.exists(os.path.join(sysconfig.get_path("include"), "Python.h")))' \
            || missing+=(python3-dev)
    fi
    if [ ${#missing[@]} -gt 0 ]; then
        apt_install "${missing[@]}"
        PY="$(pick_python)" || die "no Python 3.11 interpreter found (set MK_PYTHON)"
    fi
}

# ---------------------------------------------------------------- hashing / stamps
hash_files() {  # sha256 over the names and contents of the given files/dirs (sorted)
    (cd "$REPO" && find "$@" -type f -not -path '*/__pycache__/*' -print0 2>/dev/null \
        | LC_ALL=C sort -z | xargs -0 sha256sum) | sha256sum | cut -c1-64
}
stamp_get() { [ -f "$STAMP" ] && sed -n "s/^$1=//p" "$STAMP" || true; }
stamp_set() {
    local tmp="$STAMP.tmp"
    { [ -f "$STAMP" ] && grep -v "^$1=" "$STAMP" || true; echo "$1=$2"; } >"$tmp"
    mv "$tmp" "$STAMP"
}

# ---------------------------------------------------------------- one bootstrap per venv at a time
# (the test and demo commands may start together; a second run waits, then finds nothing to do)
LOCK_FILE="${TMPDIR:-/tmp}/mk_bootstrap_$(printf '%s' "$VENV" | sha256sum | cut -c1-16).lock"
if command -v flock >/dev/null 2>&1; then
    exec 9>"$LOCK_FILE"
    if ! flock -n 9; then
        say "waiting for another bootstrap of $VENV"
        flock 9
    fi
fi

# ---------------------------------------------------------------- 1. venv
if [ "${MK_FRESH:-0}" = 1 ] && [ -f "$VENV/pyvenv.cfg" ]; then
    say "MK_FRESH=1: removing $VENV"
    rm -rf "$VENV"
fi
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
    check_system
    if [ -e "$VENV" ]; then  # only ever delete a venv, or a directory holding just our logs
        if [ -f "$VENV/pyvenv.cfg" ]; then
            say "replacing broken venv $VENV"
        elif [ -n "$(ls -A "$VENV" 2>/dev/null | grep -vx '.mk_bootstrap_logs')" ]; then
            die "$VENV exists and is not a virtual environment: remove it or set MK_VENV"
        fi
        rm -rf "$VENV"
    fi
    say "creating venv $VENV with $PY ($("$PY" -c 'import platform; print(platform.python_version())'))"
    run_logged venv "$PY" -m venv "$VENV"
fi
PYV="$VENV/bin/python"
export VIRTUAL_ENV="$VENV"
export PATH="$VENV/bin:$PATH"
unset PYTHONHOME

DEPS_HASH="$(hash_files requirements.lock)"
# The interface build depends on the ROS wheels, numpy's C API and the code generators' helpers
# only: a new pin of ruff or pytest does not rebuild it.
IFACE_HASH="$( { grep -E '^(ros-|numpy==|empy==|lark|catkin-pkg==|setuptools==)' "$LOCK" || true;
    hash_files manipulator_kinematics_interfaces; } | sha256sum | cut -c1-64)"
# The editable install maps each top-level package found at install time, so a new top-level
# package (a new */__init__.py at the repo root) needs a re-install: hash the list too.
PROJ_HASH="$( { echo "$DEPS_HASH $REPO"; (cd "$REPO" && ls -d -- */__init__.py 2>/dev/null || true);
    hash_files setup.py setup.cfg package.xml resource; } | sha256sum | cut -c1-64)"

# Rewrite the include paths that the wheels' exported .cmake files hard-code from the machine
# that built them (/opt/python/cp311-cp311/...) to this interpreter's (platform.md item 4).
fix_cmake_paths() {
    "$PYV" - "$VENV" <<'EOF'
import re, sys, sysconfig
from pathlib import Path
import numpy
py_inc, np_inc = sysconfig.get_path("include"), numpy.get_include()
pats = [(re.compile(r"/opt/python/[^;\"\s]*?/numpy/(_core|core)/include"), np_inc),
        (re.compile(r"/opt/python/cp3\d+-cp3\d+/include/python3\.\d+"), py_inc)]
changed = 0
for f in Path(sys.argv[1], "share").glob("*/cmake/*.cmake"):
    text = f.read_text()
    if "/opt/python/" not in text:
        continue
    new = text
    for pat, repl in pats:
        new = pat.sub(lambda _m, r=repl: r, new)
    if new != text:
        f.write_text(new)
        changed += 1
print(f"{changed} exported .cmake files rewritten")
EOF
}

# ---------------------------------------------------------------- 2. pinned dependencies
if [ "$(stamp_get deps)" != "$DEPS_HASH" ]; then
    check_system
    say "installing requirements.lock (pinned; first run takes about a minute)"
    PIP_PIN="$(grep -E '^pip==' "$LOCK" || true)"
    if [ -n "$PIP_PIN" ]; then
        run_logged pip-self "$PYV" -m pip install -q --disable-pip-version-check "$PIP_PIN"
    fi
    run_logged pip-lock "$PYV" -m pip install -q --disable-pip-version-check -r "$LOCK"
    # Remove what an older lock installed and this one no longer lists (only pip-installed
    # dist-info distributions; the egg-info entries are parts of the ROS wheels).
    EXTRA="$("$PYV" - "$LOCK" <<'EOF'
import importlib.metadata as md, re, sys
norm = lambda n: re.sub(r"[-_.]+", "-", n).lower()
locked = {norm(l.split("==")[0]) for l in open(sys.argv[1]) if "==" in l and not l.startswith("#")}
keep = locked | {"manipulator-kinematics", "pip", "setuptools"}
for d in md.distributions():
    path = str(getattr(d, "_path", ""))
    if path.endswith(".dist-info") and (d.read_text("INSTALLER") or "").strip() == "pip" \
            and norm(d.metadata["Name"]) not in keep:
        print(d.metadata["Name"])
EOF
)"
    if [ -n "$EXTRA" ]; then
        say "removing packages no longer in the lock: $(echo $EXTRA)"
        # shellcheck disable=SC2086
        run_logged pip-uninstall "$PYV" -m pip uninstall -y -q $EXTRA
    fi
    run_logged fix-cmake fix_cmake_paths
    stamp_set deps "$DEPS_HASH"
fi

# ---------------------------------------------------------------- 3. interface package
if [ "$(stamp_get interfaces)" != "$IFACE_HASH" ]; then
    check_system
    say "building manipulator_kinematics_interfaces into the venv (cmake, about 1-2 min)"
    run_logged fix-cmake fix_cmake_paths
    BUILD="$VENV/.mk_build/manipulator_kinematics_interfaces"
    MANIFEST="$VENV/.mk_build/interfaces_install_manifest.txt"
    if [ -f "$MANIFEST" ]; then  # drop the previous install (a removed .srv must not linger)
        tr '\n' '\0' <"$MANIFEST" | xargs -0 rm -f --
        tr '\n' '\0' <"$MANIFEST" | xargs -0 dirname -- | sort -u \
            | xargs -r rmdir -p --ignore-fail-on-non-empty -- 2>/dev/null || true
        rm -rf "$("$PYV" -c 'import sysconfig; print(sysconfig.get_path("purelib"))')/manipulator_kinematics_interfaces"
    fi
    rm -rf "$BUILD"
    mkdir -p "$BUILD"
    (
        export AMENT_PREFIX_PATH="$VENV"
        export CMAKE_PREFIX_PATH="$VENV"
        run_logged iface-configure cmake -S "$IFACE" -B "$BUILD" \
            -DCMAKE_INSTALL_PREFIX="$VENV" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
            -DPython3_EXECUTABLE="$PYV" -DPYTHON_EXECUTABLE="$PYV" -DPython3_FIND_VIRTUALENV=ONLY
        run_logged iface-build cmake --build "$BUILD" -j "$(nproc 2>/dev/null || echo 2)"
        run_logged iface-install cmake --install "$BUILD"
    )
    cp "$BUILD/install_manifest.txt" "$MANIFEST"
    rm -rf "$BUILD"
    "$PYV" -c 'from manipulator_kinematics_interfaces.srv import SolveIK, SolveFK' \
        || die "manipulator_kinematics_interfaces was installed but does not import"
    stamp_set interfaces "$IFACE_HASH"
fi

# ---------------------------------------------------------------- 4. the project, editable
if [ "$(stamp_get project)" != "$PROJ_HASH" ]; then
    say "installing manipulator_kinematics (editable) into the venv"
    run_logged pip-project "$PYV" -m pip install -q --disable-pip-version-check \
        --no-deps --no-build-isolation -e "$REPO"
    stamp_set project "$PROJ_HASH"
fi

# ---------------------------------------------------------------- 5. compiled kernels
# numba invalidates a kernel's cache when its source changes; the stamp only skips a run.
KERNELS_HASH="$( { echo "$PROJ_HASH"; hash_files $(cd "$REPO" && ls -- */*_kernel.py | grep -v "^test/"); } | sha256sum | cut -c1-64)"
if [ "$(stamp_get kernels)" != "$KERNELS_HASH" ]; then
    say "compiling the numba kernels into their cache (first run: about two minutes)"
    run_logged warm-kernels "$PYV" "$REPO/scripts/warm_kernels.py"
    stamp_set kernels "$KERNELS_HASH"
fi

say "venv ready: $VENV ($((SECONDS - T0)) s)"
