#!/usr/bin/env bash
# The whole test suite: formatting and lints (Rust + Python), the stub contract, the docs site,
# Rust tests and the Python tests (Gymnasium/SB3 checkers, SUMO nets, loopback VLM server
# included), the wheel smoke test from a fresh venv, and a bounded run of every fuzz target. Installs every extra into .venv first.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
step() { echo "== $1 (at $((SECONDS - start)) s)"; }
bash scripts/install.sh all
PY=.venv/bin/python
export PATH="$PWD/.venv/bin:$PATH"
step "cargo fmt";    cargo fmt --all -- --check
step "cargo clippy"; cargo clippy --workspace --all-targets --locked -- -D warnings
step "ruff";         $PY -m ruff check .
                     $PY -m ruff format --check .
step "stubtest";     $PY -m mypy.stubtest drivehierarchy._core --allowlist python/stubtest-allowlist.txt
step "docs";         DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $PY -m mkdocs build --strict --quiet --site-dir "$(mktemp -d)"
step "wheel";        bash scripts/wheel_check.sh
step "fuzz";         bash scripts/fuzz.sh 8
step "cargo test";   cargo test --workspace --exclude dh-py --locked
step "pytest";       $PY -m pytest tests --durations=15 "$@"
step "done"
