"""The rendering gallery: the start frame of every built-in scenario, as committed PNGs.

`drivehierarchy r4 gallery [--out docs/gallery]` rewrites, for each scenario,

    <category>__<name>_front.png    front camera 800×450 (the protocol's, 2× supersampled)
    <category>__<name>_bev.png      BEV 800×800 (the protocol's)

plus, for one scenario, `<key>_chase.png` (the video camera) and `<key>_surround.png` (the
six-camera rig on one contact sheet), and `README.md`, a Markdown table embedding them all.
Frames are taken right after `reset(seed)`, before any action, so the files only change when the
renderer, a map or a scenario changes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from drivehierarchy.envs.config import BevConfig, CameraConfig
from drivehierarchy.scenarios import builtin_scenarios

# Scenario whose chase view and surround sheet are added (a signalised crossing with traffic).
FEATURED = "03_turning__town01_03_right_turn_signalised"
# nuScenes layout: front row left→right, back row as seen when turned round.
SURROUND_LAYOUT = (
    ("CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"),
    ("CAM_BACK_LEFT", "CAM_BACK", "CAM_BACK_RIGHT"),
)
SURROUND_TILE = (400, 225)


@dataclasses.dataclass(frozen=True)
class GalleryEntry:
    key: str
    name: str
    description: str
    files: dict[str, str]  # view ("front", "bev", "chase", "surround") → file name


def scenario_key(path: Path) -> str:
    return f"{path.parent.name}__{path.stem}"


def _save_png(frame: np.ndarray, path: Path) -> None:
    from PIL import Image

    Image.fromarray(frame).save(path, optimize=True)


def surround_sheet(frames: dict[str, np.ndarray]) -> np.ndarray:
    """The six surround images, downscaled, on a 3×2 sheet with each camera's name."""
    from PIL import Image, ImageDraw

    tw, th = SURROUND_TILE
    sheet = Image.new("RGB", (3 * tw, 2 * th))
    draw = ImageDraw.Draw(sheet)
    for r, row in enumerate(SURROUND_LAYOUT):
        for c, name in enumerate(row):
            tile = Image.fromarray(frames[name]).resize((tw, th), Image.Resampling.LANCZOS)
            sheet.paste(tile, (c * tw, r * th))
            x, y = c * tw + 6, r * th + 4
            draw.rectangle((x - 3, y - 2, x + 7 * len(name) + 3, y + 12), fill=(0, 0, 0))
            draw.text((x, y), name, fill=(255, 255, 255))
    return np.asarray(sheet)


def render_start(scenario: Path, out: Path, *, seed: int = 0, extras: bool = False) -> GalleryEntry:
    """Renders one scenario's start frame into `out`; returns what was written."""
    from drivehierarchy import _core
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    key = scenario_key(scenario)
    # No observation images: the views are rendered explicitly below, at gallery quality.
    env = DriveHierarchyR4Env(scenario=scenario, front=None, bev=None, prompt=False)
    try:
        env.reset(seed=seed)
        sim = env.sim
        files: dict[str, str] = {}
        front = CameraConfig(supersample=2)
        _save_png(sim.render_camera(front), out / f"{key}_front.png")
        files["front"] = f"{key}_front.png"
        _save_png(sim.render_bev(BevConfig()), out / f"{key}_bev.png")
        files["bev"] = f"{key}_bev.png"
        if extras:
            _save_png(sim.render("chase"), out / f"{key}_chase.png")
            files["chase"] = f"{key}_chase.png"
            _save_png(surround_sheet(sim.render_surround()), out / f"{key}_surround.png")
            files["surround"] = f"{key}_surround.png"
        summary = _core.validate_scenario(str(scenario), _sumo_home())
    finally:
        env.close()
    return GalleryEntry(key, summary.get("name", key), _description(scenario), files)


def _sumo_home() -> str | None:
    from drivehierarchy.scenarios import sumo_home

    return sumo_home()


def _description(path: Path) -> str:
    import tomllib

    try:
        return str(tomllib.loads(path.read_text(encoding="utf-8")).get("description", ""))
    except (OSError, tomllib.TOMLDecodeError):
        return ""


def readme(entries: list[GalleryEntry]) -> str:
    lines = [
        "# Rendering gallery",
        "",
        "Start frame (after `reset(seed=0)`) of every built-in R4 scenario: the front camera",
        "(800×450, FOV 100°, docs/protocol.md#r4-loop; 2× supersampled here) and the bird's-eye",
        "view (800×800, 8 px/m, ego centred, forward up, local route in red). Regenerate with",
        "`drivehierarchy r4 gallery` (see `docs/rendering.md`); do not edit by hand.",
        "",
        "| scenario | front camera | BEV |",
        "|---|---|---|",
    ]
    for e in entries:
        label = f"**{e.key}**<br>{e.name}" + (f"<br><sub>{e.description}</sub>" if e.description else "")
        front, bev = e.files["front"], e.files["bev"]
        lines.append(f'| {label} | <img src="{front}" width="400"> | <img src="{bev}" width="240"> |')
    for e in entries:
        if "chase" in e.files or "surround" in e.files:
            lines += ["", f"## {e.key}: chase camera and surround rig", ""]
            if "chase" in e.files:
                lines += ["Chase camera (videos):", "", f'<img src="{e.files["chase"]}" width="600">', ""]
            if "surround" in e.files:
                lines += [
                    "Six-camera surround rig (nuScenes-like mounts; front row FRONT_LEFT, FRONT,",
                    "FRONT_RIGHT; back row BACK_LEFT, BACK, BACK_RIGHT), each 800×450 shown at 400×225:",
                    "",
                    f'<img src="{e.files["surround"]}" width="900">',
                ]
    return "\n".join(lines) + "\n"


def write_gallery(
    out: Path,
    scenarios: Iterable[Path] | None = None,
    *,
    seed: int = 0,
    featured: str = FEATURED,
    log: Callable[[str], Any] = print,
) -> list[GalleryEntry]:
    """Regenerates the gallery in `out` (stale PNGs of this gallery's naming are removed)."""
    scenarios = list(scenarios if scenarios is not None else builtin_scenarios())
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*__*.png"):
        old.unlink()
    entries = []
    for path in scenarios:
        entry = render_start(path, out, seed=seed, extras=scenario_key(path) == featured)
        log(f"{entry.key}: {', '.join(entry.files.values())}")
        entries.append(entry)
    (out / "README.md").write_text(readme(entries), encoding="utf-8")
    return entries
