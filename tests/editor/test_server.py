"""Server-level tests of the scenario editor: security checks, the API over `_core`, save/load."""

from __future__ import annotations

import itertools
import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SUITE = REPO / "scenarios" / "r4"
BASE = "http://127.0.0.1:8765"
ORIGIN = {"Origin": BASE}
PED = "01_pedestrian/town01_01_midblock_crossing.toml"


# -- security ---------------------------------------------------------------------------------
def test_foreign_host_is_refused(client) -> None:
    assert client.get("/api/info").status_code == 200
    assert client.get("/api/info", headers={"Host": "localhost:8765"}).status_code == 200
    for host in ("evil.example:8765", "rebind.attacker.test", "127.0.0.1.evil.test:8765"):
        r = client.get("/api/info", headers={"Host": host})
        assert r.status_code == 403 and "foreign Host" in r.text, host
    r = client.post("/api/save", json={}, headers={"Host": "evil.example", "Origin": "http://evil.example"})
    assert r.status_code == 403


def test_foreign_origin_is_refused(client) -> None:
    r = client.get("/api/info", headers={"Origin": "http://evil.example"})
    assert r.status_code == 403 and "foreign Origin" in r.text
    text = (client.app.state.editor.root / PED).read_text(encoding="utf-8")
    r = client.post("/api/save", json={"path": PED, "text": text}, headers={"Origin": "http://evil.example"})
    assert r.status_code == 403
    # Same host, other port: another origin.
    r = client.post("/api/save", json={"path": PED, "text": text}, headers={"Origin": "http://127.0.0.1:9"})
    assert r.status_code == 403


def test_post_without_origin_is_refused(client) -> None:
    r = client.post("/api/validate", json={"path": PED, "text": ""})
    assert r.status_code == 403 and "Origin" in r.text
    r = client.post(
        "/api/validate", json={"path": PED, "text": ""}, headers={**ORIGIN, "Sec-Fetch-Site": "cross-site"}
    )
    assert r.status_code == 403


def test_oversized_body_is_refused(client) -> None:
    big = "#" * 300_000
    r = client.post("/api/validate", json={"path": PED, "text": big}, headers=ORIGIN)
    assert r.status_code == 413


@pytest.mark.parametrize(
    ("path", "why"),
    [
        ("../evil.toml", "`..`"),
        ("01_pedestrian/../../evil.toml", "`..`"),
        ("ABSOLUTE", "absolute"),  # replaced by an absolute path beside the root
        ("01_pedestrian/x.py", "*.toml"),
        ("out/x.toml", "symlink"),
    ],
)
def test_paths_outside_the_root_are_refused(
    client, workspace: Path, tmp_path: Path, path: str, why: str
) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    (workspace / "r4" / "out").symlink_to(outside)
    text = (workspace / "r4" / PED).read_text(encoding="utf-8")
    if path == "ABSOLUTE":
        path = str(tmp_path / "evil.toml")
    r = client.post("/api/save", json={"path": path, "text": text}, headers=ORIGIN)
    assert r.status_code == 403, r.text
    assert why in r.json()["error"]
    assert not list(outside.iterdir())
    assert not (tmp_path / "evil.toml").exists()
    r = client.get("/api/file", params={"path": path})
    assert r.status_code == 403


def test_symlinked_file_out_is_refused(client, workspace: Path, tmp_path: Path) -> None:
    target = tmp_path / "victim.toml"
    target.write_text("x = 1\n", encoding="utf-8")
    (workspace / "r4" / "link.toml").symlink_to(target)
    r = client.get("/api/file", params={"path": "link.toml"})
    assert r.status_code == 403 and "symlink" in r.json()["error"]


# -- the API over _core -------------------------------------------------------------------------
def test_load_gives_the_worlds_geometry(client) -> None:
    r = client.get("/api/file", params={"path": PED})
    d = r.json()
    assert r.status_code == 200 and d["ok"], d
    geo = d["geometry"]
    assert geo["summary"]["id"] == "town01_01_midblock_crossing"
    assert geo["summary"]["route_length_m"] == pytest.approx(230.0)
    assert geo["summary"]["reference_duration_s"] == 33.0
    assert geo["ego"]["start_lane"] == "C2T_1"
    assert len(geo["ego"]["route"]) >= 2
    ped = geo["actors"][0]
    assert ped["kind"] == "pedestrian" and ped["motion"]["trigger"]["kind"] == "ego_eta"


