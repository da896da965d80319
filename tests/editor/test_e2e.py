"""End-to-end tests of the scenario editor in headless Chromium (Debian's `chromium`, driven by
Playwright with `executable_path`: no browser download). The server is the real command,
`drivehierarchy editor --port 0`, on a copy of two suite categories."""

from __future__ import annotations

import base64
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SUITE = REPO / "scenarios" / "r4"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
PED = "01_pedestrian/town01_01_midblock_crossing.toml"


def _need_browser() -> None:
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        if os.environ.get("CI") == "true":
            pytest.fail("playwright is not installed (pip install playwright) but CI=true")
        pytest.skip("editor e2e: playwright not installed")
    if not Path(CHROMIUM).is_file():
        if os.environ.get("CI") == "true":
            pytest.fail(f"chromium not found at {CHROMIUM} but CI=true (apt-get install chromium)")
        pytest.skip("editor e2e: no chromium (apt-get install chromium)")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("e2e") / "scenarios"
    shutil.copytree(SUITE / "01_pedestrian", root / "r4" / "01_pedestrian")
    (root / "maps").mkdir()
    (root / "maps" / "town01").symlink_to(REPO / "scenarios" / "maps" / "town01")
    return root


@pytest.fixture(scope="module")
def server(workspace: Path) -> Iterator[str]:
    _need_browser()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "drivehierarchy.cli",
            "editor",
            str(workspace / "r4"),
            "--map",
            "builtin:town01",
            "--port",
            "0",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        m = re.search(r"(http://127\.0\.0\.1:\d+/)", line)
        assert m, line
        yield m.group(1)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def browser(server: str):
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        yield b
        b.close()


@pytest.fixture
def page(browser, server: str):
    ctx = browser.new_context(viewport={"width": 1700, "height": 1000})
    p = ctx.new_page()
    errors: list[str] = []
    p.on("pageerror", lambda e: errors.append(str(e)))
    yield p
    ctx.close()
    assert not errors, errors


def idle(page) -> None:
    page.wait_for_function("document.body.dataset.ready === '1' && document.body.dataset.busy === '0'")


# Screen position of lane `lane` at arc length `s` (test-side interpolation of the map's shapes).
LANE_POINT_JS = """([lane, s]) => {
  const L = window.editor.S.map.lanes.find((l) => l.id === lane);
  let acc = 0;
  for (let i = 1; i < L.shape.length; i++) {
    const [x0, y0] = L.shape[i - 1], [x1, y1] = L.shape[i];
    const d = Math.hypot(x1 - x0, y1 - y0);
    if (acc + d >= s || i === L.shape.length - 1) {
      const f = Math.min(1, (s - acc) / d);
      const [px, py] = window.editor.toScreen(x0 + f * (x1 - x0), y0 + f * (y1 - y0));
      const r = document.getElementById('map').getBoundingClientRect();
      return [px + r.left, py + r.top];
    }
    acc += d;
  }
}"""


def click_lane(page, lane: str, s: float) -> None:
    x, y = page.evaluate(LANE_POINT_JS, [lane, s])
    page.mouse.click(x, y)
    idle(page)


