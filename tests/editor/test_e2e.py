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


def _start_editor(args: list[str]) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "drivehierarchy.cli", "editor", *args, "--port", "0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    line = proc.stdout.readline()
    m = re.search(r"(http://127\.0\.0\.1:\d+/)", line)
    assert m, line
    return proc, m.group(1)


@pytest.fixture(scope="module")
def category_server(workspace: Path) -> Iterator[str]:
    """A second editor rooted at a category folder (a copy of one), started without --map."""
    _need_browser()
    root = workspace.parent / "category_root" / "01_pedestrian"
    shutil.copytree(SUITE / "01_pedestrian", root)
    proc, url = _start_editor([str(root)])
    try:
        yield url
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


# Console errors a test provokes on purpose: the browser logs every refused request
# ("Failed to load resource: ... status of 403") as one. Keyed by page; (status, url suffix).
EXPECTED_REFUSALS: dict[int, list[tuple[int, str]]] = {}


def expect_refusal(page, status: int, url_suffix: str) -> None:
    EXPECTED_REFUSALS.setdefault(id(page), []).append((status, url_suffix))


@pytest.fixture
def page(browser, server: str):
    """A page that fails its test on any page error (an unhandled promise included) and any
    console error, except the refusals the test said it provokes."""
    ctx = browser.new_context(viewport={"width": 1700, "height": 1000})
    p = ctx.new_page()
    errors: list[str] = []
    console: list[tuple[str, str]] = []
    p.on("pageerror", lambda e: errors.append(str(e)))
    p.on(
        "console",
        lambda m: console.append((m.text, m.location.get("url", ""))) if m.type == "error" else None,
    )
    yield p
    ctx.close()
    expected = EXPECTED_REFUSALS.pop(id(p), [])
    unexpected = [
        (text, url)
        for text, url in console
        if not any(f"status of {st} " in text and url.split("?")[0].endswith(sfx) for st, sfx in expected)
    ]
    assert not errors, errors
    assert not unexpected, unexpected


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
    box = page.locator("#map").bounding_box()
    if not (
        box["x"] + 5 < x < box["x"] + box["width"] - 5 and box["y"] + 5 < y < box["y"] + box["height"] - 5
    ):
        # Outside the view zoomed to the route: the whole map first.
        page.click("#btn-fit-map")
        x, y = page.evaluate(LANE_POINT_JS, [lane, s])
    page.mouse.click(x, y)
    idle(page)


def test_build_a_pedestrian_crossing_from_an_empty_map(page, server: str, workspace: Path) -> None:
    page.goto(server)
    idle(page)
    page.fill("#new-id", "my_crossing")
    page.select_option("#new-category", "01_pedestrian")
    page.select_option("#new-map", "builtin:town01")
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
    page.wait_for_function("window.editor.episodeReady()")
    page.eval_on_selector("#time", "(el) => { el.value = '12'; el.dispatchEvent(new Event('input')); }")
    # The scene at the last decision at or before t = 12 s (decisions are 0.25 s apart).
    page.wait_for_function("Number(document.getElementById('front').dataset.time) > 11.7")
    idle(page)
    t = 12.0
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
            str(t),
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
    expect_refusal(page, 422, "/api/save")
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
    marker = ".timeline-strip[data-tls='C'] .now"
    text = ".now-text[data-tls='C']"

    def slide(t: float) -> float:
        page.eval_on_selector(
            "#time", f"(el) => {{ el.value = '{t}'; el.dispatchEvent(new Event('input')); }}"
        )
        # The scene is the world at the last decision at or before t.
        page.wait_for_function(f"Math.abs((window.editor.S.scene || {{time_s: -1}}).time_s - {t}) < 0.3")
        idle(page)
        return float(page.input_value("#time"))

    page.wait_for_function("window.editor.episodeReady()")
    tmax = float(page.get_attribute("#time", "max"))
    lefts = []
    for want, phase, color in [(2.0, 0, "red"), (7.0, 1, "green"), (12.0, 0, "red")]:
        t = slide(want)
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


