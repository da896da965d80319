#!/usr/bin/env bash
# The whole test suite: formatting and lints (Rust + Python), the stub contract, the docs site,
# Rust tests and the Python tests (Gymnasium/SB3 checkers, SUMO nets, loopback VLM server
# included), and the wheel smoke test from a fresh venv. Installs every extra into .venv first.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh all
PY=.venv/bin/python
export PATH="$PWD/.venv/bin:$PATH"
echo "== cargo fmt";    cargo fmt --all -- --check
echo "== cargo clippy"; cargo clippy --workspace --all-targets --locked -- -D warnings
echo "== ruff";         $PY -m ruff check .
                        $PY -m ruff format --check .
echo "== stubtest";     $PY -m mypy.stubtest drivehierarchy._core --allowlist python/stubtest-allowlist.txt
echo "== docs";         DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $PY -m mkdocs build --strict --quiet --site-dir "$(mktemp -d)"
echo "== wheel";        bash scripts/wheel_check.sh
echo "== cargo test";   cargo test --workspace --exclude dh-py --locked
echo "== pytest";       $PY -m pytest tests "$@"
