#!/usr/bin/env bash
# Installs drivehierarchy with every extra (SUMO, RL, reports, judge, dev tools) into the current
# Python environment. Builds the Rust core with maturin (release). Safe to re-run.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --upgrade "pip>=23" "maturin>=1.7,<2" >/dev/null
# The native SUMO backend's shim is compiled against the C++ headers of the pinned eclipse-sumo
# wheel (python/build.rs): install that first and point the (isolated) build at it via SUMO_HOME.
sumo_pin="$(grep -o '"eclipse-sumo==[^"]*"' pyproject.toml | tr -d '"')"
python3 -m pip install "$sumo_pin"
SUMO_HOME="$(python3 -c 'import sumo; print(sumo.SUMO_HOME)')"
# The shim needs a C++ compiler, and SUMO's libraries (libsumocpp, like the libsumo module) a few
# system libraries (X11, GL) that a minimal Debian/Ubuntu image may lack.
missing="$(ldd "$SUMO_HOME/lib64/libsumocpp.so" | awk '/not found/ {print $1}' || true)"
command -v c++ >/dev/null || missing="$missing c++"
if [ -n "$missing" ]; then
    echo "the native SUMO backend needs:$missing" >&2
    if command -v apt-get >/dev/null; then
        sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
        $sudo apt-get update -qq
        $sudo apt-get install -y -qq g++ libx11-6 libxext6 libxrender1 libgl1 libxcb1 libexpat1 zlib1g
    fi
fi
SUMO_HOME="$SUMO_HOME" python3 -m pip install -e ".[all]"