def slide_to(page, t: float) -> float:
    """Moves the time slider to t; the time of the decision shown (the last at or before t)."""
    page.eval_on_selector("#time", f"(el) => {{ el.value = '{t}'; el.dispatchEvent(new Event('input')); }}")
    page.wait_for_function(
        f"""(() => {{ const f = Number(document.getElementById('front').dataset.time);
        return f <= {t} + 1e-6 && f > {t} - 0.26 && window.editor.S.scene
          && Math.abs(window.editor.S.scene.time_s - f) < 0.006; }})()"""
    )
    idle(page)
    return page.evaluate("window.editor.S.scene.time_s")


# Issue 31, item 1: a refused Save / Save as shows the server's reason in the status line and at
# the path field; no unhandled promise (the page fixture fails on any page or console error).
def test_refused_save_as_shows_the_reason(page, server: str) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    for path, status, reason in [
        ("../outside.toml", 403, "`..` is refused"),
        ("/tmp/abs.toml", 403, "absolute paths are refused"),
        (PED, 400, "exists already"),
    ]:
        expect_refusal(page, status, "/api/save")
        page.fill("#saveas-path", path)
        page.click("#btn-saveas")
        idle(page)
        assert reason in page.inner_text("#status"), page.inner_text("#status")
        assert page.inner_text("#status").startswith("not saved")
        assert reason in page.inner_text("#save-error")
        assert page.locator("#saveas-path.invalid-input").count() == 1


# Item 2: unsaved edits are confirmed away (another file, New) and guarded on reload / close.
def test_unsaved_edits_ask_before_they_are_lost(page, server: str) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    set_field(page, "actors.0.speed_mps", "1.3")
    assert page.inner_text("#path").endswith("*")
    asked: list[str] = []

    def answer(accept: bool):
        def handler(d) -> None:
            asked.append(d.type + ": " + d.message)
            d.accept() if accept else d.dismiss()

        return handler

    other = "01_pedestrian/town01_03_child_between_parked_cars.toml"
    page.once("dialog", answer(False))
    page.select_option("#file-list", other)
    idle(page)
    assert asked and asked[0].startswith("confirm: ") and "unsaved changes" in asked[0]
    assert page.evaluate("window.editor.S.path") == PED and page.input_value("#file-list") == PED
    assert "speed_mps = 1.3" in page.evaluate("window.editor.S.text")
    page.once("dialog", answer(False))
    page.click("#btn-new")
    idle(page)
    assert len(asked) == 2 and page.evaluate("window.editor.S.path") == PED
    # Closing (or reloading) the page asks too: the browser's own beforeunload dialog.
    with page.expect_event("dialog") as dialog:
        page.close(run_before_unload=True)
    assert dialog.value.type == "beforeunload"
    dialog.value.accept()


def test_an_unchanged_file_opens_another_without_asking(page, server: str) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    asked: list[str] = []
    page.on("dialog", lambda d: (asked.append(d.type), d.dismiss()))
    other = "01_pedestrian/town01_03_child_between_parked_cars.toml"
    page.select_option("#file-list", other)
    idle(page)
    assert page.evaluate("window.editor.S.path") == other and not asked


# Item 3: a category folder copied anywhere opens and runs with no edit (its files name their
# maps `builtin:NAME`; here the copy sits a folder deeper than the suite, so no `../../maps`).
def test_a_copied_category_folder_opens_and_runs(page, server: str, workspace: Path) -> None:
    dest = workspace / "r4" / "copies" / "mine"
    shutil.copytree(SUITE / "01_pedestrian", dest)
    try:
        page.goto(server)
        idle(page)
        rel = "copies/mine/" + PED.split("/")[1]
        page.select_option("#file-list", rel)
        idle(page)
        assert page.evaluate("window.editor.S.error") is None
        assert page.evaluate("window.editor.S.map.lanes.length") > 100
        page.wait_for_function("window.editor.episodeReady()")
        page.wait_for_function("document.getElementById('front').naturalWidth === 800")
        page.select_option("#driver", "expert")
        page.click("#btn-run")
        idle(page)
        assert "destination_reached" in page.inner_text("#run-score")
    finally:
        shutil.rmtree(workspace / "r4" / "copies")


