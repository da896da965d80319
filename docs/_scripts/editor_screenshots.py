"""Screenshots of the scenario editor for docs/editor.md (run by hand after UI changes):

    python docs/_scripts/editor_screenshots.py [--out docs/editor]

Starts `drivehierarchy editor scenarios/r4` on a free port and drives Debian's chromium
through Playwright (no browser download).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SCENARIO = "01_pedestrian/town01_01_midblock_crossing.toml"
TRAFFIC = "04_intersection/town01_09_behind_left_turner.toml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "editor")
    ap.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    args.out.mkdir(parents=True, exist_ok=True)
    proc = subprocess.Popen(
        [sys.executable, "-m", "drivehierarchy.cli", "editor", str(REPO / "scenarios" / "r4"), "--port", "0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        url = re.search(r"http://127\.0\.0\.1:\d+/", proc.stdout.readline()).group(0)  # type: ignore[union-attr]
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=args.chromium, args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1700, "height": 1000})
            idle = "document.body.dataset.ready === '1' && document.body.dataset.busy === '0'"
            # Opens zoomed to the scenario's route.
            page.goto(url + "#" + SCENARIO)
            page.wait_for_function(idle)
            page.wait_for_function("window.editor.episodeReady()")
            set_time = "(el) => { el.value = '14'; el.dispatchEvent(new Event('input')); }"
            page.eval_on_selector("#time", set_time)
            page.wait_for_function("Number(document.getElementById('front').dataset.time) > 13.7")
            page.wait_for_function(idle)
            page.click("#btn-run")
            page.wait_for_function(idle)
            page.screenshot(path=str(args.out / "editor_overview.png"))
            # The blind follower's own episode: the slider ends at its crash.
            page.select_option("#driver", "follower@8")
            page.wait_for_function("window.editor.episodeReady()")
            end = "(el) => { el.value = el.max; el.dispatchEvent(new Event('input')); }"
            page.eval_on_selector("#time", end)
            page.wait_for_function(
                "Number(document.getElementById('front').dataset.time) "
                "=== Number(document.getElementById('time').max)"
            )
            page.wait_for_function(idle)
            page.locator("#preview").screenshot(path=str(args.out / "editor_driver_end.png"))
            page.select_option("#driver", "expert")
            page.wait_for_function(idle)
            # Two errors at once, each at its field.
            for path, value in (("actors.0.speed_mps", "-1"), ("actors.0.accel_mps2", "-2")):
                page.fill(f"[data-path='{path}']", value)
                page.press(f"[data-path='{path}']", "Tab")
                page.wait_for_function(idle)
            page.locator("fieldset[data-actor='0']").screenshot(path=str(args.out / "editor_validation.png"))
            # A refused Save as: the reason at the field and in the status line.
            page.fill("#saveas-path", "../elsewhere.toml")
            page.click("#btn-saveas")
            page.wait_for_function(idle)
            page.locator("header").screenshot(path=str(args.out / "editor_refused_save.png"))
            # Lights over time and background traffic: a scenario with flows through light C.
            page.once("dialog", lambda d: d.accept())  # the unsaved edits above are discarded
            page.select_option("#file-list", TRAFFIC)
            page.wait_for_function(idle)
            page.eval_on_selector("#time", set_time)
            page.wait_for_function("Number(document.getElementById('front').dataset.time) > 13.7")
            page.wait_for_function(idle)
            page.locator("#lights").screenshot(path=str(args.out / "editor_lights_traffic.png"))
            browser.close()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    for p in sorted(args.out.glob("*.png")):
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