def test_light_programs_over_time_come_from_the_world(client) -> None:
    """The light timeline's schedule: the map's program of town01's C (phases ending at 37, 42,
    45, 82, 87, 90 s), shifted by an override's `offset_s`, or started in its `start_phase`."""
    text = client.get("/api/file", params={"path": PED}).json()["text"]

    def light_c(extra: str) -> dict:
        d = client.post("/api/validate", json={"path": PED, "text": text + extra}, headers=ORIGIN).json()
        assert d["ok"], d
        return next(lt for lt in d["geometry"]["lights"] if lt["tl_id"] == "C")

    duration = client.get("/api/file", params={"path": PED}).json()["geometry"]["scenario_duration_s"]

    plain = light_c("")
    assert not plain["overridden"] and plain["cycle_s"] == 90.0
    assert plain["schedule"][:3] == [[0.0, 37.0, 0], [37.0, 42.0, 1], [42.0, 45.0, 2]]
    # The schedule spans the episode's timeout (2 × the scenario duration), phases back to back.
    sched = plain["schedule"]
    assert all(a[1] == pytest.approx(b[0]) for a, b in itertools.pairwise(sched))
    assert sched[-1][1] == pytest.approx(2 * duration)
    # At t = 0 the shifted program is at (0 − 12) mod 90 = 78 s: phase 3, which ends at 82.
    shifted = light_c('\n[[lights]]\ntls = "C"\noffset_s = 12.0\n')
    assert shifted["overridden"] and shifted["schedule"][:2] == [[0.0, 4.0, 3], [4.0, 9.0, 4]]
    started = light_c('\n[[lights]]\ntls = "C"\nstart_phase = 2\nphase_elapsed_s = 1.0\n')
    assert started["schedule"][0] == [0.0, pytest.approx(2.0), 2]
    own = light_c('\n[[lights]]\ntls = "C"\nphases = [{ state = "' + "r" * 20 + '", duration_s = 4.0 }]\n')
    assert own["phases"] == [{"duration_s": 4.0, "state": "r" * 20}] and own["schedule"][1] == [4.0, 8.0, 0]


def test_map_geometry_and_snap(client) -> None:
    r = client.get("/api/map", params={"map": "../../maps/town01/town01.net.xml", "path": PED})
    g = r.json()
    assert r.status_code == 200, g
    lane = next(ln for ln in g["lanes"] if ln["id"] == "C2T_1")
    assert lane["drivable"] and len(lane["shape"]) >= 2
    assert g["signal_heads"] and g["programs"][0]["phases"]
    # The builtin map (the editor's --map) is the same network.
    assert len(client.get("/api/map").json()["lanes"]) == len(g["lanes"])
    x, y = lane["shape"][0]
    r = client.post(
        "/api/snap",
        json={"path": PED, "map": "builtin:town01", "x": x + 20, "y": y + 0.3, "vclass": "passenger"},
        headers=ORIGIN,
    )
    assert r.json()["lane"] == "C2T_1" and r.json()["s"] == pytest.approx(20.0, abs=0.1)
    r = client.post(
        "/api/snap", json={"path": PED, "map": "builtin:town01", "x": 1e6, "y": 0}, headers=ORIGIN
    )
    assert r.json()["lane"] is None


def test_invalid_edit_names_the_field(client) -> None:
    text = client.get("/api/file", params={"path": PED}).json()["text"]
    r = client.post(
        "/api/edit",
        json={"path": PED, "text": text, "edits": [{"path": ["actors", 0, "speed_mps"], "value": -1.0}]},
        headers=ORIGIN,
    )
    d = r.json()
    assert d["ok"] is False
    err = d["error"]
    assert err["field"] == "actors[0].speed_mps" and err["value"] == "-1"
    assert err["line"] == 19 and "must be" in err["reason"]
    assert err["message"].startswith(f"{PED}:19:")
    # Nothing invalid is saved.
    r = client.post("/api/save", json={"path": PED, "text": d["text"]}, headers=ORIGIN)
    assert r.status_code == 422 and r.json()["saved"] is False
    assert client.get("/api/file", params={"path": PED}).json()["text"] == text


