"""This machine's process table, read from /proc (Linux): what a test or the soak checks for
processes left over (SUMO subprocesses, workers, zombies)."""

from __future__ import annotations

import os
from pathlib import Path


def process_table() -> dict[int, tuple[int, str, str]]:
    """pid → (parent pid, name, state letter) of every process visible now; zombies are "Z"."""
    table: dict[int, tuple[int, str, str]] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:  # it ended while we looked
            continue
        # The name is in parentheses and may itself hold spaces or parentheses.
        fields = stat[stat.rindex(")") + 2 :].split()
        table[int(d.name)] = (int(fields[1]), stat[stat.index("(") + 1 : stat.rindex(")")], fields[0])
    return table


def descendants(root: int | None = None, *, zombies: bool = False) -> list[tuple[int, str]]:
    """(pid, name) of every process descending from `root` (default: this one), sorted; zombies
    (which hold nothing but an exit status) only with `zombies`."""
    root = os.getpid() if root is None else root
    table = {pid: row for pid, row in process_table().items() if zombies or row[2] != "Z"}
    out = []
    for pid, (_, name, _) in table.items():
        p = pid
        while p in table and p != root:
            p = table[p][0]
        if p == root and pid != root:
            out.append((pid, name))
    return sorted(out)
