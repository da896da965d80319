#!/usr/bin/env bash
# The whole test suite: formatting and lints (Rust + Python), the stub contract, the docs site,
# Rust tests and the Python tests (Gymnasium/SB3 checkers, SUMO nets, loopback VLM server
# included), the wheel smoke test from a fresh venv, and a bounded run of every fuzz target.
# Installs every extra into .venv first.
#
# Two lanes run side by side: the Rust lane (fmt, clippy, cargo test, fuzzing; it needs no
# Python) starts at once in the background, while the Python lane installs, checks and runs
# pytest (two workers). Both share the two cores evenly: at a lower priority the Rust lane's
# build chain starved and ended 70 s after pytest (951 s vs 883 s without). Each step prints when it starts; the Rust lane's
# output is printed when it ends, and the script fails if either lane failed.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
step() { echo "== $1 (at $((SECONDS - start)) s)"; }

rust_log="$(mktemp)"
rust_lane() {
    set -euo pipefail
    step "rust: cargo fmt"; cargo fmt --all -- --check
    # Clippy lints inside the test build, as `cargo clippy` itself does (clippy-driver as the
    # workspace's rustc wrapper; -D warnings as RUSTFLAGS, clippy's documented CI form): the
    # dependencies are compiled once, not once to lint and once more to test. Every target that
    # `cargo clippy --workspace --all-targets` checks is compiled: libraries, tests, examples.
    # One package selection throughout (the whole workspace, the Python binding's empty test
    # harness included): another selection unifies features differently and rebuilds. pyo3's
    # extension-module feature, as maturin builds it, links no libpython into that harness.
    step "rust: clippy + cargo test"
    RUSTFLAGS="-D warnings" RUSTC_WORKSPACE_WRAPPER="$(rustup which clippy-driver)" \
        cargo test --workspace --features pyo3/extension-module --locked
    step "rust: fuzz"; FUZZ_DEV=1 bash scripts/fuzz.sh 8
    step "rust: done"
}
rust_lane >"$rust_log" 2>&1 &
rust_pid=$!
# A failing Python lane (set -e) must not leave the Rust lane running.
trap 'pkill -P "$rust_pid" 2>/dev/null; kill "$rust_pid" 2>/dev/null || true' EXIT

bash scripts/install.sh all
PY=.venv/bin/python
export PATH="$PWD/.venv/bin:$PATH"
step "ruff";     $PY -m ruff check .
                 $PY -m ruff format --check .
step "stubtest"; $PY -m mypy.stubtest drivehierarchy._core --allowlist python/stubtest-allowlist.txt
step "docs";     DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $PY -m mkdocs build --strict --quiet --site-dir "$(mktemp -d)"
step "wheel";    bash scripts/wheel_check.sh
# Two workers, each taking whole files (`--dist loadfile`): a file's module fixtures (the docs
# walk's shared folder, a loopback server) stay in one process.
step "pytest";   $PY -m pytest tests -n 2 --dist loadfile --durations=15 "$@"
step "pytest done; waiting for the Rust lane"
rust_rc=0
wait "$rust_pid" || rust_rc=$?
trap - EXIT
echo "---- Rust lane (fmt, clippy, cargo test, fuzz) ----"
cat "$rust_log"
rm -f "$rust_log"
if [ "$rust_rc" != 0 ]; then
    echo "test.sh: the Rust lane failed (exit $rust_rc; its output is above)" >&2
    exit "$rust_rc"
fi
step "done"