def test_one_edit_gives_a_minimal_diff(client, workspace: Path) -> None:
    before = (workspace / "r4" / PED).read_text(encoding="utf-8")
    r = client.post(
        "/api/edit",
        json={
            "path": PED,
            "text": before,
            "edits": [{"path": ["actors", 0, "start", "ego_eta_s"], "value": 3.4}],
        },
        headers=ORIGIN,
    )
    d = r.json()
    assert d["ok"], d
    r = client.post("/api/save", json={"path": PED, "text": d["text"]}, headers=ORIGIN)
    assert r.json()["saved"]
    after = (workspace / "r4" / PED).read_text(encoding="utf-8")
    changed = [(a, b) for a, b in zip(before.splitlines(), after.splitlines(), strict=True) if a != b]
    assert changed == [
        (
            'start = { ego_eta_s = 2.9, of = { lane = "C2T_1", s = 140.0 } }',
            'start = { ego_eta_s = 3.4, of = { lane = "C2T_1", s = 140.0 } }',
        )
    ]


def test_unchanged_save_is_byte_identical_for_the_whole_suite(tmp_path: Path) -> None:
    """Every suite file read through the API and saved back unchanged keeps its bytes; so does a
    tomlkit parse + dump (what every edit goes through)."""
    import shutil

    import tomlkit
    from starlette.testclient import TestClient

    from drivehierarchy.editor import create_app

    root = tmp_path / "scenarios"
    shutil.copytree(SUITE.parent, root, symlinks=True, ignore=shutil.ignore_patterns("*.net.xml*"))
    # The maps are read-only for the editor: link them back.
    for d in (SUITE.parent / "maps").iterdir():
        if d.is_dir():
            shutil.rmtree(root / "maps" / d.name)
            (root / "maps" / d.name).symlink_to(d)
    paths = sorted((root / "r4").glob("*/*.toml"))
    assert len(paths) == 100
    originals = {p: p.read_bytes() for p in paths}
    with TestClient(create_app(root / "r4", precompute=False), base_url=BASE) as client:
        for p in paths:
            rel = p.relative_to(root / "r4").as_posix()
            d = client.get("/api/file", params={"path": rel}).json()
            assert d["ok"], (rel, d.get("error"))
            assert tomlkit.dumps(tomlkit.parse(d["text"])) == d["text"], rel
            r = client.post("/api/edit", json={"path": rel, "text": d["text"], "edits": []}, headers=ORIGIN)
            r = client.post("/api/save", json={"path": rel, "text": r.json()["text"]}, headers=ORIGIN)
            assert r.json()["saved"], rel
    for p, data in originals.items():
        assert p.read_bytes() == data, p


def test_scene_frames_run_and_probe(client) -> None:
    text = client.get("/api/file", params={"path": PED}).json()["text"]
    body = {"path": PED, "text": text}
    s0 = client.post("/api/scene", json={**body, "time_s": 0}, headers=ORIGIN).json()
    s10 = client.post("/api/scene", json={**body, "time_s": 10}, headers=ORIGIN).json()
    assert s10["time_s"] == pytest.approx(10.0, abs=0.26) and s10["ego"]["x"] > s0["ego"]["x"] + 20
    assert {a["id"] for a in s0["actors"]} == {1, 2}
    r = client.post("/api/frame", json={**body, "time_s": 10, "view": "front"}, headers=ORIGIN)
    assert r.status_code == 200 and r.content[:8] == b"\x89PNG\r\n\x1a\n"
    run = client.post("/api/run", json={**body, "driver": "expert"}, headers=ORIGIN).json()
    assert run["score"]["termination_reason"] == "destination_reached"
    assert run["states"][-1]["time_s"] > 20
    probe = client.post("/api/probe", json=body, headers=ORIGIN).json()["probe"]
    assert [p["cell"] for p in probe] == ["expert", "late_expert", "follower@8", "lights@8"]
    scores = {p["cell"]: p["score"] for p in probe}
    assert scores["expert"] > 80 > scores["follower@8"]


