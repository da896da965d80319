#!/usr/bin/env bash
# Installs drivehierarchy with every extra (SUMO, RL, reports, judge, dev tools) into the current
# Python environment. Builds the Rust core with maturin (release). Safe to re-run.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --upgrade "pip>=23" "maturin>=1.7,<2" >/dev/null
python3 -m pip install -e ".[all]"
