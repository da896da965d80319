#!/usr/bin/env bash
# The whole test suite: formatting and lints (Rust + Python), the stub contract, Rust tests and
# the Python tests (Gymnasium/SB3 checkers, SUMO nets, loopback VLM server included).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
echo "== cargo fmt";    cargo fmt --all -- --check
echo "== cargo clippy"; cargo clippy --workspace --all-targets --locked -- -D warnings
echo "== ruff";         python3 -m ruff check .
                        python3 -m ruff format --check .
echo "== stubtest";     python3 -m mypy.stubtest drivehierarchy._core --allowlist python/stubtest-allowlist.txt
echo "== cargo test";   cargo test --workspace --exclude dh-py --locked
echo "== pytest";       python3 -m pytest tests "$@"