def test_save_as_from_a_category_template(client, workspace: Path) -> None:
    r = client.post("/api/new", json={"id": "my_crossing", "category": "01_pedestrian"}, headers=ORIGIN)
    d = r.json()
    assert d["ok"], d
    assert d["path"] == "01_pedestrian/my_crossing.toml"
    assert 'id = "my_crossing"' in d["text"] and 'map = "builtin:town01"' in d["text"]
    r = client.post("/api/save", json={"path": d["path"], "text": d["text"], "create": True}, headers=ORIGIN)
    assert r.json()["saved"]
    assert (workspace / "r4" / d["path"]).read_text(encoding="utf-8") == d["text"]
    r = client.post("/api/save", json={"path": d["path"], "text": d["text"], "create": True}, headers=ORIGIN)
    assert r.status_code == 400 and "exists" in r.json()["error"]


def test_page_and_assets_are_served(client) -> None:
    r = client.get("/")
    assert r.status_code == 200 and "<canvas" in r.text
    assert "http" not in r.text.replace(BASE, "").split("<body")[0].lower().replace("http-equiv", "")
    assert client.get("/static/editor.js").status_code == 200
    assert json.loads(client.get("/api/info").text)["categories"][0] == "01_pedestrian"


def test_precomputed_frames_equal_rendered_ones(workspace: Path) -> None:
    """The background worker drives the previewed buffer to its end and renders every decision's
    frames; a cached frame is the bytes an on-demand render gives."""
    import threading

    from drivehierarchy.editor.app import Editor
    from drivehierarchy.editor.scene import ScenePlayer

    ed = Editor(workspace / "r4")
    path = str(workspace / "r4" / PED)
    text = Path(path).read_text(encoding="utf-8")
    player = ed.players.get(path, text)
    stop = threading.Event()
    steps = 0
    while player.precompute_step():
        steps += 1
    assert player.done and len(player.frames) == 2 * len(player.states)
    stop.set()
    fresh = ScenePlayer(path, text)
    try:
        for t in (0.0, 7.3, 19.0):
            for view in ("front", "bev"):
                cached, time_s = player.png_at(t, view)
                assert (cached, time_s) == fresh.png_at(t, view)
    finally:
        fresh.close()
        ed.players.close()


def test_sumo_maps_are_drawn_and_snapped(client) -> None:
    """`sumo:` maps (under the installed SUMO) work like project maps."""
    spec = "sumo:tools/game/A10KW/osm.net.xml"
    r = client.get("/api/map", params={"map": spec})
    if r.status_code == 400 and "SUMO" in r.json().get("error", ""):
        pytest.skip("no SUMO_HOME in this environment")
    g = r.json()
    assert r.status_code == 200 and len(g["lanes"]) > 50, g.get("error")
    lane = next(
        ln for ln in g["lanes"] if ln["drivable"] and ln["function"] == "normal" and ln["length_m"] > 20
    )
    x, y = lane["shape"][0]
    (x1, y1) = lane["shape"][1]
    f = 5.0 / max(1e-9, ((x1 - x) ** 2 + (y1 - y) ** 2) ** 0.5)
    r = client.post(
        "/api/snap",
        json={"path": PED, "map": spec, "x": x + f * (x1 - x), "y": y + f * (y1 - y), "vclass": "passenger"},
        headers=ORIGIN,
    )
    hit = r.json()
    assert hit["lane"] is not None and hit["distance_m"] < 1.0


def test_an_edited_buffer_starts_driving_before_its_preview_is_asked(client) -> None:
    """A valid edit hands its buffer to the background thread (the page asks for the preview
    120 ms later); an invalid one does not."""
    import threading
    import time

    ed = client.app.state.editor
    text = (ed.root / PED).read_text(encoding="utf-8")
    bad = client.post(
        "/api/validate",
        json={"path": PED, "text": text.replace("speed_mps", "speed_mps = -1 #")},
        headers=ORIGIN,
    )
    assert not bad.json()["ok"] and ed._wanted is None
    r = client.post(
        "/api/edit",
        json={"path": PED, "text": text, "edits": [{"path": ["ego", "speed_mps"], "value": 7.5}]},
        headers=ORIGIN,
    )
    new = r.json()["text"]
    assert r.json()["ok"] and ed._wanted == (str(ed.abs_path(PED)), new)
    stop = threading.Event()
    worker = threading.Thread(target=ed.precompute, args=(stop,), daemon=True)
    worker.start()
    try:
        deadline = time.monotonic() + 120  # a bound for a stuck thread, not a speed claim
        while time.monotonic() < deadline:
            player = ed.players.most_recent()
            if player is not None and player.text == new and len(player.times) > 1:
                break
            time.sleep(0.05)
        else:
            raise AssertionError("the edited buffer was never driven")
        assert ed._wanted is None
    finally:
        stop.set()
        ed.wake.set()
        worker.join(timeout=60)


