"""The docs check of `scripts/test.sh` can fail: run with the gate's own `mkdocs build` flags on a
copy of the site with one page left out of the nav, the build aborts and names that page. (With
`--quiet`, mkdocs raises its log level above WARNING and strict mode never sees a warning.)"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TEST_SH = ROOT / "scripts" / "test.sh"

pytest.importorskip("mkdocs", reason="the docs site needs the dev extra (mkdocs)")


def _gate_flags() -> list[str]:
    """The flags the gate passes to `mkdocs build`, without its output folder."""
    match = re.search(r"-m mkdocs build ([^\n]*)", TEST_SH.read_text(encoding="utf-8"))
    assert match, "scripts/test.sh no longer runs `mkdocs build`"
    flags = shlex.split(match.group(1), comments=True)
    if "--site-dir" in flags:
        i = flags.index("--site-dir")
        del flags[i : i + 2]
    return flags


def test_gate_build_is_strict_and_not_quiet() -> None:
    flags = _gate_flags()
    assert "--strict" in flags
    assert not {"-q", "--quiet"} & set(flags), "--quiet hides the warnings strict mode counts"


def test_stray_page_fails_the_gate_build(tmp_path: Path) -> None:
    site = tmp_path / "src"
    shutil.copytree(ROOT / "docs", site / "docs")
    shutil.copy2(ROOT / "mkdocs.yml", site / "mkdocs.yml")
    (site / "docs" / "stray-page.md").write_text("# Not in the nav\n", encoding="utf-8")
    env = {**os.environ, "DISABLE_MKDOCS_2_WARNING": "true", "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", *_gate_flags(), "--site-dir", str(tmp_path / "site")],
        cwd=site, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    log = run.stdout + run.stderr
    assert run.returncode != 0, f"the build passed with a page outside the nav:\n{log}"
    assert "not included in the" in log and "stray-page.md" in log, log
