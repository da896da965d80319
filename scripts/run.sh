#!/usr/bin/env bash
# Installs the core into .venv and runs the main job: the expert autopilot over every built-in R4
# scenario, with its summary table.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
.venv/bin/drivehierarchy r4 evaluate --agent expert --suite builtin --out runs/expert "$@"