def test_build_a_pedestrian_crossing_from_an_empty_map(page, server: str, workspace: Path) -> None:
    page.goto(server)
    idle(page)
    page.fill("#new-id", "my_crossing")
    page.select_option("#new-category", "01_pedestrian")
    page.check("#new-blank")
    page.click("#btn-new")
    idle(page)
    # Zoom on the straight so a click is well within a lane.
    page.click("#tools button[data-mode=ego-start]")
    click_lane(page, "C2T_1", 30.0)
    page.click("#tools button[data-mode=ego-dest]")
    click_lane(page, "C2T_1", 200.0)
    assert "route" in page.inner_text("#route-info")
    page.select_option("#actor-kind", "pedestrian")
    page.click("#tools button[data-mode=actor]")
    click_lane(page, "C2T_0", 140.0)
    click_lane(
        page,
        "T2C_0",
        page.evaluate("window.editor.S.map.lanes.find((l) => l.id === 'T2C_0').length_m") - 140.0,
    )
    page.keyboard.press("Enter")
    idle(page)
    page.select_option("[data-path='actors.0.start.kind']", "ego_eta_s")
    idle(page)
    page.fill("[data-path='actors.0.start.ego_eta_s']", "2.9")
    page.press("[data-path='actors.0.start.ego_eta_s']", "Tab")
    idle(page)
    page.fill("[data-path='actors.0.start.of']", '{"lane": "C2T_1", "s": 140.0}')
    page.press("[data-path='actors.0.start.of']", "Tab")
    idle(page)
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    page.fill("#saveas-path", "01_pedestrian/my_crossing.toml")
    page.click("#btn-saveas")
    idle(page)
    assert "saved" in page.inner_text("#status")
    saved = workspace / "r4" / "01_pedestrian" / "my_crossing.toml"
    text = saved.read_text(encoding="utf-8")
    assert 'kind = "pedestrian"' in text and "ego_eta_s = 2.9" in text
    r = subprocess.run(
        [sys.executable, "-m", "drivehierarchy.cli", "scenario", "validate", str(saved)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "actors" in r.stdout
    page.select_option("#driver", "expert")
    page.click("#btn-run")
    idle(page)
    assert "destination_reached" in page.inner_text("#run-score")


def test_drag_a_trigger_point_and_save_a_minimal_diff(page, server: str, workspace: Path) -> None:
    path = workspace / "r4" / PED
    before = path.read_text(encoding="utf-8")
    page.goto(server + "#" + PED)
    idle(page)
    h = page.evaluate("window.editor.triggerHandles()[0]")
    assert h["actor"] == 0 and h["kind"] == "ego_eta"
    x0, y0 = page.evaluate(LANE_POINT_JS, ["C2T_1", 140.0])
    x1, y1 = page.evaluate(LANE_POINT_JS, ["C2T_1", 165.0])
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move((x0 + x1) / 2, y0, steps=4)
    page.mouse.move(x1, y1, steps=4)
    page.mouse.up()
    idle(page)
    page.click("#btn-save")
    idle(page)
    after = path.read_text(encoding="utf-8")
    changed = [(a, b) for a, b in zip(before.splitlines(), after.splitlines(), strict=True) if a != b]
    assert len(changed) == 1, changed
    m = re.fullmatch(
        r'start = \{ ego_eta_s = 2\.9, of = \{ lane = "C2T_1", s = ([\d.]+) \} \}', changed[0][1]
    )
    assert m, changed
    assert float(m.group(1)) == pytest.approx(165.0, abs=2.0)
    path.write_text(before, encoding="utf-8")


def test_invalid_edit_shows_the_validators_message_at_the_field(page, server: str) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    page.fill("[data-path='actors.0.speed_mps']", "-1")
    page.press("[data-path='actors.0.speed_mps']", "Tab")
    idle(page)
    err = page.locator(".field.invalid[data-field='actors.0.speed_mps'] .field-error")
    assert err.count() == 1
    assert re.search(
        r"town01_01_midblock_crossing\.toml:19:\d+: field `actors\[0\]\.speed_mps` = -1: must be",
        err.inner_text(),
    )


def test_preview_front_equals_scenario_preview_byte_for_byte(
    page, server: str, workspace: Path, tmp_path: Path
) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    page.eval_on_selector("#time", "(el) => { el.value = '12'; el.dispatchEvent(new Event('input')); }")
    # The scene at the last decision at or before t = 12 s (decisions are 0.25 s apart).
    page.wait_for_function("Number(document.getElementById('front').dataset.time) > 11.7")
    idle(page)
    data = page.evaluate(
        """async () => {
        const r = await fetch(document.getElementById('front').src);
        const b = new Uint8Array(await r.arrayBuffer());
        let s = ''; for (const c of b) s += String.fromCharCode(c);
        return btoa(s);
      }"""
    )
    shown = base64.b64decode(data)
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "drivehierarchy.cli",
            "scenario",
            "preview",
            str(workspace / "r4" / PED),
            "--time",
            "12",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    front = Path(r.stdout.splitlines()[0])
    assert shown[:8] == b"\x89PNG\r\n\x1a\n"
    assert shown == front.read_bytes()
