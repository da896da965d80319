#!/usr/bin/env bash
# Builds the abi3 wheel (with the native SUMO shim, from the pinned eclipse-sumo build requirement,
# no SUMO_HOME) and smoke-tests it from a fresh venv with no Rust toolchain on PATH: what a user of
# `pip install drivehierarchy-*.whl` gets. Leaves the wheel in dist/.
set -euo pipefail
cd "$(dirname "$0")/.."
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
rm -rf dist
# `pip wheel .` is the path users take: an isolated build with only pyproject's build requirements.
env -u SUMO_HOME .venv/bin/python -m pip wheel --quiet --no-deps --wheel-dir dist .
wheel="$(ls dist/drivehierarchy-*.whl)"
echo "wheel: $wheel ($(du -h "$wheel" | cut -f1))"
.venv/bin/python - "$wheel" <<'PY'
import sys, zipfile
names = zipfile.ZipFile(sys.argv[1]).namelist()
for need in ("drivehierarchy/_core.abi3.so", "drivehierarchy/_dh_sumo_shim.so"):
    if need not in names:
        sys.exit(f"wheel check: {need} is missing from the wheel")
if not any(n.startswith("drivehierarchy/_data/scenarios/r4/") for n in names):
    sys.exit("wheel check: the scenario suite is missing from the wheel")
PY
python3 -m venv "$work/venv"
# uv installs the wheel and its dependencies as pip would, from the cache install.sh filled.
.venv/bin/uv pip install --quiet --python "$work/venv/bin/python" "$wheel"
# No cargo/rustc: the wheel must need nothing but itself and its Python dependencies.
(cd "$work" && env -u SUMO_HOME PATH="$work/venv/bin:/usr/local/bin:/usr/bin:/bin" \
    "$work/venv/bin/python" "$OLDPWD/scripts/wheel_smoke.py" "$work" "$OLDPWD/../shared/official/Open_Loop_Evaluation")
