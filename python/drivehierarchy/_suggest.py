"""Did you mean" hints for names a user types (scenario ids, agents, tasks, edges)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

CUTOFF = 0.6
# Suggest the runners-up only when they are about as close as the best (a one-letter typo names
# one id, not every id sharing a long common prefix).
MARGIN = 0.05


def close_matches(name: str, choices: Iterable[str], n: int = 3) -> list[str]:
    """Up to `n` choices closest to `name` (difflib's ratio on the whole name, or on its last
    path part: a scenario typed without its category folder still finds its id)."""

    def score(choice: str) -> float:
        whole = difflib.SequenceMatcher(None, name, choice).ratio()
        tail = difflib.SequenceMatcher(None, name.rsplit("/", 1)[-1], choice.rsplit("/", 1)[-1]).ratio()
        return max(whole, tail)

    scored = sorted(((score(c), c) for c in dict.fromkeys(choices)), key=lambda sc: (-sc[0], sc[1]))
    if not scored or scored[0][0] < CUTOFF:
        return []
    best = scored[0][0]
    return [c for s, c in scored[:n] if s >= max(CUTOFF, best - MARGIN)]


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """`"; did you mean `a` or `b`?"`, or "" when nothing is close."""
    found = close_matches(name, choices)
    if not found:
        return ""
    quoted = [f"`{c}`" for c in found]
    listed = quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"
    return f"; did you mean {listed}?"
