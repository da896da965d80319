"""Every `drivehierarchy ...` command shown in the README and the docs is one the CLI accepts:
its sub-commands and flags parse with the real argparse parser (a renamed flag breaks this test,
not a reader's copy-paste)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from drivehierarchy.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_BLOCK = re.compile(r"^```([\w+-]*)\n(.*?)^```", re.S | re.M)


def _commands(page: Path) -> list[str]:
    out = []
    for lang, block in _BLOCK.findall(page.read_text(encoding="utf-8")):
        if lang not in ("", "bash", "sh", "console", "text"):
            continue
        text = block.replace("\\\n", " ")
        for line in text.splitlines():
            line = line.split(" #", 1)[0].strip()
            if line.startswith("drivehierarchy "):
                out.append(line)
    return out


def _normalise(cmd: str) -> list[str]:
    # `[--a | --b]` in docs shows alternatives: keep the first; `...` and `[N ...]` are elisions.
    cmd = re.sub(r"\[([^\[\]]*?)\]", lambda m: m.group(1).split("|")[0], cmd)
    return [t for t in shlex.split(cmd)[1:] if t not in ("...", "…")]


CASES = [(page.relative_to(ROOT).as_posix(), cmd) for page in PAGES for cmd in _commands(page)]


def test_the_docs_show_commands() -> None:
    assert len(CASES) >= 30


@pytest.mark.parametrize(("page", "command"), CASES, ids=[f"{p}:{c[:60]}" for p, c in CASES])
def test_documented_command_parses(page: str, command: str) -> None:
    parser = build_parser()
    try:
        args = parser.parse_args(_normalise(command))
    except SystemExit as exc:  # argparse's way to reject
        pytest.fail(f"{page}: `{command}` is rejected by the CLI (exit {exc.code})")
    assert callable(args.func)
