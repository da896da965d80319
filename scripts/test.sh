#!/usr/bin/env bash
# The test gate, and a quick lane for the edit-test loop (docs/robustness.md#running-the-checks).
#
#   bash scripts/test.sh           the whole gate (what CI's .ci/run calls): installs every extra into
#                                  .venv, then formatting and lints (Rust + Python), the stub contract,
#                                  the docs site, the Rust tests, every Python test (Gymnasium/SB3
#                                  checkers, SUMO nets, loopback VLM servers, browser, serving, Ray),
#                                  the wheel smoke test from a fresh venv, and a bounded run of every
#                                  fuzz target.
#   bash scripts/test.sh --quick   lints (cargo fmt, ruff, stubtest) and the Python tests of every
#                                  area except the slow end-to-end ones (QUICK_SKIP below), on the
#                                  existing .venv; rebuilds the extension first only when a Rust
#                                  source is newer than it. No Rust tests, docs build, wheel or fuzz.
# Extra arguments go to pytest (`bash scripts/test.sh --quick -k scoring`).
#
# The full gate runs four lanes on the two cores. The Python lane installs (building the Rust
# core with maturin while uv installs the dependencies), then runs pytest (two workers), the
# heaviest test files first (tests/conftest.py). The checks lane starts when the install is done
# and runs stubtest and the docs build beside pytest (they are short and would otherwise sit on
# the critical path). The Rust lane formats, runs ruff and mypy once the dependencies are
# installed (they need no build), waits for the install's build, then runs clippy + the Rust
# tests on that same build and the wheel check. The fuzz lane builds the fuzz targets at the
# lowest priority and runs each for 3 s. Each step prints when it starts; the background lanes'
# output is printed when they end, and the script fails if any lane failed.
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
# Bytecode caches on even where PYTHONDONTWRITEBYTECODE is set (as in some CI sandboxes): without
# them each of the gate's many Python processes (pytest workers, every documented command, spawned
# worker pools, the scripts' smoke runs) compiles torch, transformers and the rest from source
# again; one pytest collection took 20 CPU-s without them and 8.5 with. `__pycache__` is git-ignored.
unset PYTHONDONTWRITEBYTECODE
quick=0
if [ "${1:-}" = "--quick" ]; then
    quick=1
    shift
fi

BUILD=(
    RUSTFLAGS="-D warnings"
    RUSTC_WORKSPACE_WRAPPER="$(rustup which clippy-driver)"
    CARGO_PROFILE_RELEASE_LTO=false
    CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS=true
    CARGO_PROFILE_RELEASE_DEBUG_ASSERTIONS=true
)
PY=.venv/bin/python

# What --quick leaves to the full gate: the tests that drive the whole suite, train, start
# servers, browsers or many SUMO processes (each tens of CPU-seconds or more). Every area keeps
# its other tests. A new slow test file belongs here; `--durations` in the gate's log finds them.
QUICK_SKIP=(
    --ignore=tests/docs/test_docs_commands_run.py      # every documented command, as a process
    --ignore=tests/docs/test_docs_build.py             # builds the docs site
    --ignore=tests/fuzz/test_agent_fuzz.py             # 1,340 bad-driver episodes over the suite
    --ignore=tests/editor/test_e2e.py                  # Chromium through Playwright
    --ignore=tests/baselines/test_end_to_end.py        # RL / IL training runs
    --ignore=tests/scenarios/test_suite.py             # 200 probe episodes + the suite's checks
    --ignore=tests/scenarios/test_suite_probe.py       # the probe over several scenarios
    --ignore=tests/scenarios/test_maps_rebuild.py      # netconvert rebuilds of every map
    --ignore=tests/scenarios/test_import_official.py   # the expert over the imported scenes
    --ignore=tests/faults/test_r4_worker_faults.py     # kills and restarts worker processes
    --ignore=tests/vlm/test_vlm_sumo_workers.py        # SUMO scenarios in worker processes
    --ignore=tests/vlm/test_vlm_kill_resume.py         # kills an evaluation and resumes it
    --ignore=tests/scripts/test_scripts_quick.py       # each scripts/*.py --quick, as a process
    # The expert over every suite scenario (the probe's 400 reference episodes).
    --deselect=tests/envs/test_r4_env.py::test_expert_scores_at_least_90_on_every_builtin_scenario
    # Whole generated sets twice, seeded evaluations, the paper's correlations, a torch judge.
    --deselect=tests/openloop/generate/test_generate.py::test_same_options_give_byte_identical_files
    --deselect=tests/openloop/generate/test_generate.py::test_train_split_plays_shifted_starts_reproducibly
    --deselect=tests/vlm/test_vlm_evaluate.py::test_seeds_give_keys_intervals_and_reproducible_episodes
    --deselect=tests/benchmark/test_openloop_report.py::test_report_reproduces_paper_rank_correlations
    --deselect=tests/benchmark/test_scoring_judge.py::test_real_tiny_bert_judge_scores_run
    # transformers serve, a Ray cluster: ignored, not only deselected, so that collecting them
    # does not import torch and Ray (3 CPU-s per worker).
    --ignore=tests/vlm/test_transformers_serve.py
    --ignore=tests/vlm/test_vlm_ray.py
    --ignore=tests/baselines/test_baselines_ray.py
    -m "not serving and not ray"
)

