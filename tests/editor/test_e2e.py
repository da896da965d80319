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
# Background traffic (two `[[traffic.flows]]`) through town01's light C.
FLOWS = "04_intersection/town01_09_behind_left_turner.toml"


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
    (root / "r4" / "04_intersection").mkdir()
    shutil.copy(SUITE / FLOWS, root / "r4" / FLOWS)
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


def set_field(page, path: str, value: str) -> None:
    """Types into the input bound to key path `path` and commits it (the form's change event)."""
    sel = f"[data-path='{path}']"
    page.fill(sel, value)
    page.press(sel, "Tab")
    idle(page)


def validate_cli(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "drivehierarchy.cli", "scenario", "validate", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )


def changed_lines(before: str, after: str) -> list[tuple[str, str]]:
    return [(a, b) for a, b in zip(before.splitlines(), after.splitlines(), strict=True) if a != b]


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
    # The trigger's `of` is a place form (lane + s), prefilled 40 m ahead of the ego's start.
    assert page.input_value("[data-path='actors.0.start.of']") == "lane"
    set_field(page, "actors.0.start.of.lane", "C2T_1")
    set_field(page, "actors.0.start.of.s", "140")
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


def test_edit_a_flow_row_and_save(page, server: str, workspace: Path) -> None:
    path = workspace / "r4" / FLOWS
    before = path.read_text(encoding="utf-8")
    page.goto(server + "#" + FLOWS)
    idle(page)
    # The second flow's row: its rate and its destination edge, picked on the map.
    assert page.input_value("[data-path='traffic.flows.1.vehs_per_hour']") == "300"
    set_field(page, "traffic.flows.1.vehs_per_hour", "450")
    page.click("[data-field='traffic.flows.1.to'] button.pick")
    click_lane(page, "C2T_1", 40.0)
    assert page.input_value("[data-path='traffic.flows.1.to']") == "C2T"
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    page.click("#btn-save")
    idle(page)
    after = path.read_text(encoding="utf-8")
    try:
        assert changed_lines(before, after) == [
            ('to = "C2N"', 'to = "C2T"'),
            ("vehs_per_hour = 300", "vehs_per_hour = 450"),
        ]
        r = validate_cli(path)
        assert r.returncode == 0, r.stdout + r.stderr
    finally:
        path.write_text(before, encoding="utf-8")


def test_add_a_flow_row_then_remove_it(page, server: str, workspace: Path) -> None:
    page.goto(server + "#" + FLOWS)
    idle(page)
    text = page.evaluate("window.editor.S.text")
    page.click("[data-rows='traffic.flows'] .rows-head button.add")
    idle(page)
    assert page.locator("[data-rows='traffic.flows'] .rowcard").count() == 3
    page.click("[data-field='traffic.flows.2.from'] button.pick")
    click_lane(page, "T2C_1", 100.0)
    page.click("[data-field='traffic.flows.2.to'] button.pick")
    click_lane(page, "C2W_1", 60.0)
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    added = page.evaluate("window.editor.S.text")
    assert added.startswith(text)
    assert (
        added[len(text) :]
        == '\n[[traffic.flows]]\nid = "flow2"\nfrom = "T2C"\nto = "C2W"\nvehs_per_hour = 300\n'
    )
    page.click("[data-row='traffic.flows.2'] button.del")
    idle(page)
    assert page.evaluate("window.editor.S.text") == text


def test_invalid_row_value_shows_the_validators_message_at_that_rows_field(page, server: str) -> None:
    page.goto(server + "#" + FLOWS)
    idle(page)
    set_field(page, "traffic.flows.0.vehs_per_hour", "-5")
    err = page.locator(".field.invalid[data-field='traffic.flows.0.vehs_per_hour'] .field-error")
    assert err.count() == 1
    assert re.search(
        r"town01_09_behind_left_turner\.toml:52:\d+: "
        r"field `traffic\.flows\[0\]\.vehs_per_hour` = -5: must be",
        err.inner_text(),
    ), err.inner_text()
    # Only that row's field is marked; Save refuses the buffer.
    assert page.locator(".invalid").count() == 1
    page.click("#btn-save")
    idle(page)
    assert "not saved" in page.inner_text("#status")


def _override_phases(page) -> None:
    """Overrides town01's light C and copies the map's phases into the override's table."""
    page.click("[data-light='C'] button:has-text('Override C')")
    idle(page)
    page.click("[data-light='C'] button:has-text('Edit phases')")
    idle(page)