# Items 4 and 12: New offers the built-in maps (no `map = ""`), and a template's description
# and (when asked) actors are not copied.
def test_new_from_a_map_or_a_template(page, server: str) -> None:
    page.goto(server)
    idle(page)
    maps = page.eval_on_selector_all("#new-map option", "els => els.map((e) => e.value)")
    assert {"builtin:town01", "builtin:town02"} <= set(maps)
    page.fill("#new-id", "on_town02")
    page.select_option("#new-category", "01_pedestrian")
    page.select_option("#new-map", "builtin:town02")
    page.click("#btn-new")
    idle(page)
    assert 'map = "builtin:town02"' in page.evaluate("window.editor.S.text")
    assert page.input_value("#saveas-path") == "01_pedestrian/on_town02.toml"
    page.select_option("#new-map", "")
    page.once("dialog", lambda d: d.accept())  # the unsaved new scenario
    page.uncheck("#new-actors")
    page.fill("#new-id", "no_actors")
    page.click("#btn-new")
    idle(page)
    doc = page.evaluate("window.editor.S.doc")
    assert doc["description"] == "" and "actors" not in doc and doc["id"] == "no_actors"
    assert page.input_value("[data-path='description']") == ""
    page.once("dialog", lambda d: d.accept())
    page.check("#new-actors")
    page.click("#btn-new")
    idle(page)
    doc = page.evaluate("window.editor.S.doc")
    assert doc["description"] == "" and len(doc["actors"]) >= 1


# Item 6: the status follows the buffer: after a save, an invalid "Apply text" says invalid.
def test_status_follows_the_buffer(page, server: str, workspace: Path) -> None:
    path = workspace / "r4" / PED
    before = path.read_text(encoding="utf-8")
    page.goto(server + "#" + PED)
    idle(page)
    page.click("#btn-save")
    idle(page)
    assert page.inner_text("#status").startswith("saved")
    page.click("#toml-box summary")
    page.fill("#toml", before.replace("speed_mps = 1.1", "speed_mps = -1.1", 1))
    page.click("#btn-apply-text")
    idle(page)
    assert page.inner_text("#status") == "text applied: invalid, 1 error (see the fields)"
    assert page.locator(".field.invalid[data-field='actors.0.speed_mps']").count() == 1
    assert path.read_text(encoding="utf-8") == before


# Item 7: every error of the buffer at its field.
def test_every_error_is_shown_at_its_field(page, server: str) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    text = page.evaluate("window.editor.S.text")
    bad = text.replace("speed_mps = 1.1", "speed_mps = -1.1", 1).replace(
        "speed_mps = 1.2", "speed_mps = -1.2", 1
    )
    bad = re.sub(r"reference_duration_s = [\d.]+", "reference_duration_s = -3.0", bad, count=1)
    page.click("#toml-box summary")
    page.fill("#toml", bad)
    page.click("#btn-apply-text")
    idle(page)
    for f in ("actors.0.speed_mps", "actors.1.speed_mps", "reference_duration_s"):
        err = page.locator(f".field.invalid[data-field='{f}'] .field-error")
        assert err.count() == 1, f
    assert page.locator("#error-box .error-line").count() == 3
    assert "3 errors" in page.inner_text("#status")


# Item 8: an off-road path is a warning, at its field, and the file still saves.
def test_an_off_road_path_warns_without_refusing(page, server: str, workspace: Path) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    text = page.evaluate("window.editor.S.text")
    off = text.replace('{ lane = "T2C_0", s = 242.4 }', "{ x = 60.0, y = 60.0 }", 1)
    assert off != text
    page.click("#toml-box summary")
    page.fill("#toml", off)
    page.click("#btn-apply-text")
    idle(page)
    assert page.is_hidden("#error-box")
    assert "1 warning" in page.inner_text("#status")
    w = page.locator("[data-rows='actors.0.waypoints'] .field-warning, .field.warned .field-warning")
    assert w.count() >= 1 and "open to pedestrian" in w.first.inner_text()
    page.fill("#saveas-path", "01_pedestrian/off_road.toml")
    page.click("#btn-saveas")
    idle(page)
    assert page.inner_text("#status").startswith("saved")
    (workspace / "r4" / "01_pedestrian" / "off_road.toml").unlink()


