#!/usr/bin/env bash
# Installs drivehierarchy into the project's own virtual environment `.venv/` (created on first
# use; the system Python is never touched) and builds the Rust core with maturin (release).
#   bash scripts/install.sh          the core: env, suite, expert, SUMO, VLM harness, reports, open loop
#   bash scripts/install.sh all      every extra (what scripts/test.sh needs; pulls torch, ~6 GB)
#   bash scripts/install.sh rl,dev   any extras of pyproject.toml
# Safe to re-run. Needs Python >= 3.11 with venv, a Rust toolchain and a C++ compiler.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"
PY="${PYTHON:-python3}"

if ! command -v cargo >/dev/null; then
    echo "install: no Rust toolchain (cargo) on PATH; install one with rustup (https://rustup.rs)" >&2
    exit 1
fi
if [ ! -x .venv/bin/python ]; then
    if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
        echo "install: $("$PY" --version 2>&1) is too old: drivehierarchy needs Python >= 3.11 (set PYTHON=...)" >&2
        exit 1
    fi
    "$PY" -m venv .venv || {
        echo "install: '$PY -m venv' failed; on Debian/Ubuntu: apt-get install python3-venv" >&2
        exit 1
    }
fi
VPY=.venv/bin/python
"$VPY" -m pip install --quiet --upgrade "pip>=23" "maturin>=1.7,<2" "uv>=0.5"

# SUMO's native libraries come with the pinned eclipse-sumo wheel; it is installed first so that
# their system libraries can be checked below. (The build itself gets SUMO's C++ headers from the
# same pin, a build requirement in pyproject.toml: no SUMO_HOME is needed.)
sumo_pin="$(grep -o '"eclipse-sumo==[^"]*"' pyproject.toml | head -1 | tr -d '"')"
# uv, not pip: the build waits for this 300 MB wheel, which uv unpacks in a fraction of pip's time.
.venv/bin/uv pip install --quiet --python "$VPY" "$sumo_pin"
SUMO_HOME="$("$VPY" -c 'import sumo; print(sumo.SUMO_HOME)')"

# The shim needs a C++ compiler, and SUMO's libraries (libsumocpp, like the libsumo module) a few
# system libraries (X11, GL) that a minimal Debian/Ubuntu image may lack. As root (CI, containers)
# they are installed with apt-get; otherwise the missing packages are named and nothing is run.
apt_packages="g++ libx11-6 libxext6 libxrender1 libgl1 libxcb1 libexpat1 zlib1g"
missing="$(ldd "$SUMO_HOME/lib64/libsumocpp.so" | awk '/not found/ {print $1}' || true)"
command -v c++ >/dev/null || missing="$missing c++"
if [ -n "$missing" ]; then
    if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
        echo "install: installing system libraries for SUMO (missing:$missing)"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $apt_packages
    else
        echo "install: SUMO's native libraries need:$missing" >&2
        echo "install: on Debian/Ubuntu run: sudo apt-get install $apt_packages" >&2
        exit 1
    fi
fi
# The editor's browser tests (tests/editor/test_e2e.py, the dev extra) drive Debian's chromium
# through Playwright: the system browser, no download.
case ",$extras," in
*,dev,* | *,all,*)
    if ! command -v chromium >/dev/null; then
        if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
            echo "install: installing chromium for the editor's browser tests"
            apt-get update -qq
            DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium
        else
            echo "install: the editor's browser tests need chromium: sudo apt-get install chromium" >&2
        fi
    fi
    ;;
esac
# The dependencies (mostly downloads: torch alone is ~1 GB) install in the background while the
# Rust core builds: uv resolves them from pyproject.toml's own lists (the same versions pip picks,
# in a seventh of pip's time: 22 s from a cold cache vs 170 s from a warm one for `all`), and the
# package itself is built and installed by pip with --no-deps, so the two never touch the same
# distribution. (pip builds it: uv would reuse a cached build of an unchanged pyproject.toml
# after a Rust change.)
reqs="$(mktemp)"
trap 'rm -f "$reqs"' EXIT
"$VPY" - "$extras" >"$reqs" <<'PY'
import sys
import tomllib

project = tomllib.load(open("pyproject.toml", "rb"))["project"]
extras = project.get("optional-dependencies", {})
out, seen = list(project["dependencies"]), set()


def add(extra: str) -> None:
    if extra in seen:
        return
    if extra not in extras:
        sys.exit(f"install: pyproject.toml has no extra {extra!r} (extras: {', '.join(extras)})")
    seen.add(extra)
    for req in extras[extra]:
        if req.startswith(project["name"] + "["):  # a self-reference, e.g. drivehierarchy[rl,dev]
            for inner in req[req.index("[") + 1 : req.index("]")].split(","):
                add(inner.strip())
        else:
            out.append(req)


for extra in filter(None, (e.strip() for e in sys.argv[1].split(","))):
    add(extra)
print("\n".join(out))
PY
# DH_DEPS_DONE (scripts/test.sh): a file touched once the dependencies are in, so that checks
# needing no build (ruff, mypy) can start while the Rust core still builds.
(
    .venv/bin/uv pip install --quiet --python "$VPY" -r "$reqs"
    if [ -n "${DH_DEPS_DONE:-}" ]; then touch "$DH_DEPS_DONE"; fi
) &
deps_pid=$!
# No build isolation: the venv already has pyproject's build requirements (maturin and the pinned
# eclipse-sumo, both installed above), so pip need not install SUMO's 300 MB wheel a second time
# into a throwaway environment before cargo starts (5-10 s). scripts/wheel_check.sh keeps the
# isolated build users' `pip wheel .` takes.
build_rc=0
env -u SUMO_HOME "$VPY" -m pip install --quiet --no-deps --no-build-isolation -e . || build_rc=$?
deps_rc=0
wait "$deps_pid" || deps_rc=$?
if [ "$deps_rc" != 0 ]; then
    echo "install: installing the dependencies${extras:+ of [$extras]} failed (uv exit $deps_rc, its output is above)" >&2
    exit "$deps_rc"
fi
if [ "$build_rc" != 0 ]; then
    echo "install: building drivehierarchy failed (pip exit $build_rc, its output is above)" >&2
    exit "$build_rc"
fi
echo "install: drivehierarchy${extras:+[$extras]} installed in .venv ($(du -sh .venv | cut -f1)); activate with: source .venv/bin/activate"
