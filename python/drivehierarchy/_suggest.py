"""Did you mean" hints for names a user types (scenario ids, agents, tasks)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def close_matches(name: str, choices: Iterable[str], n: int = 3) -> list[str]:
    """Up to `n` choices closest to `name`: difflib's ratio on the whole name, then on the last
    path part (a scenario typed without its category folder still finds its id)."""
    choices = list(dict.fromkeys(choices))
    found = difflib.get_close_matches(name, choices, n=n, cutoff=0.6)
    if len(found) < n:
        tails = {c.rsplit("/", 1)[-1]: c for c in choices}
        for tail in difflib.get_close_matches(name.rsplit("/", 1)[-1], list(tails), n=n, cutoff=0.6):
            if tails[tail] not in found:
                found.append(tails[tail])
    return found[:n]


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """`"; did you mean `a` or `b`?"`, or "" when nothing is close."""
    found = close_matches(name, choices)
    if not found:
        return ""
    quoted = [f"`{c}`" for c in found]
    listed = quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"
    return f"; did you mean {listed}?"