if [ "$quick" = 1 ]; then
    if ! "$PY" -c 'import drivehierarchy._core' 2>/dev/null; then
        echo "test.sh --quick: no built drivehierarchy in .venv; run bash scripts/test.sh (or bash scripts/install.sh all) once" >&2
        exit 1
    fi
    # A Rust change needs a new extension before pytest means anything. The gate's flags, so the
    # quick lane and the gate share one build (clippy lints what is rebuilt). No build isolation,
    # as install.sh: the venv has the build requirements, and pip need not reinstall them each time.
    core="$(ls python/drivehierarchy/_core*.so | head -1)"
    if [ -n "$(find env agents benchmark python/src python/build.rs python/Cargo.toml Cargo.toml Cargo.lock \
        -newer "$core" \( -name '*.rs' -o -name Cargo.toml -o -name Cargo.lock -o -name '*.cpp' \) \
        -not -path '*/target/*' -not -path '*/tests/*' -print -quit)" ]; then
        step "rebuild the extension (a Rust source is newer than $core)"
        env -u SUMO_HOME "${BUILD[@]}" "$PY" -m pip install --quiet --no-deps --no-build-isolation -e .
    fi
    export PATH="$PWD/.venv/bin:$PATH"
    step "cargo fmt"; cargo fmt --all -- --check
    step "ruff";      $PY -m ruff check .
                      $PY -m ruff format --check .
    step "stubtest";  $PY -m mypy.stubtest drivehierarchy._core --allowlist python/stubtest-allowlist.txt
    step "mypy";      $PY -m mypy
    step "pytest (quick)"
    $PY -m pytest tests -n 2 --dist loadfile -q --durations=10 "${QUICK_SKIP[@]}" "$@"
    step "done"
    exit 0
fi

