"""The editor's file side: paths confined to the root folder, and TOML edits that keep the file.

Edits are applied to the file's text with `tomlkit`, which keeps comments, order and layout: a
file loaded and saved with no change is byte-identical, and one edit changes only what it names.
"""

from __future__ import annotations

import os
import re
from pathlib import Path, PurePosixPath
from typing import Any

import tomlkit
from tomlkit.items import AoT, Array, InlineTable, Table

from drivehierarchy._core import DriveHierarchyError

MAX_FILE_BYTES = 1_000_000


class PathRefused(ValueError):
    """A path the editor will not read or write, with the reason."""


def confine(root: Path, rel: str, *, must_exist: bool = False) -> Path:
    """`rel` (a POSIX path relative to `root`) as a path inside `root`, or `PathRefused`.

    Refuses absolute paths, `..` components, and paths that leave the root through a symlink
    (the file itself or any folder on the way); only `.toml` files are served.
    """
    if not rel or "\x00" in rel:
        raise PathRefused(f"path {rel!r}: empty or contains NUL")
    if rel.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", rel) or os.path.isabs(rel):
        raise PathRefused(f"path {rel!r}: absolute paths are refused; give a path relative to the root")
    parts = PurePosixPath(rel.replace("\\", "/")).parts
    if ".." in parts:
        raise PathRefused(f"path {rel!r}: `..` is refused; the editor stays inside its root folder")
    if not rel.endswith(".toml"):
        raise PathRefused(f"path {rel!r}: only scenario files (*.toml) are read and written")
    root_real = root.resolve()
    candidate = root_real.joinpath(*parts)
    real = candidate.resolve()
    if real != root_real and root_real not in real.parents:
        raise PathRefused(f"path {rel!r}: leaves the root folder through a symlink ({real})")
    if must_exist and not real.is_file():
        raise PathRefused(f"path {rel!r}: no such file")
    return candidate


def list_scenarios(root: Path) -> list[str]:
    """Every `*.toml` under the root (relative POSIX paths), not following symlinks out."""
    root_real = root.resolve()
    out = []
    for p in sorted(root_real.rglob("*.toml")):
        real = p.resolve()
        if (
            root_real in real.parents
            and ".venv" not in p.parts
            and "target" not in p.relative_to(root_real).parts
        ):
            out.append(p.relative_to(root_real).as_posix())
    return out


def _container(doc: Any, key: str | int) -> Any:
    try:
        return doc[key]
    except (KeyError, IndexError, TypeError) as exc:
        raise ValueError(f"no `{key}` here") from exc


def _as_toml(value: Any) -> str:
    item = _item(value)
    return item.as_string() if hasattr(item, "as_string") else tomlkit.item(item).as_string()


def _item(value: Any) -> Any:
    """A JSON value as a tomlkit item; objects become inline tables (`{ lane = ..., s = ... }`)."""
    if isinstance(value, dict):
        # Written as the suite writes them: `{ lane = "C2T_1", s = 140.0 }`.
        body = ", ".join(f"{tomlkit.key(k).as_string()} = {_as_toml(v)}" for k, v in value.items())
        return tomlkit.parse(f"v = {{ {body} }}" if body else "v = {}")["v"]
    if isinstance(value, list):
        a = tomlkit.array()
        for v in value:
            a.append(_item(v))
        return a
    return value


def _table(value: dict[str, Any]) -> Table:
    t = tomlkit.table()
    for k, v in value.items():
        if isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            aot = tomlkit.aot()
            for x in v:
                aot.append(_table(x))
            t[k] = aot
        elif isinstance(v, dict) and any(isinstance(x, (dict, list)) for x in v.values()):
            t[k] = _table(v)
        else:
            t[k] = _item(v)
    return t


