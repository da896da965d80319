#!/usr/bin/env python3
"""Builds the project's SUMO networks from their hand-written netconvert sources.

    python scenarios/maps/build.py              # every map in build.toml, in place
    python scenarios/maps/build.py town02       # one map
    python scenarios/maps/build.py --out-dir D  # write D/<map>/<map>.net.xml instead
    python scenarios/maps/build.py --check      # rebuild into a temp folder, compare with the committed nets

The per-map inputs and options live in build.toml beside this file. The built nets are
committed, so a rebuild is only needed after editing sources; `--check` (and the test
tests/scenarios/test_maps_rebuild.py) keeps sources and nets from drifting apart. Uses the
netconvert of the eclipse-sumo package (pinned in pyproject.toml), else the one on PATH.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from dataclasses import dataclass
from pathlib import Path

MAPS_DIR = Path(__file__).resolve().parent
TABLE = MAPS_DIR / "build.toml"

# netconvert's header: "<!-- generated on <time> by Eclipse SUMO netconvert <version>" followed by
# the echoed configuration (which names the output path) up to "-->". Everything after it is the net.
_HEADER = re.compile(r"<!-- generated on .*?-->\s*", re.DOTALL)


class BuildError(Exception):
    """A map that cannot be built: unknown name, bad table entry, missing source, netconvert failure."""


@dataclass(frozen=True)
class MapSpec:
    name: str
    sources: dict[str, str]
    options: list[str]

    @property
    def folder(self) -> Path:
        return MAPS_DIR / self.name

    @property
    def net(self) -> Path:
        return self.folder / f"{self.name}.net.xml"


def load_table(path: Path = TABLE) -> dict[str, MapSpec]:
    """The maps of build.toml; errors name the file and the field."""
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise BuildError(f"{path}: {e}") from e
    maps: dict[str, MapSpec] = {}
    for name, entry in raw.items():
        if not isinstance(entry, dict):
            raise BuildError(f"{path}: [{name}] must be a table")
        unknown = set(entry) - {"sources", "options"}
        if unknown:
            raise BuildError(f"{path}: [{name}] unknown keys {sorted(unknown)}")
        sources = entry.get("sources")
        if (
            not isinstance(sources, dict)
            or not sources
            or not all(isinstance(v, str) for v in sources.values())
        ):
            raise BuildError(
                f"{path}: [{name}].sources must be a non-empty table of file names, got {sources!r}"
            )
        options = entry.get("options", [])
        if not isinstance(options, list) or not all(isinstance(o, str) for o in options):
            raise BuildError(f"{path}: [{name}].options must be a list of strings, got {options!r}")
        maps[name] = MapSpec(name, dict(sources), list(options))
    return maps


def find_netconvert() -> str | None:
    """netconvert of the installed eclipse-sumo package, else the one on PATH, else None."""
    try:
        import sumo  # eclipse-sumo wheel

        cand = Path(sumo.SUMO_HOME) / "bin" / "netconvert"
        if cand.exists():
            return str(cand)
    except ImportError:
        pass
    return shutil.which("netconvert")


def netconvert_command(exe: str, spec: MapSpec, output: str) -> list[str]:
    """The command line, with file names relative to the map folder (the working directory), so
    the configuration netconvert echoes into the net's header carries no machine paths."""
    cmd = [exe]
    for option, file in spec.sources.items():
        if not (spec.folder / file).is_file():
            raise BuildError(f"{TABLE}: [{spec.name}].sources.{option}: {spec.folder / file} not found")
        cmd += [f"--{option}", file]
    return [*cmd, "--output-file", output, *spec.options]


def build(spec: MapSpec, out_dir: Path | None = None, exe: str | None = None) -> Path:
    """Runs netconvert for one map; returns the written net (in place, or out_dir/<map>/)."""
    exe = exe or find_netconvert()
    if exe is None:
        raise BuildError("netconvert not found: pip install eclipse-sumo")
    if out_dir is None:
        out, output = spec.net, spec.net.name
    else:
        out = (out_dir / spec.name / spec.net.name).resolve()
        out.parent.mkdir(parents=True, exist_ok=True)
        output = str(out)
    proc = subprocess.run(
        netconvert_command(exe, spec, output), cwd=spec.folder, capture_output=True, text=True
    )
    if proc.returncode != 0:
        msg = (proc.stderr or proc.stdout).strip().splitlines()
        raise BuildError(f"{spec.name}: netconvert failed (exit {proc.returncode}): " + " | ".join(msg[-5:]))
    return out


def net_body(text: str) -> str:
    """The net without netconvert's header comment (time, version, echoed configuration)."""
    return _HEADER.sub("", text, count=1)


def differences(spec: MapSpec, rebuilt: Path) -> str | None:
    """None when the rebuilt net equals the committed one (header aside), else the first difference."""
    if not spec.net.is_file():
        return f"{spec.net} is missing"
    a = net_body(spec.net.read_text(encoding="utf-8")).splitlines()
    b = net_body(rebuilt.read_text(encoding="utf-8")).splitlines()
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if x != y:
            return (
                f"{spec.name}: line {i + 1} of the net body differs:\n"
                f"  committed: {x.strip()[:200]}\n  rebuilt:   {y.strip()[:200]}"
            )
    if len(a) != len(b):
        return f"{spec.name}: the committed net body has {len(a)} lines, the rebuilt one {len(b)}"
    return None


def select(maps: dict[str, MapSpec], names: list[str]) -> list[MapSpec]:
    unknown = [n for n in names if n not in maps]
    if unknown:
        raise BuildError(f"unknown map(s) {unknown}; {TABLE.name} has {sorted(maps)}")
    return [maps[n] for n in (names or sorted(maps))]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("maps", nargs="*", help="map names of build.toml (default: all)")
    ap.add_argument("--out-dir", type=Path, help="write <dir>/<map>/<map>.net.xml instead of in place")
    ap.add_argument(
        "--check", action="store_true", help="rebuild into a temp folder and compare with the committed nets"
    )
    args = ap.parse_args(argv)
    try:
        specs = select(load_table(), args.maps)
        if args.check:
            with tempfile.TemporaryDirectory() as tmp:
                bad = [d for s in specs if (d := differences(s, build(s, Path(tmp)))) is not None]
            for d in bad:
                print(d, file=sys.stderr)
            print(f"{len(specs) - len(bad)}/{len(specs)} maps match their sources")
            return 1 if bad else 0
        for s in specs:
            print(f"wrote {build(s, args.out_dir)}")
    except BuildError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