def test_suite_files_name_builtin_maps_and_a_copied_folder_validates(tmp_path: Path) -> None:
    """Every suite file on a shipped map names it `builtin:NAME`, so a category folder copied
    anywhere resolves; an old relative path to a shipped map gets an error that offers the fix."""
    import shutil

    from drivehierarchy import _core
    from drivehierarchy.scenarios import sumo_home

    paths = sorted(SUITE.glob("*/*.toml"))
    assert len(paths) == 100
    for p in paths:
        (line,) = [ln for ln in p.read_text(encoding="utf-8").splitlines() if ln.startswith("map = ")]
        assert re.match(r'map = "(builtin:[a-z0-9_]+|sumo:[^"]+)"', line), (p, line)
    mine = tmp_path / "mine"
    shutil.copytree(SUITE / "01_pedestrian", mine)
    for p in sorted(mine.glob("town01_*.toml")):
        _core.scenario_geometry(str(p), p.read_text(encoding="utf-8"), sumo_home())
    old = (mine / PED.split("/")[1]).read_text(encoding="utf-8")
    old = old.replace('map = "builtin:town01"', 'map = "../../maps/town01/town01.net.xml"')
    with pytest.raises(Exception) as exc:
        _core.scenario_geometry(str(mine / "old.toml"), old, sumo_home())
    msg = str(exc.value)
    assert "field `map` = ../../maps/town01/town01.net.xml: map file not found" in msg, msg
    assert 'write map = "builtin:town01" to use it from any folder' in msg, msg


def test_every_error_of_a_buffer_is_reported_at_its_field(client) -> None:
    """The validator stops at its first error; the editor reports each independent one."""
    text = client.get("/api/file", params={"path": PED}).json()["text"]
    bad = text.replace("speed_mps = 1.1", "speed_mps = -1.1", 1)
    assert bad != text
    bad = bad.replace('kind = "pedestrian"', 'kind = "pedestrian"\nat_end = "vanish"', 1)
    bad = re.sub(r"reference_duration_s = [\d.]+", "reference_duration_s = -3.0", bad, count=1)
    d = client.post("/api/validate", json={"path": PED, "text": bad}, headers=ORIGIN).json()
    assert not d["ok"]
    fields = [e["field"] for e in d["errors"]]
    assert set(fields) == {"reference_duration_s", "actors[0].speed_mps", "actors[0].at_end"}, d["errors"]
    assert d["error"] == d["errors"][0]
    # Each message's line is the line of the text as written.
    lines = bad.splitlines()
    for e in d["errors"]:
        key = e["field"].rsplit(".", 1)[-1]
        assert lines[e["line"] - 1].startswith(key), (e, lines[e["line"] - 1])
    # An error of a whole row (a required key left out names its table) ends the search:
    # removing the row would renumber the rows after it.
    missing = bad.replace('kind = "pedestrian"\n', "", 1)
    d = client.post("/api/validate", json={"path": PED, "text": missing}, headers=ORIGIN).json()
    fields = [e["field"] for e in d["errors"]]
    assert fields[-1] == "actors[0]" and "missing field `kind`" in d["errors"][-1]["message"], fields


