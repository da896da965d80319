#!/usr/bin/env bash
# The whole test suite: formatting and lints (Rust + Python), the stub contract, the docs site,
# Rust tests and the Python tests (Gymnasium/SB3 checkers, SUMO nets, loopback VLM server
# included), the wheel smoke test from a fresh venv, and a bounded run of every fuzz target.
# Installs every extra into .venv first.
#
# Two lanes share the two cores. The Python lane installs (building the Rust core with maturin
# while uv installs the dependencies), checks and runs pytest (two workers). The Rust lane
# formats, builds and runs the fuzz targets (5 s each), waits for the install's build, then runs
# clippy + the Rust tests on that same build and the wheel check. Each step prints when it
# starts; the Rust lane's output is printed when it ends, and the script fails if either lane
# failed.
#
# One release build serves the extension, clippy, the Rust tests and the wheel: the install, the
# wheel and `cargo test --release` get the same profile, flags, features and build-script inputs
# (BUILD below; PYO3_PYTHON / PYO3_CONFIG_FILE as maturin sets them), so cargo reuses every
# dependency and compiles only the test targets (~70 CPU-s instead of a ~360 CPU-s dev build).
#   - clippy-driver as the workspace's rustc wrapper with -D warnings (clippy's documented CI
#     form) lints every target it compiles: libraries, tests, examples. Dependencies are not
#     wrapped and their lints are capped, so they build as in any release build.
#   - No LTO here: each test binary would redo it (cargo test --release with LTO costs 880
#     CPU-s); the code is the same. The release profile keeps thin LTO for users' installs.
#   - Overflow checks and debug assertions on, as the dev profile has them: the Rust tests keep
#     them, and pytest runs against an extension that has them too.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
step() { echo "== $1 (at $((SECONDS - start)) s)"; }

BUILD=(
    RUSTFLAGS="-D warnings"
    RUSTC_WORKSPACE_WRAPPER="$(rustup which clippy-driver)"
    CARGO_PROFILE_RELEASE_LTO=false
    CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS=true
    CARGO_PROFILE_RELEASE_DEBUG_ASSERTIONS=true
)
rust_log="$(mktemp)"
built="$(mktemp -u)"  # exists once the install has built the extension
rust_lane() {
    set -euo pipefail
    step "rust: cargo fmt"; cargo fmt --all -- --check
    # The fuzz build and run first, beside the install: they fill the core its build chain and
    # downloads leave idle. (Measured alternatives, all slower: at nice 10 the fuzz build starved
    # behind pytest; after the Rust tests it slowed pytest more than it slows the install.)
    # CARGO_INCREMENTAL=0: a fresh clone builds the fuzz crate once, so incremental caches
    # (the dev profile's default) are work nobody reads.
    step "rust: fuzz"; CARGO_INCREMENTAL=0 FUZZ_DEV=1 bash scripts/fuzz.sh 5
    step "rust: waiting for the install's build"
    until [ -e "$built" ]; do sleep 1; done
    step "rust: clippy + cargo test (the install's build)"
    local config pyo3=(PYO3_PYTHON="$PWD/.venv/bin/python")
    config="$(ls "${CARGO_TARGET_DIR:-target}"/maturin/pyo3-config-*.txt 2>/dev/null | head -1 || true)"
    if [ -n "$config" ]; then pyo3+=(PYO3_CONFIG_FILE="$(realpath "$config")"); fi
    env -u SUMO_HOME "${BUILD[@]}" "${pyo3[@]}" cargo test --release --workspace --features pyo3/extension-module --locked
    step "rust: wheel"; env "${BUILD[@]}" bash scripts/wheel_check.sh
    step "rust: done"
}
rust_lane >"$rust_log" 2>&1 &
rust_pid=$!
# A failing Python lane (set -e) must not leave the Rust lane running.
trap 'pkill -P "$rust_pid" 2>/dev/null; kill "$rust_pid" 2>/dev/null || true; rm -f "$built"' EXIT

env "${BUILD[@]}" bash scripts/install.sh all
touch "$built"
PY=.venv/bin/python
export PATH="$PWD/.venv/bin:$PATH"
step "ruff";     $PY -m ruff check .
                 $PY -m ruff format --check .
step "stubtest"; $PY -m mypy.stubtest drivehierarchy._core --allowlist python/stubtest-allowlist.txt
step "mypy";     $PY -m mypy  # [tool.mypy] in pyproject.toml: strict on envs, agents, benchmark
step "docs";     DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $PY -m mkdocs build --strict --quiet --site-dir "$(mktemp -d)"
# Two workers, each taking whole files (`--dist loadfile`): a file's module fixtures (the docs
# walk's shared folder, a loopback server) stay in one process. (Three were not faster: the work
# is CPU-bound.)
step "pytest";   $PY -m pytest tests -n 2 --dist loadfile --durations=15 "$@"
step "pytest done; waiting for the Rust lane"
rust_rc=0
wait "$rust_pid" || rust_rc=$?
trap - EXIT
rm -f "$built"
echo "---- Rust lane (fmt, fuzz, clippy, cargo test, wheel) ----"
cat "$rust_log"
rm -f "$rust_log"
if [ "$rust_rc" != 0 ]; then
    echo "test.sh: the Rust lane failed (exit $rust_rc; its output is above)" >&2
    exit "$rust_rc"
fi
step "done"