def _insert_key(parent: Any, key: Any, item: Any) -> bool:
    """Adds a new plain key to a `[table]` right after its last key, so the blank lines and
    comments that end the table (the ones before the next `[[actors]]`) stay where they are.
    False when this is not such a case (the caller sets the key as usual)."""
    if not isinstance(parent, Table) or not isinstance(key, str) or key in parent:
        return False
    if isinstance(item, (Table, AoT)):
        return False
    body = parent.value.body
    keys = [i for i, (k, _) in enumerate(body) if k is not None]
    if not keys or keys[-1] == len(body) - 1:
        return False
    parent.value._insert_at(keys[-1] + 1, key, item)
    new = body[keys[-1] + 1][1]
    if "\n" not in new.trivia.trail:
        new.trivia.trail += "\n"  # its own line: the whitespace after it stays a blank line
    return True


def _keep_float(current: Any, value: Any) -> Any:
    """A whole number typed over a float stays a float (`30.0`, not `30`): JSON (the page's
    numbers) does not tell 30 from 30.0, the file does."""
    if isinstance(current, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def _floats(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _floats(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_floats(v) for v in value]
    return float(value) if isinstance(value, int) and not isinstance(value, bool) else value


def doc_json(text: str) -> dict[str, Any] | None:
    """The TOML text as plain JSON-able data (None when it is no TOML)."""
    try:
        return tomlkit.parse(text).unwrap()
    except tomlkit.exceptions.TOMLKitError:
        return None


def path_str(path: list[str | int]) -> str:
    """`["actors", 0, "start"]` → `actors[0].start` (the validator's field notation)."""
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out


def apply_edits(text: str, edits: list[dict[str, Any]]) -> str:
    """Applies edits to TOML text: `{"path": [...], "value": v}` sets, `{"path": [...],
    "delete": true}` removes, `{"path": ["actors"], "append": {...}}` adds a table to an array
    of tables (created when missing) or a value to an array (`["actors", 0, "route", "lanes"]`);
    `"table": true` beside a table `value` writes a new key as a `[table]` of its own rather than
    inline; `"floats": true` writes the value's whole numbers as floats (`0.0`: JSON, the page's
    numbers, has no 0.0 apart from 0), except over an int already there. Everything not named
    keeps its bytes."""
    doc = tomlkit.parse(text)
    for e in edits:
        path = e.get("path")
        if not isinstance(path, list) or not path:
            raise ValueError(f"edit {e!r}: `path` must be a non-empty list of keys and indices")
        where = path_str(path)
        parent: Any = doc
        for k in path[:-1]:
            if isinstance(k, str) and isinstance(parent, dict) and k not in parent and "delete" not in e:
                # Setting a key of a missing table makes the table: `[traffic]` at the top,
                # an inline `{ ... }` inside an entry.
                top = isinstance(parent, tomlkit.TOMLDocument)
                parent[k] = tomlkit.table() if top else tomlkit.inline_table()
            try:
                parent = _container(parent, k)
            except ValueError as exc:
                raise ValueError(f"edit of `{where}`: {exc}") from exc
        last = path[-1]
        if "append" in e:
            value = _floats(e["append"]) if e.get("floats") else e["append"]
            if isinstance(parent, (Table, tomlkit.TOMLDocument)) and last not in parent:
                if not isinstance(value, dict):
                    raise ValueError(f"edit of `{where}`: no array here to append to")
                parent.append(last, tomlkit.aot())
            target = _container(parent, last)
            if isinstance(target, AoT):
                if not isinstance(value, dict):
                    raise ValueError(f"edit of `{where}`: an array of tables takes a table")
                table = tomlkit.table()
                table.trivia.indent = "\n"  # a blank line before the new `[[...]]`, as the suite has
                for k, v in value.items():
                    table[k] = _item(v)
                target.append(table)
            elif isinstance(target, Array):
                target.append(_item(value))
            else:
                raise ValueError(f"edit of `{where}`: not an array")
        elif e.get("delete"):
            try:
                del parent[last]
            except (KeyError, IndexError) as exc:
                raise ValueError(f"edit of `{where}`: nothing to delete") from exc
        elif "value" in e:
            value = e["value"]
            current = parent.get(last) if isinstance(parent, dict) else None
            if isinstance(parent, list) and isinstance(last, int) and -len(parent) <= last < len(parent):
                current = parent[last]
            # A whole number typed over an int stays an int (`vehs_per_hour = 450`).
            if e.get("floats") and not (isinstance(current, int) and not isinstance(current, bool)):
                value = _floats(value)
            value = _keep_float(current, value)
            if isinstance(current, InlineTable) and isinstance(value, dict) and set(current) == set(value):
                # Same keys in place: the table keeps its layout, only changed values differ.
                for k, v in value.items():
                    v = _keep_float(current.get(k), v)
                    if current.get(k) != v:
                        current[k] = _item(v)
                continue
            try:
                # A `[table]` stays a table (with `[[sub]]` arrays), not an inline one.
                # `"table": true` makes a new `[parent.key]` table (`[traffic.random]`).
                as_table = isinstance(value, dict) and (isinstance(current, Table) or bool(e.get("table")))
                item = _table(value) if as_table else _item(value)
                if not _insert_key(parent, last, item):
                    parent[last] = item
            except (IndexError, TypeError) as exc:
                raise ValueError(f"edit of `{where}`: {exc}") from exc
        else:
            raise ValueError(f"edit of `{where}`: give `value`, `delete` or `append`")
    out = tomlkit.dumps(doc)
    # The file ends as it did: a table appended at the end still ends with the newline, one
    # removed from the end leaves no blank line behind.
    return out.rstrip("\r\n") + text[len(text.rstrip("\r\n")) :]


def error_fields(exc: DriveHierarchyError, root: Path | None = None) -> dict[str, Any]:
    """What the page shows of a validator error: the message (paths under `root` made relative)
    and the `file`, `line`, `column`, `field`, `value` and `reason` the core error carries
    (None where it does not know them)."""

    def rel(text: str) -> str:
        return text.replace(str(root) + os.sep, "") if root is not None else text

    file = getattr(exc, "file", None)
    return {
        "message": rel(str(exc)),
        "file": rel(file) if file is not None else None,
        "line": getattr(exc, "line", None),
        "column": getattr(exc, "column", None),
        "field": getattr(exc, "field", None),
        "value": getattr(exc, "value", None),
        "reason": getattr(exc, "reason", None),
    }


def field_path(field: str) -> list[str | int] | None:
    """`actors[0].start.of` → `["actors", 0, "start", "of"]` (None: not a plain key path)."""
    out: list[str | int] = []
    for part in field.split("."):
        m = re.fullmatch(r"([A-Za-z0-9_-]*)((?:\[\d+\])*)", part)
        if not m:
            return None
        if m.group(1):
            out.append(m.group(1))
        out.extend(int(i) for i in re.findall(r"\[(\d+)\]", m.group(2)))
    return out or None


def relocate_error(err: dict[str, Any], edited: str, original: str) -> dict[str, Any]:
    """An error found on `edited` (keys removed from `original`) with its line number mapped
    back to `original`."""
    line = err.get("line")
    if not line:
        return err
    import difflib

    a, b = original.splitlines(), edited.splitlines()
    mapped = line
    index = line - 1
    for tag, i1, _i2, j1, j2 in difflib.SequenceMatcher(None, a, b, autojunk=False).get_opcodes():
        if j1 <= index < j2:
            mapped = i1 + (index - j1) + 1 if tag == "equal" else i1 + 1
            break
    out = dict(err)
    out["line"] = mapped
    out["message"] = re.sub(
        r"^(.*?):\d+:(\d+): ", lambda m: f"{m.group(1)}:{mapped}:{m.group(2)}: ", err["message"], count=1
    )
    return out
