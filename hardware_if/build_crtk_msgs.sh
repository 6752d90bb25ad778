#!/usr/bin/env bash
# Build and install the crtk_msgs interfaces (all of collaborative-robotics/crtk_msgs 1.3.0: messages and
# services) into a Python venv that holds ROS 2 Jazzy from PyPI (the project's `ros` extra). Plain cmake,
# no colcon.
#
# Usage: hardware_if/build_crtk_msgs.sh [VENV]   (default: .venv, or $VIRTUAL_ENV when set)
#
# Idempotent: it does nothing when the installed package already matches the interface sources
# (a hash of them is kept in $VENV/share/crtk_msgs/.source-hash). Set FORCE=1 to rebuild.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
src="$here/crtk_msgs"
venv="${1:-${VIRTUAL_ENV:-.venv}}"
venv="$(cd "$venv" && pwd)"
python="$venv/bin/python"
stamp="$venv/share/crtk_msgs/.source-hash"

check="from crtk_msgs.msg import OperatingState, StringStamped; from crtk_msgs.srv import QueryForwardKinematics, QueryInverseKinematics"
hash="$(cd "$src" && cat package.xml CMakeLists.txt msg/*.msg srv/*.srv | sha256sum | cut -d' ' -f1)"
if [[ "${FORCE:-0}" != 1 && -f "$stamp" && "$(cat "$stamp")" == "$hash" ]] \
    && "$python" -c "$check" 2>/dev/null; then
    echo "crtk_msgs: up to date in $venv"
    exit 0
fi

build="$(mktemp -d "${TMPDIR:-/tmp}/crtk_msgs_build.XXXXXX")"
trap 'rm -rf "$build"' EXIT

# Type supports are found through the ament index at configure time; the venv is the only prefix.
export AMENT_PREFIX_PATH="$venv"
export CMAKE_PREFIX_PATH="$venv"
export PATH="$venv/bin:$PATH"
jobs="$(nproc 2>/dev/null || echo 2)"

echo "crtk_msgs: building into $venv"
cmake -S "$src" -B "$build" \
    -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_INSTALL_PREFIX="$venv" \
    -DCMAKE_PREFIX_PATH="$venv" \
    -DPython3_EXECUTABLE="$python" \
    -DPython3_FIND_STRATEGY=LOCATION \
    -DBUILD_TESTING=OFF \
    > "$build/configure.log" 2>&1 || { cat "$build/configure.log" >&2; exit 1; }
cmake --build "$build" -j "$jobs" > "$build/build.log" 2>&1 || { tail -n 60 "$build/build.log" >&2; exit 1; }
cmake --install "$build" > "$build/install.log" 2>&1 || { cat "$build/install.log" >&2; exit 1; }

"$python" -c "$check" \
    || { echo "crtk_msgs: built but not importable from $python" >&2; exit 1; }
mkdir -p "$(dirname "$stamp")"
echo "$hash" > "$stamp"
echo "crtk_msgs: installed"