def test_edit_a_phase_row_and_save(page, server: str, workspace: Path) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    _override_phases(page)
    assert page.locator("[data-rows='lights.0.phases'] .rowcard").count() >= 2
    set_field(page, "lights.0.phases.1.duration_s", "5")
    state0 = page.input_value("[data-path='lights.0.phases.0.state']")
    # An invalid state (a character short) is shown at that row's `state`.
    set_field(page, "lights.0.phases.0.state", state0[:-1])
    err = page.locator(".field.invalid[data-field='lights.0.phases.0.state'] .field-error")
    assert err.count() == 1
    assert re.search(
        r"town01_01_midblock_crossing\.toml:\d+:\d+: "
        rf'field `lights\[0\]\.phases\[0\]\.state` = "{state0[:-1]}": '
        rf"has {len(state0) - 1} characters",
        err.inner_text(),
    ), err.inner_text()
    set_field(page, "lights.0.phases.0.state", state0)
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    page.fill("#saveas-path", "01_pedestrian/phases.toml")
    page.click("#btn-saveas")
    idle(page)
    assert "saved" in page.inner_text("#status")
    saved = workspace / "r4" / "01_pedestrian" / "phases.toml"
    import tomllib

    doc = tomllib.loads(saved.read_text(encoding="utf-8"))
    assert doc["lights"][0]["tls"] == "C"
    assert doc["lights"][0]["phases"][1]["duration_s"] == 5
    assert doc["lights"][0]["phases"][0]["state"] == state0
    r = validate_cli(saved)
    assert r.returncode == 0, r.stdout + r.stderr
    saved.unlink()


def test_phase_timeline_now_marker_follows_the_slider(page, server: str) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    _override_phases(page)
    # A two-phase program: all red for 5 s, then all green for 5 s.
    n = len(page.input_value("[data-path='lights.0.phases.0.state']"))
    while page.locator("[data-rows='lights.0.phases'] .rowcard").count() > 2:
        page.click("[data-row='lights.0.phases.2'] button.del")
        idle(page)
    set_field(page, "lights.0.phases.0.state", "r" * n)
    set_field(page, "lights.0.phases.0.duration_s", "5")
    set_field(page, "lights.0.phases.1.state", "G" * n)
    set_field(page, "lights.0.phases.1.duration_s", "5")
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    tmax = float(page.get_attribute("#time", "max"))
    marker = ".timeline-strip[data-tls='C'] .now"
    text = ".now-text[data-tls='C']"

    def slide(t: float) -> None:
        page.eval_on_selector(
            "#time", f"(el) => {{ el.value = '{t}'; el.dispatchEvent(new Event('input')); }}"
        )
        # The scene is the world at the last decision at or before t.
        page.wait_for_function(f"Math.abs((window.editor.S.scene || {{time_s: -1}}).time_s - {t}) < 0.3")
        idle(page)

    lefts = []
    for t, phase, color in [(2.0, 0, "red"), (7.0, 1, "green"), (12.0, 0, "red")]:
        slide(t)
        left = page.eval_on_selector(marker, "(el) => el.style.left")
        assert float(left.rstrip("%")) == pytest.approx(100 * t / tmax, abs=1e-3)
        lefts.append(page.eval_on_selector(marker, "(el) => el.getBoundingClientRect().left"))
        # The schedule's phase at t, and the world's own colours of C's heads at t, agree.
        shown = page.inner_text(text)
        assert f"phase {phase} " in shown, shown
        world = re.findall(r"\S+ (red|green|yellow|off)", shown.split("world:")[1])
        assert world and set(world) == {color}, shown
    assert lefts[0] < lefts[1] < lefts[2]


def test_suite_files_open_in_forms_with_no_json_fallback(page, server: str, workspace: Path) -> None:
    """Every key of these suite files has a form (JSON fields are for keys the forms do not know);
    the page fixture fails the test on any script error."""
    files = sorted(
        p.relative_to(workspace / "r4").as_posix() for p in (workspace / "r4").rglob("town01_*.toml")
    )
    assert len(files) >= 5
    for f in files:
        page.goto(server + "#" + f)
        page.reload()
        idle(page)
        assert page.evaluate("window.editor.S.error") is None, f
        labels = page.eval_on_selector_all("label", "els => els.map((e) => e.textContent)")
        assert not [x for x in labels if "(JSON)" in x], (f, labels)
        assert page.locator("[data-path='ego.start.lane']").count() == 1, f


def test_pace_and_lane_change_rows_are_added_edited_and_removed(page, server: str) -> None:
    page.goto(server + "#" + FLOWS)
    idle(page)
    text = page.evaluate("window.editor.S.text")
    van = "fieldset[data-actor='0']"
    page.click(f"{van} button:has-text('+ gap pace')")
    idle(page)
    set_field(page, "actors.0.pace.gap_m", "3")
    page.click(f"{van} button:has-text('+ lane change')")
    idle(page)
    set_field(page, "actors.0.lane_changes.0.at_s", "30")
    # The van runs on T2C_2; the lane beside it is picked on the map.
    page.click("[data-field='actors.0.lane_changes.0.to_lane'] button.pick")
    click_lane(page, "T2C_1", 120.0)
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    now = page.evaluate("window.editor.S.text")
    assert "pace = { gap_s = 1.5, gap_m = 3.0, min_speed_mps = 1.0 }" in now
    assert 'lane_changes = [{ at_s = 30.0, to_lane = "T2C_1", length_m = 20.0 }]' in now
    page.click("[data-row='actors.0.lane_changes.0'] button.del")
    idle(page)
    page.click(f"{van} .pace button.del")
    idle(page)
    assert page.evaluate("window.editor.S.text") == text