# Items 9 and 10: the previews follow the chosen driver; the slider ends where its episode
# ended, with a marker; every label shows its frame's own time; Play animates the images.
def test_previews_follow_the_driver_and_its_episode(page, server: str) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    page.wait_for_function("window.editor.episodeReady()")
    expert_end = float(page.get_attribute("#time", "max"))
    assert "expert ends at" in page.inner_text("#time-end") and "destination_reached" in page.inner_text(
        "#time-end"
    )
    page.select_option("#driver", "follower@8")
    page.wait_for_function("window.editor.episodeReady()")
    idle(page)
    end = float(page.get_attribute("#time", "max"))
    assert end < expert_end
    marker = page.inner_text("#time-end")
    assert f"follower@8 ends at {end:.2f} s" in marker and "collision" in marker, marker
    # The slider starts at the episode's first decision: the label there is that frame's time.
    t0 = float(page.get_attribute("#time", "min"))
    v = slide_to(page, t0)
    assert page.inner_text("#time-out") == f"{v:.2f}"
    assert page.get_attribute("#front", "data-driver") == "follower@8"
    assert page.inner_text("#front-label").endswith(f"t = {v:.2f} s")
    # At the end: the follower's own frame at the crash (not the expert's).
    v = slide_to(page, end)
    assert v == pytest.approx(end) and page.inner_text("#time-out") == f"{end:.2f}"
    assert "follower@8" in page.inner_text("#bev-label")
    # Play: the images change with the map, frame by frame.
    slide_to(page, t0)
    seen: list[str] = page.evaluate(
        """() => new Promise((resolve) => {
        const times = [];
        const img = document.getElementById('front');
        const obs = new MutationObserver(() => times.push(img.dataset.time));
        obs.observe(img, { attributes: true, attributeFilter: ['data-time'] });
        document.getElementById('btn-play').click();
        const wait = () => document.getElementById('btn-play').textContent === 'Play' && times.length
          ? (obs.disconnect(), resolve(times)) : setTimeout(wait, 50);
        setTimeout(wait, 50);
      })"""
    )
    assert len(set(seen)) > 10 and float(seen[-1]) == pytest.approx(end), seen[-3:]


# Item 11: the editor's driver names are `r4 run --agent` names; the scores agree.
def test_the_editors_run_is_reproduced_by_r4_run(page, server: str, workspace: Path, tmp_path: Path) -> None:
    page.goto(server + "#" + PED)
    idle(page)
    page.select_option("#driver", "follower@8")
    page.click("#btn-run")
    idle(page)
    shown = page.inner_text("#run-score")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "drivehierarchy.cli",
            "r4",
            "run",
            "--agent",
            "follower@8",
            "--scenario",
            str(workspace / "r4" / PED),
            "--seed",
            "0",
            "--out",
            str(tmp_path),
            "--json",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    import json

    rec = json.loads(r.stdout)
    assert f"follower@8: S_R4 {rec['score_composed']:.1f}, {rec['termination_reason']}" in shown, (shown, rec)


