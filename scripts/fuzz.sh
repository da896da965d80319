#!/usr/bin/env bash
# Bounded coverage-guided fuzzing of the project's readers (docs/fuzzing.md).
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]
#
# Builds the cargo-fuzz targets in fuzz/ (nightly; installs cargo-fuzz when missing), seeds each
# target's corpus (fuzz/corpus/TARGET, kept between runs) from the project's own files, and runs
# every target for SECONDS_PER_TARGET (default 15) in one process. Exits non-zero if any target
# finds a crash; the input is left in fuzz/artifacts/TARGET/. FUZZ_DEV=1 builds the dev profile
# (below); FUZZ_BUILD_ONLY=1 only builds.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

secs=${1:-15}
shift || true
all=(scenario_toml scenario_world net_xml vlm_reply plan_reply run_log openloop_answer openloop_predictions)
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=("${all[@]}")

if ! rustup run nightly rustc --version >/dev/null 2>&1; then
    echo "fuzz.sh: needs the nightly toolchain (rustup toolchain install nightly)" >&2
    exit 2
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz.sh: installing cargo-fuzz from crates.io"
    cargo install cargo-fuzz --locked
fi

# The fuzz crate has its own target dir (its flags differ from the workspace build's).
unset CARGO_TARGET_DIR

# Seeds: the project's real inputs (never the original release's data).
seeds() {
    case $1 in
        scenario_toml | scenario_world) find -L scenarios env/tests/world_fixtures -name '*.toml' ;;
        net_xml) find -L scenarios/maps env/tests/world_fixtures -name '*.net.xml' ;;
        *) find fuzz/seeds/"$1" -type f ;;
    esac
}
dict() {
    case $1 in
        openloop_answer | openloop_predictions) echo fuzz/dicts/openloop.dict ;;
        scenario_world) echo fuzz/dicts/scenario_toml.dict ;;
        *) echo fuzz/dicts/"$1".dict ;;
    esac
}

# Release build with debug assertions (overflow checks); no sanitizer: the workspace has no
# unsafe code, and without ASan the targets run about twice as fast. 16 codegen units build
# several times faster than cargo-fuzz's default of 1 on a small machine, for somewhat slower
# runs (FUZZ_CODEGEN_UNITS=1 for long campaigns). FUZZ_DEV=1 (CI's bounded run) builds the
# unoptimised dev profile instead: less than half the build, for fewer runs per second.
if [ "${FUZZ_DEV:-0}" = 1 ]; then
    cgu=(--dev)
else
    cgu=(--codegen-units "${FUZZ_CODEGEN_UNITS:-16}")
fi
(cd fuzz && cargo +nightly fuzz build -s none "${cgu[@]}")
# FUZZ_BUILD_ONLY=1: build, run nothing (to build ahead of a run timed by the clock).
if [ "${FUZZ_BUILD_ONLY:-0}" = 1 ]; then exit 0; fi
mkdir -p fuzz/artifacts
failed=()
for t in "${targets[@]}"; do
    corpus=fuzz/corpus/$t
    log=fuzz/artifacts/$t.log
    mkdir -p "$corpus"
    seeds "$t" | while read -r f; do cp -n "$f" "$corpus/" 2>/dev/null || true; done
    echo "== $t (${secs}s)"
    rc=0
    (cd fuzz && cargo +nightly fuzz run -s none "${cgu[@]}" "$t" "$root/$corpus" -- -max_total_time="$secs" \
        -timeout=30 -dict="$root/$(dict "$t")" -print_final_stats=1) >"$log" 2>&1 || rc=$?
    grep -E '^(#[0-9]+[[:space:]]+DONE|stat::number_of_executed_units)' "$log" || true
    if [ "$rc" != 0 ]; then
        tail -n 40 "$log"
        failed+=("$t")
    fi
done
if [ ${#failed[@]} -gt 0 ]; then
    echo "fuzz.sh: crashes in: ${failed[*]} (inputs under fuzz/artifacts/, logs fuzz/artifacts/*.log)" >&2
    exit 1
fi
echo "fuzz.sh: no crashes"