rust_log="$(mktemp)"
fuzz_log="$(mktemp)"
checks_log="$(mktemp)"
built="$(mktemp -u)"  # exists once the install has built the extension
deps="$(mktemp -u)"   # exists once the install has installed the dependencies (DH_DEPS_DONE)
rust_lane() {
    set -euo pipefail
    step "rust: cargo fmt"; cargo fmt --all -- --check
    # Ruff and mypy need no build, only the dependencies: they run here, in the install's serial
    # tail (the extension crate builds on one core while this lane would wait), instead of beside
    # pytest when both cores are busy.
    step "rust: waiting for the install's dependencies"
    until [ -e "$deps" ]; do sleep 1; done
    step "rust: ruff";  $PY -m ruff check .
                        $PY -m ruff format --check .
    step "rust: mypy";  $PY -m mypy  # [tool.mypy] in pyproject.toml: strict on envs, agents, benchmark
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
# The fuzz targets build at the lowest CPU priority: a second full build (nightly, coverage
# instrumentation) that nothing else waits for. Beside the install at normal priority it took a
# core from the extension's build (the install: 275 s with it, 193 s without); niced, it takes
# the cycles the install and pytest leave idle (the extension's serial tail, pytest's waits on
# sockets and servers). The bounded runs (3 s per target, by the clock) run at normal priority,
# so each gets its share of executions. CARGO_INCREMENTAL=0: a fresh clone builds the fuzz crate
# once, so incremental caches are work nobody reads. Debug info: fuzz/Cargo.toml's dev profile
# (line tables for our crates, none for dependencies).
fuzz_lane() {
    set -euo pipefail
    step "fuzz: build (nice 19)"
    CARGO_INCREMENTAL=0 FUZZ_DEV=1 FUZZ_BUILD_ONLY=1 nice -n 19 bash scripts/fuzz.sh 3
    step "fuzz: run";  CARGO_INCREMENTAL=0 FUZZ_DEV=1 bash scripts/fuzz.sh 3
    step "fuzz: done"
}
# The stub contract and the docs site need the built extension: short, and independent of
# pytest, so they run beside it instead of before it. The docs build is strict and not --quiet: --quiet raises the log level
# above WARNING, so strict mode would never count a warning (tests/docs/test_docs_build.py holds
# the gate to it). A clean build prints three lines.
checks_lane() {
    set -euo pipefail
    step "checks: stubtest"; $PY -m mypy.stubtest drivehierarchy._core --allowlist python/stubtest-allowlist.txt
    step "checks: docs";     DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $PY -m mkdocs build --strict --site-dir "$(mktemp -d)"
    step "checks: done"
}
rust_lane >"$rust_log" 2>&1 &
rust_pid=$!
fuzz_lane >"$fuzz_log" 2>&1 &
fuzz_pid=$!
checks_pid=""
# A failing Python lane (set -e) must not leave the other lanes running.
cleanup() {
    local pid
    for pid in "$rust_pid" "$fuzz_pid" $checks_pid; do
        pkill -P "$pid" 2>/dev/null || true
        kill "$pid" 2>/dev/null || true
    done
    rm -f "$built" "$deps"
}
trap cleanup EXIT

env "${BUILD[@]}" DH_DEPS_DONE="$deps" bash scripts/install.sh all
touch "$built"
export PATH="$PWD/.venv/bin:$PATH"
checks_lane >"$checks_log" 2>&1 &
checks_pid=$!
# Two workers, each taking whole files (`--dist loadfile`): a file's module fixtures (the docs
# walk's shared folder, a loopback server) stay in one process. Three are faster for pytest alone
# (369 s vs 401 s: a worker often waits on a socket, a server or a browser), but not in the gate,
# where the Rust lane fills those gaps: there a third worker only stretched the long sequential
# files (the docs walk) and the Rust lane (802 s on a fresh clone, against 751-783 s with two).
step "pytest";   $PY -m pytest tests -n 2 --dist loadfile --durations=15 "$@"
step "pytest done; waiting for the other lanes"
checks_rc=0
wait "$checks_pid" || checks_rc=$?
rust_rc=0
wait "$rust_pid" || rust_rc=$?
fuzz_rc=0
wait "$fuzz_pid" || fuzz_rc=$?
trap - EXIT
rm -f "$built" "$deps"
echo "---- checks lane (stubtest, docs) ----"
cat "$checks_log"
echo "---- Rust lane (fmt, ruff, mypy, clippy, cargo test, wheel) ----"
cat "$rust_log"
echo "---- fuzz lane (the fuzz targets' build and bounded run) ----"
cat "$fuzz_log"
rm -f "$rust_log" "$fuzz_log" "$checks_log"
if [ "$checks_rc" != 0 ]; then
    echo "test.sh: the checks lane failed (exit $checks_rc; its output is above)" >&2
fi
if [ "$rust_rc" != 0 ]; then
    echo "test.sh: the Rust lane failed (exit $rust_rc; its output is above)" >&2
fi
if [ "$fuzz_rc" != 0 ]; then
    echo "test.sh: the fuzz lane failed (exit $fuzz_rc; its output is above)" >&2
fi
if [ "$checks_rc" != 0 ] || [ "$rust_rc" != 0 ] || [ "$fuzz_rc" != 0 ]; then
    exit 1
fi
step "done"