def test_an_off_road_path_is_a_warning_not_an_error(client) -> None:
    text = client.get("/api/file", params={"path": PED}).json()["text"]
    d = client.post("/api/validate", json={"path": PED, "text": text}, headers=ORIGIN).json()
    assert d["ok"] and d["warnings"] == []
    doc = d["doc"]
    i = next(i for i, a in enumerate(doc["actors"]) if "waypoints" in a)
    edits = [{"path": ["actors", i, "waypoints", 1], "value": {"x": 60.0, "y": 60.0}, "floats": True}]
    r = client.post("/api/edit", json={"path": PED, "text": text, "edits": edits}, headers=ORIGIN).json()
    assert r["ok"], r.get("error")
    (w,) = r["warnings"]
    assert w["field"] == f"actors[{i}].waypoints"
    assert "from the nearest lane open to pedestrian" in w["message"] and "(60.0, 60.0)" in w["message"]
    r = client.post(
        "/api/save",
        json={"path": "01_pedestrian/off.toml", "text": r["text"], "create": True},
        headers=ORIGIN,
    )
    assert r.json()["saved"]


def test_new_scenarios_map_picker_template_and_save_as_path(client, workspace: Path) -> None:
    info = client.get("/api/info").json()
    assert {"builtin:town01", "builtin:town02"} <= set(info["builtin_maps"])
    assert {"expert", "late_expert", "follower@8", "lights@8", "constant@8"} <= set(info["drivers"])
    body = {"id": "n1", "category": "01_pedestrian"}
    d = client.post(
        "/api/new", json={**body, "template": False, "map": "builtin:town02"}, headers=ORIGIN
    ).json()
    assert 'map = "builtin:town02"' in d["text"] and d["path"] == "01_pedestrian/n1.toml"
    kept = client.post("/api/new", json=body, headers=ORIGIN).json()
    dropped = client.post("/api/new", json={**body, "keep_actors": False}, headers=ORIGIN).json()
    assert kept["ok"] and dropped["ok"], dropped.get("error")
    assert kept["doc"]["description"] == "" and kept["doc"]["actors"]
    assert "actors" not in dropped["doc"] and "obstacles" not in dropped["doc"]
    from starlette.testclient import TestClient

    from drivehierarchy.editor import create_app

    # No --map and no map picked: a clear refusal, not `map = ""`.
    with TestClient(create_app(workspace / "r4", None, precompute=False), base_url=BASE) as c:
        r = c.post("/api/new", json={**body, "template": False}, headers=ORIGIN)
        assert r.status_code == 400 and "needs a map" in r.json()["error"]
    # Rooted at a category folder, Save as's default stays in it.
    with TestClient(
        create_app(workspace / "r4" / "01_pedestrian", None, precompute=False), base_url=BASE
    ) as c:
        d = c.post("/api/new", json=body, headers=ORIGIN).json()
        assert d["path"] == "n1.toml", d["path"]


def test_drivers_by_the_probes_names(client) -> None:
    text = client.get("/api/file", params={"path": PED}).json()["text"]
    body = {"path": PED, "text": text}
    ep = client.post("/api/episode", json={**body, "driver": "follower@8"}, headers=ORIGIN).json()
    run = client.post("/api/run", json={**body, "driver": "follower@8"}, headers=ORIGIN).json()
    assert ep["end_s"] == run["states"][-1]["time_s"] and ep["start_s"] == run["states"][0]["time_s"]
    assert ep["termination"] == run["score"]["termination_reason"]
    r = client.post("/api/episode", json={**body, "driver": "follower@99"}, headers=ORIGIN)
    assert r.status_code == 400 and "follower@99" in r.json()["error"]


def test_favicon(client) -> None:
    r = client.get("/favicon.ico")
    assert r.status_code == 200 and r.headers["content-type"].startswith("image/svg")


def test_an_error_caused_by_a_removed_key_is_not_reported() -> None:
    from drivehierarchy.editor.app import _caused_by

    rate = "traffic.flows[0].vehs_per_hour"
    assert _caused_by("traffic.flows[0]", "give exactly one of vehs_per_hour and probability", rate)
    assert _caused_by("actors[0]", "missing field `waypoints`", "actors[0].waypoints")
    assert _caused_by("actors[0].start.of", "must be a place", "actors[0].start")
    assert not _caused_by("actors[0]", "missing field `kind`", "actors[0].at_end")
    assert not _caused_by("actors[1].speed_mps", "must be ≥ 0", "actors[0].speed_mps")
