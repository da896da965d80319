"""Reference pages generated from the code at docs build time (mkdocs-gen-files).

- `reference/env.md`: the env's spaces, `STATE_FIELDS` and every `R4Config` field with its default
  and the comment the code gives it;
- `reference/scenario-schema.md`: every table and key of the scenario format, from the JSON Schema
  that `drivehierarchy scenario schema` derives from the Rust types;
- `reference/cli.md`: every `drivehierarchy` command's `--help`, from the argparse parser itself.

Nothing here is hand-kept: a renamed field or flag changes the page on the next build.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import json
import os
import textwrap
from typing import Any

import mkdocs_gen_files

from drivehierarchy import _core, cli
from drivehierarchy.envs import config as config_mod
from drivehierarchy.envs.r4 import STATE_FIELDS, DriveHierarchyR4Env

# argparse wraps help to the terminal width: fix it so the page does not depend on who builds it.
os.environ["COLUMNS"] = "100"


def _field_comments(cls: type) -> dict[str, str]:
    """The `# ...` comment lines written just above each dataclass field."""
    source = textwrap.dedent(inspect.getsource(cls))
    lines = source.splitlines()
    out: dict[str, str] = {}
    for node in ast.parse(source).body[0].body:  # type: ignore[attr-defined]
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            comment: list[str] = []
            i = node.lineno - 2
            while i >= 0 and lines[i].strip().startswith("#"):
                comment.insert(0, lines[i].strip().lstrip("#").strip())
                i -= 1
            out[node.target.id] = " ".join(comment)
    return out


def _default(f: dataclasses.Field[Any]) -> str:
    if f.default is not dataclasses.MISSING:
        return f"`{f.default!r}`"
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return f"`{type(f.default_factory()).__name__}()`"  # type: ignore[misc]
    return "required"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def config_table(cls: type) -> str:
    comments = _field_comments(cls)
    rows = ["| field | type | default | meaning |", "|---|---|---|---|"]
    for f in dataclasses.fields(cls):
        rows.append(
            f"| `{f.name}` | `{_cell(str(f.type))}` | {_default(f)} | {_cell(comments.get(f.name, ''))} |"
        )
    return "\n".join(rows)


def env_page() -> str:
    env = DriveHierarchyR4Env(front=None, bev=None)
    with_images = DriveHierarchyR4Env()
    parts = [
        "# Environment reference",
        "",
        "Generated from the code (`docs/_scripts/gen_reference.py`).",
        "",
        "## `DriveHierarchy-R4`",
        "",
        inspect.cleandoc(DriveHierarchyR4Env.__doc__ or ""),
        "",
        "## Spaces (default configuration)",
        "",
        "| key | space |",
        "|---|---|",
    ]
    for key, space in with_images.observation_space.spaces.items():
        parts.append(f"| `{key}` | `{_cell(repr(space))}` |")
    parts += ["", f'Action space (`action_mode="decision"`): `{with_images.action_space!r}`', ""]
    raw = DriveHierarchyR4Env(front=None, bev=None, action_mode="raw")
    parts += [f'Action space (`action_mode="raw"`): `{raw.action_space!r}`', ""]
    for e in (env, with_images, raw):
        e.close()
    parts += [
        "## State vector",
        "",
        '`obs["state"][i]` is `STATE_FIELDS[i]`:',
        "",
        "| i | field |",
        "|---|---|",
    ]
    parts += [f"| {i} | `{name}` |" for i, name in enumerate(STATE_FIELDS)]
    rust = _core.default_sim_config()
    parts += ["", "## `R4Config`", "", inspect.cleandoc(config_mod.R4Config.__doc__ or ""), ""]
    parts += [config_table(config_mod.R4Config), ""]
    for cls in (config_mod.CameraConfig, config_mod.BevConfig):
        parts += [
            f"### `{cls.__name__}`",
            "",
            inspect.cleandoc(cls.__doc__ or ""),
            "",
            config_table(cls),
            "",
        ]
    parts += [
        "## The Rust core's defaults",
        "",
        "`drivehierarchy._core.default_sim_config()`: the world's own defaults, which the dataclasses"
        " above mirror:",
        "",
        "```json",
        json.dumps(rust, indent=2, sort_keys=True),
        "```",
        "",
    ]
    return "\n".join(parts)


def _type_of(prop: dict[str, Any]) -> str:
    if "$ref" in prop:
        name = prop["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{name.lower()})"
    if "allOf" in prop and len(prop["allOf"]) == 1:
        return _type_of(prop["allOf"][0])
    for key in ("anyOf", "oneOf"):
        if key in prop:
            return " or ".join(_type_of(p) for p in prop[key])
    if "enum" in prop:
        return " \\| ".join(f"`{v!r}`" if not isinstance(v, str) else f'`"{v}"`' for v in prop["enum"])
    if "const" in prop:
        return f'`"{prop["const"]}"`' if isinstance(prop["const"], str) else f"`{prop['const']!r}`"
    t = prop.get("type", "any")
    if isinstance(t, list):
        t = " or ".join(t)
    if t == "array" and "items" in prop:
        return f"array of {_type_of(prop['items'])}"
    return t


def _range(prop: dict[str, Any]) -> str:
    bounds = []
    for key, sym in (
        ("minimum", "≥"),
        ("exclusiveMinimum", ">"),
        ("maximum", "≤"),
        ("exclusiveMaximum", "<"),
    ):
        if key in prop:
            bounds.append(f"{sym} {prop[key]}")
    for key, word in (("minItems", "items ≥"), ("maxItems", "items ≤"), ("minLength", "length ≥")):
        if key in prop:
            bounds.append(f"{word} {prop[key]}")
    return ", ".join(bounds)


def _props_table(obj: dict[str, Any]) -> list[str]:
    required = set(obj.get("required", []))
    rows = ["| key | type | required | default | range | meaning |", "|---|---|---|---|---|---|"]
    for name, prop in obj.get("properties", {}).items():
        default = f"`{json.dumps(prop['default'])}`" if "default" in prop else ""
        rows.append(
            f"| `{name}` | {_cell(_type_of(prop))} | {'yes' if name in required else ''} | {_cell(default)} "
            f"| {_cell(_range(prop))} | {_cell(prop.get('description', ''))} |"
        )
    return rows


def schema_page() -> str:
    schema = _core.scenario_json_schema()
    defs = schema.get("definitions") or schema.get("$defs") or {}
    parts = [
        "# Scenario format reference",
        "",
        "Generated from the JSON Schema that the Rust types derive (`drivehierarchy scenario schema`); "
        "the prose guide with examples is [the scenario format](../scenario-format.md).",
        "",
        "## Top level",
        "",
        schema.get("description", ""),
        "",
        *_props_table(schema),
        "",
    ]
    for name in sorted(defs):
        d = defs[name]
        parts += [f"## {name}", "", _cell(d.get("description", "")), ""]
        if "properties" in d:
            parts += _props_table(d)
        else:
            parts.append(f"One of: {_type_of(d)}")
            for key in ("oneOf", "anyOf"):
                for alt in d.get(key, []):
                    if "properties" in alt:
                        parts += ["", _cell(alt.get("description", "")), "", *_props_table(alt)]
        parts.append("")
    return "\n".join(parts)


def _commands(
    parser: argparse.ArgumentParser, path: list[str]
) -> list[tuple[list[str], argparse.ArgumentParser]]:
    out = [(path, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _commands(sub, [*path, name])
    return out


def cli_page() -> str:
    parser = cli.build_parser()
    parts = ["# Command-line reference", "", "Generated from the `drivehierarchy` argparse parser.", ""]
    for path, sub in _commands(parser, ["drivehierarchy"]):
        heading = "#" * min(len(path) + 1, 4)
        parts += [f"{heading} `{' '.join(path)}`", "", "```text", sub.format_help().rstrip(), "```", ""]
    return "\n".join(parts)


for name, build in (("env", env_page), ("scenario-schema", schema_page), ("cli", cli_page)):
    with mkdocs_gen_files.open(f"reference/{name}.md", "w") as fh:
        fh.write(build())
