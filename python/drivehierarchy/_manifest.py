"""Facts every run manifest records about the code that wrote it (shared by the R4 and open-loop
runners)."""

from __future__ import annotations

import subprocess
from pathlib import Path


def git_commit() -> str | None:
    """Commit of the source tree this package runs from when it is a git checkout; None when it
    is not, when git is absent, or when git does not answer within 5 s (a manifest never fails on
    this)."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5, check=False
        )
    except (OSError, subprocess.SubprocessError):  # no git, or TimeoutExpired
        return None
    return (out.stdout.strip() or None) if out.returncode == 0 else None
