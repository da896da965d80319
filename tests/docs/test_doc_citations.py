"""Code, tests and docs cite the protocol and the architecture by the anchors of
`docs/protocol.md` and `docs/architecture.md`: every cited anchor exists, and no citation points
at a spec file outside the repository (`PROTOCOL §2.3`, `ARCHITECTURE.md`)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = ("protocol", "architecture")
# `docs/protocol.md#r4-termination, #r4-scene-score` or `... #answer-parsing and #record-scores`.
_CITATION = re.compile(r"docs/(protocol|architecture)\.md((?:#[a-z0-9-]+(?:,? (?:and )?)?)+)")
_STALE = re.compile(r"PROTOCOL(?:\.md)?\s*§|ARCHITECTURE(?:\.md| seam)")


def _sources() -> list[Path]:
    try:
        listed = subprocess.run(
            ["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True, text=True,
            check=True,
        ).stdout.split()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    suffixes = {".rs", ".py", ".pyi", ".md", ".js", ".html", ".toml", ".dict", ".sh"}
    this = Path(__file__).resolve()  # its docstring and messages name the patterns
    return [
        ROOT / p for p in listed if Path(p).suffix in suffixes and (ROOT / p).is_file() and ROOT / p != this
    ]


def _anchors(page: str) -> set[str]:
    text = (ROOT / "docs" / f"{page}.md").read_text(encoding="utf-8")
    return set(re.findall(r"\{#([a-z0-9-]+)\}", text))


def test_cited_anchors_exist() -> None:
    anchors = {page: _anchors(page) for page in PAGES}
    missing, cited = [], 0
    for path in _sources():
        for n, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            for page, tail in _CITATION.findall(line):
                for anchor in re.findall(r"#([a-z0-9-]+)", tail):
                    cited += 1
                    if anchor not in anchors[page]:
                        missing.append(f"{path.relative_to(ROOT)}:{n}: docs/{page}.md#{anchor}")
    assert cited > 50, f"only {cited} citations found: is the pattern still right?"
    assert not missing, "citations of anchors that do not exist:\n" + "\n".join(missing)


def test_no_citation_of_spec_files_outside_the_repository() -> None:
    stale = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
        for path in _sources()
        for n, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1)
        if _STALE.search(line)
    ]
    assert not stale, "cite docs/protocol.md#anchor or docs/architecture.md#anchor instead:\n" + "\n".join(
        stale
    )
