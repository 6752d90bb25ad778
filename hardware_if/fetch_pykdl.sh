#!/usr/bin/env bash
# Fetch PyKDL (python3-pykdl and liborocos-kdl1.5) from Debian into a venv's own folder, for the dVRK's
# Python client that the tests run against sim-dvrk (PyKDL is not on PyPI in a usable form). Nothing is
# installed on the system: the packages are downloaded with `apt-get download` and unpacked with
# `dpkg -x` into $VENV/opt/pykdl. A client then needs
#   PYTHONPATH=$VENV/opt/pykdl/usr/lib/python3/dist-packages
#   LD_LIBRARY_PATH=$VENV/opt/pykdl/usr/lib/x86_64-linux-gnu
# (tests/ros/dvrk_client.py sets both for the client processes it starts).
#
# Usage: hardware_if/fetch_pykdl.sh [VENV]   (default: .venv, or $VIRTUAL_ENV when set)
# Idempotent: does nothing when PyKDL already imports from that folder. FORCE=1 fetches again.
set -euo pipefail

venv="${1:-${VIRTUAL_ENV:-.venv}}"
venv="$(cd "$venv" && pwd)"
python="$venv/bin/python"
root="$venv/opt/pykdl"
packages=(python3-pykdl liborocos-kdl1.5)

check() {
    PYTHONPATH="$root/usr/lib/python3/dist-packages" LD_LIBRARY_PATH="$root/usr/lib/x86_64-linux-gnu" \
        "$python" -c "import PyKDL; PyKDL.Frame(PyKDL.Rotation.RPY(0.1, 0.2, 0.3), PyKDL.Vector(1, 2, 3))"
}

if [[ "${FORCE:-0}" != 1 ]] && check 2>/dev/null; then
    echo "PyKDL: up to date in $root"
    exit 0
fi

command -v apt-get > /dev/null && command -v dpkg > /dev/null \
    || { echo "PyKDL: needs apt-get and dpkg (Debian or Ubuntu) to fetch ${packages[*]}" >&2; exit 1; }

download="$(mktemp -d "${TMPDIR:-/tmp}/pykdl.XXXXXX")"
trap 'rm -rf "$download"' EXIT
# apt-get download writes into the current directory; it needs no root.
(cd "$download" && apt-get download "${packages[@]}" > download.log 2>&1) \
    || { cat "$download/download.log" >&2; echo "PyKDL: apt-get download failed (try apt-get update)" >&2; exit 1; }
rm -rf "$root"
mkdir -p "$root"
for deb in "$download"/*.deb; do
    dpkg -x "$deb" "$root"
done
check || { echo "PyKDL: unpacked into $root but does not import with $python" >&2; exit 1; }
echo "PyKDL: installed into $root"