# Item 12: no broken images or empty panels before a file is open; a favicon; zoom to the
# route with a scale bar; undo / redo of form edits.
def test_landing_page_favicon_zoom_scale_bar_and_undo(page, server: str) -> None:
    page.goto(server)
    idle(page)
    broken = page.eval_on_selector_all(
        "img", "els => els.filter((e) => e.offsetParent !== null && !e.naturalWidth).length"
    )
    assert broken == 0
    assert page.is_visible("#preview .placeholder") and not page.is_visible("#run")
    assert page.get_attribute("link[rel=icon]", "href") == "/static/favicon.svg"
    page.goto(server + "#" + PED)
    idle(page)
    # Zoomed to the route: its ends are inside the canvas, and much larger than the whole town.
    scale = page.evaluate("window.editor.S.view.scale")
    page.click("#btn-fit-map")
    whole = page.evaluate("window.editor.S.view.scale")
    assert scale > 1.5 * whole
    page.click("#btn-fit-route")
    m = float(page.get_attribute("#map", "data-scale-m"))
    px = float(page.get_attribute("#map", "data-scale-px"))
    assert m in {1, 2, 5, 10, 20, 50, 100, 200, 500, 1000} and px == pytest.approx(m * scale, rel=1e-3)
    text = page.evaluate("window.editor.S.text")
    set_field(page, "actors.0.speed_mps", "1.3")
    set_field(page, "actors.1.speed_mps", "0.9")
    edited = page.evaluate("window.editor.S.text")
    page.click("#btn-undo")
    idle(page)
    page.click("#btn-undo")
    idle(page)
    assert page.evaluate("window.editor.S.text") == text
    assert page.input_value("[data-path='actors.0.speed_mps']") == "1.1"
    assert page.is_disabled("#btn-undo")
    page.click("#btn-redo")
    idle(page)
    page.keyboard.press("Control+Shift+Z")
    idle(page)
    assert page.evaluate("window.editor.S.text") == edited


# Items 4 and 5, rooted at a category folder with no --map: New picks a built-in map (never
# `map = ""`), and Save as's default path is inside the root, not `01_pedestrian/...` again.
def test_new_in_a_category_root_without_a_default_map(page, category_server: str, workspace: Path) -> None:
    page.goto(category_server)
    idle(page)
    maps = page.eval_on_selector_all("#new-map option", "els => els.map((e) => e.value)")
    assert maps[0] == "" and all(m.startswith("builtin:") for m in maps[1:]) and "builtin:town01" in maps
    page.fill("#new-id", "here")
    page.select_option("#new-category", "01_pedestrian")
    page.click("#btn-new")
    idle(page)
    assert page.input_value("#saveas-path") == "here.toml"
    page.once("dialog", lambda d: d.accept())
    page.select_option("#new-map", "builtin:town01")
    page.click("#btn-new")
    idle(page)
    assert page.input_value("#saveas-path") == "here.toml"
    assert 'map = "builtin:town01"' in page.evaluate("window.editor.S.text")
    page.click("#tools button[data-mode=ego-start]")
    click_lane(page, "C2T_1", 30.0)
    page.click("#tools button[data-mode=ego-dest]")
    click_lane(page, "C2T_1", 200.0)
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    page.click("#btn-saveas")
    idle(page)
    assert page.inner_text("#status") == "saved here.toml"
    root = workspace.parent / "category_root" / "01_pedestrian"
    assert (root / "here.toml").is_file() and not (root / "01_pedestrian").exists()


def test_conditions_are_picked_from_the_facts_and_saved(page, server: str, workspace: Path) -> None:
    path = workspace / "r4" / PED
    before = path.read_text(encoding="utf-8")
    page.goto(server + "#" + PED)
    idle(page)
    options = page.eval_on_selector_all(
        "[data-path='conditions.weather'] option", "els => els.map(e => e.value)"
    )
    assert options == ["", "clear", "overcast", "rain", "fog"]
    page.select_option("[data-path='conditions.time_of_day']", "night")
    idle(page)
    page.select_option("[data-path='conditions.weather']", "rain")
    idle(page)
    assert page.is_hidden("#error-box"), page.inner_text("#error-box")
    page.click("#btn-save")
    idle(page)
    after = path.read_text(encoding="utf-8")
    try:
        assert "[conditions]" in after and 'time_of_day = "night"' in after and 'weather = "rain"' in after
        r = validate_cli(path)
        assert r.returncode == 0, r.stdout + r.stderr
    finally:
        path.write_text(before, encoding="utf-8")
