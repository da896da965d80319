"""The editor's ASGI app (Starlette): the page, its assets, and a JSON API over `_core`.

A local server that writes files, so every request is checked before it reaches a route:

* Host must be the server's own name (127.0.0.1 / localhost): a DNS-rebinding page gets 403;
* a request carrying a foreign Origin gets 403, and a state-changing request (POST) must carry
  the page's own Origin (browsers always send it on POST), so a cross-site form or fetch cannot
  save files;
* bodies over `max_body_bytes` get 413;
* file paths are confined to the root folder (`files.confine`).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import re
import threading
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import tomlkit
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, PlainTextResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from drivehierarchy import DriveHierarchyError, _core
from drivehierarchy.editor import files
from drivehierarchy.editor.scene import DRIVERS, PROBE_CELLS, PlayerCache, ScenePlayer
from drivehierarchy.scenarios import builtin_root, builtin_scenarios, sumo_home

STATIC = Path(__file__).resolve().parent / "static"
ALLOWED_HOSTS = ("127.0.0.1", "localhost")
MAX_BODY_BYTES = 2_000_000
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


class OriginAndSizeGuard:
    """Refuses foreign Origins, POSTs without the page's Origin, and oversized bodies."""

    def __init__(self, app: ASGIApp, max_body_bytes: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.max_body_bytes = max_body_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        host = headers.get("host", "")
        origin = headers.get("origin")
        name = host.rsplit(":", 1)[0] if not host.startswith("[") else host
        if name not in ALLOWED_HOSTS:
            # DNS rebinding: a page of another name resolved to 127.0.0.1.
            await PlainTextResponse(f"refused: foreign Host {host!r}", 403)(scope, receive, send)
            return
        own = {f"http://{host}"}
        if origin is not None and origin not in own:
            await PlainTextResponse(f"refused: foreign Origin {origin!r}", 403)(scope, receive, send)
            return
        if scope["method"] not in SAFE_METHODS and origin is None:
            msg = "refused: a state-changing request must carry the page's Origin header"
            await PlainTextResponse(msg, 403)(scope, receive, send)
            return
        if headers.get("sec-fetch-site") not in (None, "same-origin", "none"):
            msg = f"refused: cross-site request (Sec-Fetch-Site: {headers['sec-fetch-site']})"
            await PlainTextResponse(msg, 403)(scope, receive, send)
            return
        length = headers.get("content-length")
        if length is not None and (not length.isdigit() or int(length) > self.max_body_bytes):
            msg = f"refused: request body of {length} bytes (limit {self.max_body_bytes})"
            await PlainTextResponse(msg, 413)(scope, receive, send)
            return
        seen = 0
        limit = self.max_body_bytes

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise BodyTooLarge
            return message

        try:
            await self.app(scope, counted, send)
        except BodyTooLarge:
            await PlainTextResponse(f"refused: request body over {limit} bytes", 413)(scope, receive, send)


class BodyTooLarge(Exception):
    pass


class Editor:
    """State of one editor server: its root folder, default map and players."""

    def __init__(self, root: Path, default_map: str | None = None) -> None:
        self.root = root.resolve()
        self.default_map = default_map
        # Each player has its own lock: a request on one buffer never waits for work on another.
        self.players = PlayerCache()
        # Requests being served: the precompute thread yields the CPU to them.
        self.in_flight = 0
        self._count_lock = threading.Lock()
        # A buffer just edited (path, text), for the precompute thread to start driving while the
        # page waits out its preview debounce; `wake` ends the thread's idle wait at once.
        self._wanted: tuple[str, str] | None = None
        self.wake = threading.Event()

    @contextlib.contextmanager
    def serving(self) -> Iterator[None]:
        with self._count_lock:
            self.in_flight += 1
        try:
            yield
        finally:
            with self._count_lock:
                self.in_flight -= 1

    def want(self, path: str, text: str) -> None:
        """Starts the world of a buffer just edited ahead of its preview request (the page asks
        120 ms after an edit; a new world on a SUMO scene must be driven from reset to t)."""
        with self._count_lock:
            self._wanted = (path, text)
        self.wake.set()

    def precompute(self, stop: threading.Event) -> None:
        """Works ahead for the most recent player (a buffer just edited first), one short unit at
        a time under its lock, so requests on it get the lock in between."""
        while not stop.is_set():
            if self.in_flight:
                stop.wait(0.02)
                continue
            try:
                with self._count_lock:
                    wanted, self._wanted = self._wanted, None
                if wanted is not None:
                    self.players.get(*wanted)  # becomes the most recent player
                player = self.players.most_recent()
                busy = player is not None and player.precompute_step()
            except Exception:  # a closed player, or a buffer the world cannot play (requests say why)
                busy = False
            self.wake.wait(0.005 if busy else 0.2)
            self.wake.clear()

    # -- helpers ---------------------------------------------------------------------------
    def abs_path(self, rel: str) -> Path:
        return files.confine(self.root, rel)

    def map_spec_for(self, rel: str, spec: str) -> str:
        """A scenario's `map` value as `_core` reads it from anywhere (relative → absolute)."""
        if spec.startswith(("sumo:", "builtin:")) or os.path.isabs(spec):
            return spec
        return str((self.abs_path(rel).parent / spec).resolve())

    def geometry(self, rel: str, text: str) -> dict[str, Any]:
        """`{ok, geometry | error, errors, warnings, doc}`: the world's resolution of the text,
        or the validator's messages split into file, line, column, field, value and reason
        (`error` the first, `errors` every independent one found); `warnings` (on a valid
        text) are what the world accepts but an author likely did not mean; `doc` is the TOML
        as data (what the page's forms show)."""
        doc = files.doc_json(text)
        out = self._resolve(rel, text)
        if out["ok"]:
            out["warnings"] = self.warnings(rel, doc, out["geometry"])
        else:
            out["errors"] = self._more_errors(rel, text, out["error"])
        return {"doc": doc, **out}

    def _resolve(self, rel: str, text: str) -> dict[str, Any]:
        try:
            geo = _core.scenario_geometry(str(self.abs_path(rel)), text, sumo_home())
        except DriveHierarchyError as exc:
            return {"ok": False, "error": files.error_fields(exc, self.root)}
        geo["summary"]["file"] = rel
        return {"ok": True, "geometry": geo}

    def _more_errors(self, rel: str, text: str, first: dict[str, Any]) -> list[dict[str, Any]]:
        """Every independent error of the text, not only the first the validator stops at.

        The validator (Rust) stops at its first error. Each error's key is removed from a copy
        of the text and the copy validated again: an error at another key is independent of
        the ones before (its line mapped back to the text as written). It stops at a TOML
        syntax error, at an error on a key already removed or inside / around one (that is the
        removal's own consequence, e.g. a required key now missing), at an error on a whole
        row (`actors[1]`: removing it would renumber the rows after it), or after
        `MAX_ERRORS`."""
        errors = [first]
        removed: list[str] = []
        current = text
        while len(errors) < MAX_ERRORS:
            field = errors[-1].get("field")
            path = files.field_path(field) if field else None
            if not path or isinstance(path[-1], int):
                break  # removing a row would renumber the rows after it (and their errors)
            try:
                current = files.apply_edits(current, [{"path": path, "delete": True}])
            except (ValueError, tomlkit.exceptions.TOMLKitError):
                break
            removed.append(str(field))
            nxt = self._resolve(rel, current)
            if nxt["ok"]:
                break
            err = nxt["error"]
            f = err.get("field")
            if not f or any(_caused_by(f, err.get("reason") or "", r) for r in removed):
                break
            errors.append(files.relocate_error(err, current, text))
        return errors

    def warnings(self, rel: str, doc: Any, geo: dict[str, Any]) -> list[dict[str, Any]]:
        """Actor paths that leave every lane open to the actor's class by more than a lane
        width (`snap_to_lane` from each point of the resolved path): valid, but likely a
        misplaced point. Pedestrians and cyclists cross roads on purpose (the suite's
        jaywalkers, a cyclist crossing a junction), so for them a point on any lane counts as
        on a lane: only a point off every lane is warned about."""
        if not isinstance(doc, dict) or not isinstance(doc.get("map"), str):
            return []
        spec = self.map_spec_for(rel, doc["map"])
        widths = _lane_widths(spec)
        out = []
        for i, actor in enumerate(geo.get("actors", [])):
            path = actor.get("motion", {}).get("path") or []
            vclass = actor.get("vclass")
            worst: tuple[float, list[float]] | None = None
            crosses = vclass in ("pedestrian", "bicycle")
            for x, y in path:
                hit = _core.snap_to_lane(
                    spec, float(x), float(y), OFF_ROAD_SEARCH_M, vclass, True, sumo_home()
                )
                if hit is not None and hit[2] <= widths.get(hit[0], 3.2):
                    continue
                if crosses:
                    near = _core.snap_to_lane(
                        spec, float(x), float(y), OFF_ROAD_SEARCH_M, None, True, sumo_home()
                    )
                    if near is not None and near[2] <= widths.get(near[0], 3.2):
                        continue
                dist = hit[2] if hit is not None else OFF_ROAD_SEARCH_M
                if worst is None or dist > worst[0]:
                    worst = (dist, [x, y])
            if worst is None:
                continue
            dist, (x, y) = worst
            actor_doc = (doc.get("actors") or [{}])[i] if i < len(doc.get("actors") or []) else {}
            key = "waypoints" if "waypoints" in actor_doc else "route" if "route" in actor_doc else "at"
            far = f"{dist:.0f} m" if dist < OFF_ROAD_SEARCH_M else f"over {OFF_ROAD_SEARCH_M:.0f} m"
            out.append(
                {
                    "field": f"actors[{i}].{key}",
                    "message": (
                        f"field `actors[{i}].{key}`: the path of {actor.get('name')!r} passes "
                        f"({x:.1f}, {y:.1f}), {far} from the nearest lane open to {vclass} "
                        "(more than a lane width): is a point misplaced? (a warning: the file is valid)"
                    ),
                }
            )
        return out


# Errors collected per validation (each costs one more validation of the text).
MAX_ERRORS = 20
# How far from a path point a lane is looked for (farther: "over 200 m").
OFF_ROAD_SEARCH_M = 200.0


def _inside(field: str, outer: str) -> bool:
    """`field` is `outer` or lies inside it (`actors[0].start.of` inside `actors[0]`)."""
    return field == outer or field.startswith((outer + ".", outer + "["))


def _caused_by(field: str, reason: str, removed: str) -> bool:
    """Whether an error found after removing `removed` may be that removal's consequence: an
    error at the removed key or inside it, or at a table around it whose reason names it
    (`missing field `waypoints``, `give exactly one of vehs_per_hour and probability`; a
    `missing field `kind`` is not the removed `at_end`'s)."""
    if _inside(field, removed):
        return True
    if _inside(removed, field):
        leaf = re.split(r"[.\[]", removed)[-1].rstrip("]")
        return re.search(rf"\b{re.escape(leaf)}\b", reason) is not None
    return False


@functools.lru_cache(maxsize=8)
def _lane_widths(spec: str) -> dict[str, float]:
    geo = _core.map_geometry(spec, sumo_home())
    return {lane["id"]: float(lane["width_m"]) for lane in geo["lanes"]}


def builtin_maps() -> list[str]:
    """The shipped maps, as `builtin:NAME`."""
    maps = builtin_root() / "maps"
    return sorted(f"builtin:{p.name}" for p in maps.iterdir() if (p / f"{p.name}.net.xml").is_file())


def _json(request_body: bytes) -> dict[str, Any]:
    try:
        data = json.loads(request_body or b"{}")
    except json.JSONDecodeError as exc:
        raise ValueError(f"request body: not JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise ValueError("request body: expected a JSON object")
    return data


def _field(data: dict[str, Any], key: str, kind: type | tuple[type, ...]) -> Any:
    if key not in data or not isinstance(data[key], kind):
        raise ValueError(f"request field `{key}`: missing or not a {getattr(kind, '__name__', kind)}")
    return data[key]


def templates() -> dict[str, str]:
    """One template per category: its first built-in scenario on the shipped town01 map (the
    small one every category has), else its first scenario."""
    out: dict[str, str] = {}
    for p in sorted(builtin_scenarios(), key=lambda p: (not p.stem.startswith("town01"), p.name)):
        out.setdefault(p.parent.name, str(p))
    return dict(sorted(out.items()))


def template_text(category: str, new_id: str, *, keep_actors: bool = True) -> str:
    """A category's template with its id and name set, its description emptied (it describes
    the template), its map made location-independent, and (`keep_actors=False`) its actors and
    obstacles dropped."""
    path = templates().get(category)
    if path is None:
        raise ValueError(f"category {category!r}: no template (known: {', '.join(sorted(templates()))})")
    doc = tomlkit.parse(Path(path).read_text(encoding="utf-8"))
    doc["id"] = new_id
    doc["name"] = new_id.replace("_", " ")
    if "description" in doc:
        doc["description"] = ""
    if not keep_actors:
        for key in ("actors", "obstacles"):
            if key in doc:
                del doc[key]
    spec = str(doc["map"])
    if not spec.startswith(("sumo:", "builtin:")):
        real = (Path(path).parent / spec).resolve()
        maps = (builtin_root() / "maps").resolve()
        if real.parent.parent == maps and real.name == f"{real.parent.name}.net.xml":
            doc["map"] = f"builtin:{real.parent.name}"
        else:
            doc["map"] = str(real)
    return tomlkit.dumps(doc)


def blank_text(new_id: str, category: str, map_spec: str) -> str:
    """A new scenario with nothing placed yet (invalid until the ego has a start and a goal)."""
    doc = tomlkit.document()
    doc["version"] = 1
    doc["id"] = new_id
    doc["name"] = new_id.replace("_", " ")
    doc["category"] = category
    doc["map"] = map_spec
    doc["ego"] = tomlkit.table()
    return tomlkit.dumps(doc)


def create_app(
    root: Path,
    default_map: str | None = None,
    *,
    max_body_bytes: int = MAX_BODY_BYTES,
    precompute: bool = True,
) -> Starlette:
    """The editor on `root`. `precompute`: a background thread drives the most recently
    previewed buffer to its end and renders its frames ahead of the slider."""
    ed = Editor(root, default_map)

    def api(fn: Any) -> Any:
        """Runs a sync handler in the thread pool; errors → 400 (403 for refused paths)."""

        async def endpoint(request: Request) -> Response:
            body = await request.body() if request.method == "POST" else b""
            from starlette.concurrency import run_in_threadpool

            try:
                with ed.serving():
                    return await run_in_threadpool(fn, request, body)
            except files.PathRefused as exc:
                return JSONResponse({"error": str(exc)}, 403)
            except (ValueError, DriveHierarchyError) as exc:
                return JSONResponse({"error": str(exc)}, 400)

        return endpoint

    def index(request: Request, body: bytes) -> Response:
        return FileResponse(STATIC / "index.html")

    def info(request: Request, body: bytes) -> Response:
        return JSONResponse(
            {
                "root": str(ed.root),
                "default_map": ed.default_map,
                "files": files.list_scenarios(ed.root),
                "categories": sorted(templates()),
                "probe_cells": list(PROBE_CELLS),
                "drivers": list(DRIVERS),
                "builtin_maps": builtin_maps(),
            }
        )

    def new_rel(category: str, new_id: str) -> str:
        """Where a new scenario is saved, relative to the actual root: `category/id.toml` when
        the root holds category folders (the suite's layout) or is empty, `id.toml` when the
        root is itself a category folder (or any other folder of scenarios)."""
        cats = set(templates())
        if ed.root.name in cats:
            return f"{new_id}.toml"
        subdirs = {p.name for p in ed.root.iterdir() if p.is_dir()}
        if subdirs & cats or not any(ed.root.glob("*.toml")):
            return f"{category}/{new_id}.toml"
        return f"{new_id}.toml"

    def facts(request: Request, body: bytes) -> Response:
        """The Rust facts the page builds its forms from (it keeps no copy of them)."""
        schema = _core.scenario_json_schema()
        return JSONResponse({"constants": _core.constants(), "schema": schema})

    def read(request: Request, body: bytes) -> Response:
        rel = request.query_params.get("path", "")
        p = files.confine(ed.root, rel, must_exist=True)
        if p.stat().st_size > files.MAX_FILE_BYTES:
            raise ValueError(f"{rel}: larger than {files.MAX_FILE_BYTES} bytes")
        # newline="" keeps the file's line endings, so an unchanged save is byte-identical.
        with p.open(encoding="utf-8", newline="") as fh:
            text = fh.read()
        return JSONResponse({"path": rel, "text": text, **ed.geometry(rel, text)})

    def map_geometry(request: Request, body: bytes) -> Response:
        spec = request.query_params.get("map") or ed.default_map
        if not spec:
            raise ValueError("query `map`: give the scenario's map (or start the editor with --map)")
        rel = request.query_params.get("path")
        if rel:
            spec = ed.map_spec_for(rel, spec)
        return JSONResponse(_core.map_geometry(spec, sumo_home()))

    def snap(request: Request, body: bytes) -> Response:
        d = _json(body)
        spec = ed.map_spec_for(_field(d, "path", str), _field(d, "map", str))
        hit = _core.snap_to_lane(
            spec,
            float(_field(d, "x", (int, float))),
            float(_field(d, "y", (int, float))),
            float(d.get("max_dist_m", 10.0)),
            d.get("vclass"),
            bool(d.get("internal", False)),
            sumo_home(),
        )
        if hit is None:
            return JSONResponse({"lane": None})
        lane, s, dist = hit
        return JSONResponse({"lane": lane, "s": round(s, 1), "distance_m": dist})

    def _checked(rel: str, text: str) -> dict[str, Any]:
        """The validator's answer; a valid buffer's world starts in the background."""
        out = ed.geometry(rel, text)
        if out["ok"]:
            ed.want(str(ed.abs_path(rel)), text)
        return out

    def validate(request: Request, body: bytes) -> Response:
        d = _json(body)
        return JSONResponse(_checked(_field(d, "path", str), _field(d, "text", str)))

    def edit(request: Request, body: bytes) -> Response:
        d = _json(body)
        rel, text = _field(d, "path", str), _field(d, "text", str)
        new = files.apply_edits(text, _field(d, "edits", list))
        return JSONResponse({"text": new, **_checked(rel, new)})

    def save(request: Request, body: bytes) -> Response:
        d = _json(body)
        rel, text = _field(d, "path", str), _field(d, "text", str)
        p = ed.abs_path(rel)
        if d.get("create") and p.exists():
            raise ValueError(f"{rel}: exists already (save as a new name, or open it)")
        if len(text.encode("utf-8")) > files.MAX_FILE_BYTES:
            raise ValueError(f"{rel}: larger than {files.MAX_FILE_BYTES} bytes")
        checked = ed.geometry(rel, text)
        if not checked["ok"]:
            return JSONResponse({"saved": False, **checked}, 422)
        p.parent.mkdir(parents=True, exist_ok=True)
        files.confine(ed.root, rel)  # again: the folder just made must not be a symlink out
        tmp = p.with_name(f".{p.name}.tmp")
        with tmp.open("w", encoding="utf-8", newline="") as fh:
            fh.write(text)
        os.replace(tmp, p)
        return JSONResponse({"saved": True, "path": rel, **checked})

    def new(request: Request, body: bytes) -> Response:
        d = _json(body)
        new_id = _field(d, "id", str)
        category = _field(d, "category", str)
        if d.get("template", True):
            text = template_text(category, new_id, keep_actors=bool(d.get("keep_actors", True)))
        else:
            spec = _field(d, "map", str) if d.get("map") is not None else ed.default_map
            if not spec:
                raise ValueError(
                    "request field `map`: an empty-map scenario needs a map (pick one, or start the "
                    "editor with --map)"
                )
            text = blank_text(new_id, category, spec)
        rel = new_rel(category, new_id)
        files.confine(ed.root, rel)
        return JSONResponse({"path": rel, "text": text, **ed.geometry(rel, text)})

    def _player(d: dict[str, Any]) -> Any:
        rel, text = _field(d, "path", str), _field(d, "text", str)
        return ed.players.get(str(ed.abs_path(rel)), text, int(d.get("seed", 0)), d.get("driver", "expert"))

    def scene(request: Request, body: bytes) -> Response:
        d = _json(body)
        t = float(_field(d, "time_s", (int, float)))
        return JSONResponse(_player(d).state_at(t))

    def frame(request: Request, body: bytes) -> Response:
        d = _json(body)
        t = float(_field(d, "time_s", (int, float)))
        view = d.get("view", "front")
        png, time_s = _player(d).png_at(t, view)
        return Response(png, media_type="image/png", headers={"X-Scene-Time": f"{time_s:.2f}"})

    def run(request: Request, body: bytes) -> Response:
        return JSONResponse(_player(_json(body)).run_to_end())

    def episode(request: Request, body: bytes) -> Response:
        """The chosen driver's episode to its end: its first and last decision times, how it
        ended and its score (the slider's range; no per-decision states)."""
        return JSONResponse(_player(_json(body)).episode())

    def favicon(request: Request, body: bytes) -> Response:
        return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml")

    def probe(request: Request, body: bytes) -> Response:
        d = _json(body)
        path, text = str(ed.abs_path(_field(d, "path", str))), _field(d, "text", str)
        out = []
        ed.players.release_worlds()
        for cell in PROBE_CELLS:
            # One-off players: probing does not push the previewed buffer out of the cache.
            player = ScenePlayer(path, text, seed=int(d.get("seed", 0)), driver=cell)
            try:
                rec = player.run_to_end()["score"]
            finally:
                player.close()
            out.append(
                {
                    "cell": cell,
                    "score": rec["score_composed"],
                    "termination": rec["termination_reason"],
                    "events": sorted({e["type"] for e in rec["events"]}),
                }
            )
        return JSONResponse({"probe": out})

    routes = [
        Route("/", api(index)),
        Route("/api/info", api(info)),
        Route("/api/facts", api(facts)),
        Route("/api/file", api(read)),
        Route("/api/map", api(map_geometry)),
        Route("/api/snap", api(snap), methods=["POST"]),
        Route("/api/validate", api(validate), methods=["POST"]),
        Route("/api/edit", api(edit), methods=["POST"]),
        Route("/api/save", api(save), methods=["POST"]),
        Route("/api/new", api(new), methods=["POST"]),
        Route("/api/scene", api(scene), methods=["POST"]),
        Route("/api/frame", api(frame), methods=["POST"]),
        Route("/api/run", api(run), methods=["POST"]),
        Route("/api/episode", api(episode), methods=["POST"]),
        Route("/favicon.ico", api(favicon)),
        Route("/api/probe", api(probe), methods=["POST"]),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    # The guard answers a foreign Host with 403; Starlette's TrustedHostMiddleware stays behind
    # it as a second check of the same rule.
    middleware = [
        Middleware(OriginAndSizeGuard, max_body_bytes=max_body_bytes),
        Middleware(TrustedHostMiddleware, allowed_hosts=list(ALLOWED_HOSTS)),
    ]

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        stop = threading.Event()
        worker = threading.Thread(target=ed.precompute, args=(stop,), daemon=True) if precompute else None
        if worker is not None:
            worker.start()
        yield
        stop.set()
        ed.wake.set()
        if worker is not None:
            worker.join(timeout=30)
        ed.players.close()

    app = Starlette(routes=routes, middleware=middleware, lifespan=lifespan)
    app.state.editor = ed
    return app
