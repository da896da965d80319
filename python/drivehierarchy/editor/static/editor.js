// The scenario editor's page. It draws and edits; every piece of world logic (lane snapping,
// routes, validation, actor poses at time t, frames, scores) is asked of the server, which asks
// the simulator (`_core`). Edits are sent as key paths and applied to the TOML by the server,
// so the file keeps its comments and layout.
"use strict";

const $ = (id) => document.getElementById(id);
const S = {
  path: null, text: "", doc: null, geo: null, error: null, map: null, mapKey: null,
  view: { scale: 1, ox: 0, oy: 0 }, mode: "select", selected: null, pending: [],
  scene: null, run: null, dirty: false, time: 0, info: null, busy: 0, hoverLane: null,
  errors: [], warnings: [], episode: null, undo: [], redo: [],
};
window.editor = { S };
// The simulator's facts (scenario enums, kind → SUMO class, actor keys: `_core.constants()`)
// and the scenario JSON Schema, fetched from /api/facts at load: the page keeps no copy of them.
let FACTS = null;
const K = () => FACTS.constants;
const EGO_VCLASS = () => K().ego_vclass;
// The SUMO class a traffic row's route must allow: its (shipped) vehicle type's; the ego's otherwise.
const vtypeClass = (vtype) => K().builtin_vtypes[vtype || K().default_vtype] ?? EGO_VCLASS();

// -- server ----------------------------------------------------------------------------------
function busy(delta) {
  S.busy += delta;
  document.body.dataset.busy = String(S.busy);
}

async function api(url, body) {
  busy(1);
  try {
    const opts = body === undefined ? {} : {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
    };
    const r = await fetch(url, opts);
    const type = r.headers.get("content-type") || "";
    if (type.startsWith("image/") && r.ok) {
      return { blob: await r.blob(), time: r.headers.get("X-Scene-Time") };
    }
    const d = type.includes("json") ? await r.json() : { error: await r.text() };
    if (!r.ok && !("ok" in d)) {
      const e = new Error(d.error || `${r.status} ${r.statusText}`);
      e.status = r.status;
      throw e;
    }
    return d;
  } finally {
    busy(-1);
  }
}

function status(msg, kind) {
  const el = $("status");
  el.textContent = msg;
  el.className = kind || "";
}

// An event handler whose failure is shown in the status line (never an unhandled promise).
function guard(fn, what) {
  return (...args) => Promise.resolve().then(() => fn(...args)).catch((e) => {
    status((what ? what + ": " : "") + e.message, "bad");
  });
}

function buffer() {
  return { path: S.path, text: S.text };
}

// -- buffer ------------------------------------------------------------------------------------
async function setBuffer(d) {
  if (d.path) S.path = d.path;
  S.text = d.text;
  S.doc = d.doc;
  if (d.ok) {
    S.geo = d.geometry;
    S.error = null;
    S.errors = [];
    S.warnings = d.warnings || [];
    S.episode = null; // the driver's episode of this text is asked for with the preview
  } else {
    S.error = d.error;
    S.errors = d.errors || [d.error];
    S.warnings = [];
    previewSeq++;
  }
  showPath();
  $("toml").value = S.text;
  await ensureMap();
  // The form is rebuilt from the new text: the input that had the focus gets it back.
  const focused = document.activeElement && document.activeElement.dataset && document.activeElement.dataset.path;
  renderForm();
  renderSummary();
  showError();
  if (focused) {
    const el = document.querySelector(`[data-path="${CSS.escape(focused)}"]`);
    if (el && el.type !== "hidden") el.focus();
  }
  draw();
  document.body.classList.toggle("has-file", !!S.doc);
  if (!S.error) {
    S.run = null;
    $("run-result").textContent = "";
    $("probe-result").textContent = "";
    drawTimeline();
    schedulePreview();
  }
}

// Another buffer (opened or new): nothing of the one before stays on the page.
function clearPreview() {
  S.episode = null;
  S.scene = null;
  S.run = null;
  previewSeq++;
  for (const view of ["front", "bev"]) {
    const img = $(view);
    if (img.src) URL.revokeObjectURL(img.src);
    img.removeAttribute("src");
    delete img.dataset.time;
    $(view + "-label").textContent = "";
  }
  $("time-end").textContent = "";
  delete $("time-end").dataset.endS;
  $("time-out").textContent = "–";
  $("run-result").textContent = "";
  $("probe-result").textContent = "";
  drawTimeline();
}

function showPath() {
  $("path").textContent = S.path ? S.path + (S.dirty ? " *" : "") : "";
  document.title = (S.dirty ? "* " : "") + (S.path || "drivehierarchy scenario editor");
}

// The status after a buffer change: what the validator said (never a stale "saved").
function bufferStatus(what) {
  if (S.error) {
    const n = S.errors.length;
    return status(`${what}: invalid, ${n} error${n === 1 ? "" : "s"} (see the fields)`, "bad");
  }
  const w = S.warnings.length;
  return status(w ? `${what}: valid, ${w} warning${w === 1 ? "" : "s"}` : `${what}: valid`, w ? "warn" : "good");
}

async function ensureMap() {
  const spec = (S.doc && typeof S.doc.map === "string" && S.doc.map) || (S.info && S.info.default_map);
  if (!spec) return;
  const key = S.path + "|" + spec;
  if (key === S.mapKey) return;
  const q = new URLSearchParams({ map: spec });
  if (S.path) q.set("path", S.path);
  try {
    S.map = await api("/api/map?" + q.toString());
    S.mapKey = key;
    fitRoute();
  } catch (e) {
    S.map = null;
    S.mapKey = null;
    status("map: " + e.message, "bad");
  }
}

// Edits run one after the other, each on the text the one before left.
let editChain = Promise.resolve();
function edit(edits) {
  const run = editChain.then(() => applyEdit(edits));
  editChain = run.catch(() => {});
  return run;
}

async function applyEdit(edits) {
  const before = S.text;
  const d = await api("/api/edit", { ...buffer(), edits });
  if (d.error && !("ok" in d)) throw new Error(d.error);
  remember(before, d.text);
  S.dirty = true;
  await setBuffer(d);
  bufferStatus("edited");
}

// Undo / redo: the buffer's texts before each edit (form, map, TOML panel), re-validated when
// taken back.
function remember(before, after) {
  if (before === after) return;
  S.undo.push(before);
  if (S.undo.length > 200) S.undo.shift();
  S.redo = [];
  updateUndo();
}

function updateUndo() {
  $("btn-undo").disabled = !S.undo.length;
  $("btn-redo").disabled = !S.redo.length;
}

async function undoRedo(from, to, what) {
  if (!from.length) return;
  const text = from.pop();
  to.push(S.text);
  updateUndo();
  const d = await api("/api/validate", { path: S.path, text });
  S.dirty = true;
  await setBuffer({ ...d, text });
  bufferStatus(what);
}
const undo = () => undoRedo(S.undo, S.redo, "undone");
const redo = () => undoRedo(S.redo, S.undo, "redone");

// Work not saved is confirmed away (another file, a new scenario).
function mayDiscard(what) {
  return !S.dirty || window.confirm(`${S.path || "This scenario"} has unsaved changes. Discard them and ${what}?`);
}

async function openFile(rel) {
  const d = await api("/api/file?" + new URLSearchParams({ path: rel }));
  S.dirty = false;
  S.mapKey = null;
  S.selected = null;
  S.scene = null;
  S.geo = null; // an invalid file draws nothing of the one before
  clearPreview();
  S.undo = [];
  S.redo = [];
  updateUndo();
  await setBuffer({ ...d, path: rel });
  $("file-list").value = rel;
  if (S.error) bufferStatus("opened " + rel);
  else status("opened " + rel + (S.warnings.length ? ` (${S.warnings.length} warning${S.warnings.length === 1 ? "" : "s"})` : ""), S.warnings.length ? "warn" : "good");
}

// -- view ----------------------------------------------------------------------------------------
const canvas = $("map");
const ctx = canvas.getContext("2d");

function fitView() {
  if (!S.map) return;
  fitBounds(S.map.bounds, 10);
}

function fitBounds([x0, y0, x1, y1], margin) {
  resizeCanvas();
  const s = Math.min(canvas.width / (x1 - x0 + 2 * margin), canvas.height / (y1 - y0 + 2 * margin));
  S.view.scale = s;
  S.view.ox = (x0 + x1) / 2 - canvas.width / 2 / s;
  S.view.oy = (y0 + y1) / 2 + canvas.height / 2 / s;
}

// The ego's route and every actor's path, with a margin; the whole map when nothing is placed.
function fitRoute() {
  if (!S.geo) return fitView();
  const pts = [...S.geo.ego.route, S.geo.ego.destination, [S.geo.ego.start.x, S.geo.ego.start.y]];
  for (const a of S.geo.actors) {
    const m = a.motion;
    if (m.path) pts.push(...m.path);
    else if (m.pose) pts.push([m.pose.x, m.pose.y]);
  }
  const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
  return fitBounds([Math.min(...xs), Math.min(...ys), Math.max(...xs), Math.max(...ys)], 30);
}
window.editor.fitView = () => { fitView(); draw(); };

// A scale bar (1, 2 or 5 × 10^k m, about 120 px) in the map's lower left corner.
function scaleBar() {
  const target = 120 / S.view.scale;
  const k = Math.pow(10, Math.floor(Math.log10(target)));
  const m = [5, 2, 1].map((f) => f * k).find((v) => v <= target) || k;
  const w = m * S.view.scale, x = 12, y = canvas.height - 14;
  ctx.fillStyle = "rgba(255,255,255,.8)";
  ctx.fillRect(x - 6, y - 18, w + 12, 26);
  ctx.strokeStyle = "#222";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y - 5); ctx.lineTo(x, y); ctx.lineTo(x + w, y); ctx.lineTo(x + w, y - 5);
  ctx.stroke();
  ctx.fillStyle = "#222";
  ctx.font = "11px system-ui, sans-serif";
  ctx.fillText(m >= 1000 ? `${m / 1000} km` : `${m} m`, x + 2, y - 7);
  canvas.dataset.scaleM = String(m);
  canvas.dataset.scalePx = w.toFixed(1);
}

function resizeCanvas() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
}

function toScreen(x, y) {
  return [(x - S.view.ox) * S.view.scale, (S.view.oy - y) * S.view.scale];
}
function toWorld(px, py) {
  return [px / S.view.scale + S.view.ox, S.view.oy - py / S.view.scale];
}
window.editor.toScreen = toScreen;
window.editor.toWorld = toWorld;

function polyline(pts) {
  ctx.beginPath();
  pts.forEach(([x, y], i) => {
    const [sx, sy] = toScreen(x, y);
    if (i === 0) ctx.moveTo(sx, sy); else ctx.lineTo(sx, sy);
  });
}

function box(x, y, yaw, len, wid, fill, stroke) {
  const [sx, sy] = toScreen(x, y);
  ctx.save();
  ctx.translate(sx, sy);
  ctx.rotate(-yaw);
  const l = Math.max(len * S.view.scale, 4), w = Math.max(wid * S.view.scale, 3);
  ctx.fillStyle = fill;
  ctx.fillRect(-l / 2, -w / 2, l, w);
  if (stroke) {
    ctx.strokeStyle = stroke;
    ctx.lineWidth = 1.5;
    ctx.strokeRect(-l / 2, -w / 2, l, w);
  }
  ctx.fillStyle = "rgba(0,0,0,.5)";
  ctx.fillRect(l / 2 - Math.min(l / 4, 4), -w / 2, Math.min(l / 4, 4), w);
  ctx.restore();
}

function dot(x, y, r, fill, stroke) {
  const [sx, sy] = toScreen(x, y);
  ctx.beginPath();
  ctx.arc(sx, sy, r, 0, Math.PI * 2);
  ctx.fillStyle = fill;
  ctx.fill();
  if (stroke) {
    ctx.strokeStyle = stroke;
    ctx.lineWidth = 2;
    ctx.stroke();
  }
}

function rgb(c, a) {
  return c ? `rgba(${c[0]},${c[1]},${c[2]},${a === undefined ? 1 : a})` : "#888";
}

const LIGHT = { red: "#d32f2f", yellow: "#f9a825", green: "#2e7d32", off: "#777" };

function lightColors() {
  const out = {};
  if (S.scene) for (const l of S.scene.lights) out[l.lane] = l.color;
  return out;
}

// The handles a drag can move: actors' trigger points.
function triggerHandles() {
  const out = [];
  if (!S.geo) return out;
  S.geo.actors.forEach((a, i) => {
    const t = a.motion.trigger;
    if (t && t.point) out.push({ actor: i, x: t.point[0], y: t.point[1], kind: t.kind, radius: t.radius_m });
  });
  return out;
}
window.editor.triggerHandles = triggerHandles;

function draw() {
  resizeCanvas();
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!S.map) {
    ctx.fillStyle = "#555";
    ctx.font = "15px system-ui, sans-serif";
    ctx.textAlign = "center";
    ctx.fillText("Open a scenario file (the list at the top left), or pick a category and New.", canvas.width / 2, canvas.height / 2);
    ctx.textAlign = "start";
    return;
  }
  ctx.lineCap = "round";
  ctx.lineJoin = "round";
  for (const j of S.map.junctions) {
    if (j.shape.length < 3) continue;
    polyline(j.shape);
    ctx.closePath();
    ctx.fillStyle = "#9a9a9a";
    ctx.fill();
  }
  for (const l of S.map.lanes) {
    if (l.shape.length < 2) continue;
    polyline(l.shape);
    ctx.lineWidth = Math.max(1, l.width_m * S.view.scale * 0.95);
    ctx.strokeStyle = l.function === "crossing" ? "#f0f0f0"
      : l.drivable ? (l.function === "internal" ? "#8a8a8a" : "#6e6e6e")
        : l.allow.includes("pedestrian") ? "#cfc7b8" : "#9fb39a";
    if (l.id === S.hoverLane) ctx.strokeStyle = "#ff9800";
    ctx.stroke();
  }
  // Lane direction: a thin centre line on normal drivable lanes.
  ctx.setLineDash([4, 6]);
  for (const l of S.map.lanes) {
    if (!l.drivable || l.function !== "normal") continue;
    polyline(l.shape);
    ctx.lineWidth = 1;
    ctx.strokeStyle = "rgba(255,255,255,.5)";
    ctx.stroke();
  }
  ctx.setLineDash([]);
  const colors = lightColors();
  for (const h of S.map.signal_heads) {
    dot(h.stop_line.x, h.stop_line.y, 4, LIGHT[colors[h.lane]] || "#444", "#fff");
  }
  if (S.geo) drawScenario();
  // A path being placed.
  if (S.pending.length) {
    ctx.strokeStyle = "#e06c00";
    ctx.lineWidth = 2;
    ctx.setLineDash([6, 4]);
    polyline(S.pending.map((p) => [p.x, p.y]));
    ctx.stroke();
    ctx.setLineDash([]);
    for (const p of S.pending) dot(p.x, p.y, 4, "#e06c00");
  }
  scaleBar();
}

function drawScenario() {
  const g = S.geo;
  polyline(g.ego.route);
  ctx.strokeStyle = "rgba(30,110,230,.55)";
  ctx.lineWidth = Math.max(3, 1.2 * S.view.scale);
  ctx.stroke();
  dot(g.ego.destination[0], g.ego.destination[1], 7, "#1e6ee6", "#fff");
  g.actors.forEach((a, i) => {
    const m = a.motion;
    const sel = S.selected === i;
    if (m.path) {
      polyline(m.path);
      ctx.strokeStyle = rgb(a.color, sel ? 1 : 0.7);
      ctx.lineWidth = sel ? 3 : 2;
      ctx.setLineDash([5, 4]);
      ctx.stroke();
      ctx.setLineDash([]);
    }
  });
  for (const h of triggerHandles()) {
    if (h.radius) {
      const [sx, sy] = toScreen(h.x, h.y);
      ctx.beginPath();
      ctx.arc(sx, sy, h.radius * S.view.scale, 0, Math.PI * 2);
      ctx.strokeStyle = "rgba(224,108,0,.6)";
      ctx.lineWidth = 1;
      ctx.stroke();
    }
    dot(h.x, h.y, 6, "#fff", "#e06c00");
  }
  const sc = S.scene;
  if (sc) {
    for (const a of sc.actors) {
      const spec = a.traffic ? null : g.actors[a.id - 1];
      box(a.x, a.y, a.yaw, a.length_m, a.width_m, spec ? rgb(spec.color) : "#b0b0b0",
        S.selected === a.id - 1 ? "#e06c00" : "#222");
    }
    box(sc.ego.x, sc.ego.y, sc.ego.yaw, sc.ego.length_m, sc.ego.width_m, "#1e6ee6", "#fff");
  } else {
    g.actors.forEach((a) => {
      const p = a.motion.pose || a.motion.start;
      box(p.x, p.y, p.yaw, a.length_m, a.width_m, rgb(a.color), "#222");
    });
    box(g.ego.start.x, g.ego.start.y, g.ego.start.yaw, g.ego.length_m, g.ego.width_m, "#1e6ee6", "#fff");
  }
}

// -- map interaction ---------------------------------------------------------------------------
const HELP = {
  select: "Drag the map to pan, wheel to zoom; drag a trigger point (white ring) to move it; click an actor path to select it.",
  "ego-start": "Click a drivable lane: the ego starts there.",
  "ego-dest": "Click a drivable lane: the ego's destination.",
  actor: "Click places (waypoints) or lanes (route) in order; double-click or Enter finishes, Esc cancels.",
  obstacle: "Click a lane: the obstacle stands there.",
};

function setMode(mode) {
  S.mode = mode;
  S.pick = null;
  S.pending = [];
  for (const b of document.querySelectorAll("#tools button[data-mode]")) {
    b.classList.toggle("active", b.dataset.mode === mode);
  }
  $("mode-help").textContent = HELP[mode] || "";
  draw();
}

function vclassFor(kind) {
  return K().vclass_of[kind] ?? null;
}

// The tool bar's kind pickers: moving kinds for actors, every kind for obstacles (moving ones standing still).
function fillKindPickers() {
  const opts = (kinds, label) => kinds.map((k) => h("option", { value: k }, label(k)));
  $("actor-kind").replaceChildren(...opts(K().actor_kinds, (k) => k));
  $("obstacle-kind").replaceChildren(...opts(K().obstacle_kinds, (k) => (K().actor_kinds.includes(k) ? `${k} (static)` : k)));
}

async function snap(x, y, vclass, internal) {
  const spec = (S.doc && S.doc.map) || (S.info && S.info.default_map);
  return api("/api/snap", { path: S.path || "new.toml", map: spec, x, y, vclass, internal: !!internal, max_dist_m: 8 });
}

function eventPos(ev) {
  const r = canvas.getBoundingClientRect();
  return [ev.clientX - r.left, ev.clientY - r.top];
}

let drag = null;
canvas.addEventListener("mousedown", (ev) => {
  const [px, py] = eventPos(ev);
  if (S.mode === "select") {
    for (const h of triggerHandles()) {
      const [sx, sy] = toScreen(h.x, h.y);
      if (Math.hypot(sx - px, sy - py) <= 9) {
        drag = { handle: h, px, py };
        return;
      }
    }
    drag = { pan: true, px, py, ox: S.view.ox, oy: S.view.oy, moved: false };
  }
});

canvas.addEventListener("mousemove", (ev) => {
  const [px, py] = eventPos(ev);
  if (drag && drag.pan) {
    S.view.ox = drag.ox - (px - drag.px) / S.view.scale;
    S.view.oy = drag.oy + (py - drag.py) / S.view.scale;
    drag.moved = drag.moved || Math.hypot(px - drag.px, py - drag.py) > 3;
    draw();
    return;
  }
  if (drag && drag.handle) {
    const [x, y] = toWorld(px, py);
    drag.handle.x = x;
    drag.handle.y = y;
    draw();
    dot(x, y, 7, "#e06c00", "#fff");
    return;
  }
  hover(px, py);
});

let hoverTimer = null;
function hover(px, py) {
  clearTimeout(hoverTimer);
  hoverTimer = setTimeout(async () => {
    if (!S.map) return;
    const [x, y] = toWorld(px, py);
    const d = await snap(x, y, null, true).catch(() => null);
    const lane = d && d.lane;
    $("hover").textContent = lane ? `lane ${lane}  s = ${d.s.toFixed(1)} m` : `x = ${x.toFixed(1)}, y = ${y.toFixed(1)}`;
    if (lane !== S.hoverLane) {
      S.hoverLane = lane;
      draw();
    }
  }, 60);
}

window.addEventListener("mouseup", guard(async (ev) => {
  const d = drag;
  drag = null;
  if (!d) return;
  if (d.handle) {
    const [px, py] = eventPos(ev);
    const [x, y] = toWorld(px, py);
    const hit = await snap(x, y, EGO_VCLASS(), false);
    const i = d.handle.actor;
    const of = hit.lane ? { lane: hit.lane, s: hit.s } : [round(x), round(y)];
    await edit([{ path: ["actors", i, "start", "of"], value: of, floats: true }]);
    return;
  }
  if (d.pan && !d.moved && ev.target === canvas) {
    const [px, py] = eventPos(ev);
    selectAt(px, py);
  }
}));

function selectAt(px, py) {
  if (!S.geo) return;
  let best = null;
  S.geo.actors.forEach((a, i) => {
    const pts = a.motion.path || [[(a.motion.pose || a.motion.start).x, (a.motion.pose || a.motion.start).y]];
    for (const [x, y] of pts) {
      const [sx, sy] = toScreen(x, y);
      const dd = Math.hypot(sx - px, sy - py);
      if (dd < 12 && (!best || dd < best.d)) best = { i, d: dd };
    }
  });
  S.selected = best ? best.i : null;
  renderForm();
  draw();
  const fs = best && document.querySelector(`fieldset[data-actor="${best.i}"]`);
  if (fs) fs.scrollIntoView({ block: "nearest" });
}

canvas.addEventListener("wheel", (ev) => {
  ev.preventDefault();
  const [px, py] = eventPos(ev);
  const [wx, wy] = toWorld(px, py);
  S.view.scale *= ev.deltaY < 0 ? 1.2 : 1 / 1.2;
  S.view.ox = wx - px / S.view.scale;
  S.view.oy = wy + py / S.view.scale;
  draw();
}, { passive: false });

function round(v) {
  return Math.round(v * 10) / 10;
}

canvas.addEventListener("click", guard(async (ev) => {
  if (S.mode === "select") return;
  const [px, py] = eventPos(ev);
  const [x, y] = toWorld(px, py);
  if (S.mode === "pick" && S.pick) {
    const p = S.pick;
    const hit = await snap(x, y, p.vclass, false);
    if (!hit.lane && p.vclass !== null) return status("no lane there" + (p.vclass ? ` open to ${p.vclass}` : ""), "bad");
    setMode("select");
    await p.apply(hit, x, y);
  } else if (S.mode === "ego-start" || S.mode === "ego-dest") {
    const hit = await snap(x, y, EGO_VCLASS(), false);
    if (!hit.lane) return status("no drivable lane there", "bad");
    const key = S.mode === "ego-start" ? "start" : "destination";
    await edit([{ path: ["ego", key], value: { lane: hit.lane, s: hit.s }, floats: true }]);
  } else if (S.mode === "obstacle") {
    const hit = await snap(x, y, null, false);
    if (!hit.lane) return status("no lane there", "bad");
    await edit([{ path: ["obstacles"], append: { kind: $("obstacle-kind").value, at: { lane: hit.lane, s: hit.s } }, floats: true }]);
  } else if (S.mode === "actor") {
    const kind = $("actor-kind").value;
    const hit = await snap(x, y, vclassFor(kind), false);
    if (!hit.lane) return status("no lane open to a " + kind + " there", "bad");
    S.pending.push({ x, y, lane: hit.lane, s: hit.s });
    draw();
  }
}));

canvas.addEventListener("dblclick", guard(() => finishActor()));
window.addEventListener("keydown", (ev) => {
  if (ev.target.tagName === "INPUT" || ev.target.tagName === "TEXTAREA") return;
  if (ev.key === "Escape" && S.mode === "pick") return setMode("select");
  if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === "z") {
    ev.preventDefault();
    guard(ev.shiftKey ? redo : undo)();
    return;
  }
  if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === "y") {
    ev.preventDefault();
    guard(redo)();
    return;
  }
  if (ev.key === "Enter") guard(finishActor)();
  if (ev.key === "Escape") setMode("select");
});

async function finishActor() {
  if (S.mode !== "actor") return;
  const pts = S.pending;
  if (pts.length < 2) return status("an actor needs at least two places", "bad");
  const kind = $("actor-kind").value;
  const n = (S.doc && S.doc.actors ? S.doc.actors.length : 0);
  const actor = { name: `${kind}_${n + 1}`, kind };
  if ($("actor-path").value === "route") {
    const lanes = [];
    for (const p of pts) if (lanes[lanes.length - 1] !== p.lane) lanes.push(p.lane);
    actor.route = { lanes, start_s: pts[0].s };
  } else {
    actor.waypoints = pts.map((p) => ({ lane: p.lane, s: p.s }));
  }
  S.pending = [];
  await edit([{ path: ["actors"], append: actor, floats: true }]);
  S.selected = n;
  setMode("select");
  renderForm();
}

// -- forms -------------------------------------------------------------------------------------
// Every input is bound to a key path of the TOML (`data-path`, the validator's field name with
// indices as `.i`), so an edit changes that key only and the validator's message lands on it.
function h(tag, attrs, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null) el.setAttribute(k, v);
  }
  for (const c of children) if (c !== null && c !== undefined && c !== false) el.append(c);
  return el;
}

function get(obj, path) {
  let o = obj;
  for (const k of path) {
    if (o === null || o === undefined) return undefined;
    o = o[k];
  }
  return o;
}

function isObj(v) {
  return v !== null && typeof v === "object" && !Array.isArray(v);
}

function safeEdit(edits) {
  return edit(edits).catch((e) => status(e.message, "bad"));
}

// The value typed into an input of `kind`; `undefined` when it is not one (status says why).
function parseValue(raw, kind, path) {
  if (kind === "number" || kind === "int") {
    const v = Number(raw);
    return Number.isFinite(v) ? v : raw; // the validator says what is wrong
  }
  if (kind === "numkw" || kind === "laneindex") {
    // A number or a keyword (`depart_lane = 1` or `"best"`).
    const v = Number(raw);
    return raw !== "" && Number.isFinite(v) ? v : raw;
  }
  if (kind === "json") {
    try {
      return JSON.parse(raw);
    } catch (e) {
      status(`${path.join(".")}: not JSON (${e.message})`, "bad");
      return undefined;
    }
  }
  return raw;
}

// One control bound to a key path. kind: "number", "int", "numkw" (number or keyword), "text",
// "json", "lane", "edge", "laneindex" (with a pick-on-the-map button) or a list of choices. An emptied input deletes
// the key (its default applies).
function control(path, kind, opts) {
  opts = opts || {};
  const value = get(S.doc, path);
  let input;
  if (Array.isArray(kind)) {
    const choices = value !== undefined && !kind.includes(String(value)) ? [...kind, String(value)] : kind;
    input = h("select", {}, ...choices.map((c) => h("option", { value: c }, c === "" ? "(default)" : c)));
    input.value = value === undefined ? "" : String(value);
  } else {
    input = h("input", { type: "text", placeholder: opts.placeholder, list: opts.list });
    input.value = value === undefined ? "" : kind === "json" ? JSON.stringify(value) : String(value);
    if (kind === "number" || kind === "int") input.inputMode = "decimal";
  }
  input.dataset.path = path.join(".");
  input.addEventListener("change", async () => {
    const raw = input.value.trim();
    if (raw === "") return safeEdit([{ path, delete: true }]);
    const v = parseValue(raw, kind, path);
    if (v === undefined) return;
    await safeEdit([{ path, value: v, floats: kind === "number" }]);
  });
  if (kind !== "lane" && kind !== "edge" && kind !== "laneindex") return input;
  const pickBtn = h("button", {
    class: "pick", type: "button", title: `pick the ${kind === "laneindex" ? "lane" : kind} on the map`,
    onclick: () => pick(`${path.join(".")}: click a lane`, opts.vclass, (hit) => {
      const lane = S.map.lanes.find((x) => x.id === hit.lane);
      const id = kind === "lane" ? hit.lane : kind === "edge" ? laneEdge(hit.lane) : lane && lane.index;
      return safeEdit([{ path, value: id }]);
    }),
  }, "map");
  return h("span", { class: "with-pick" }, input, pickBtn);
}

// A labelled control: a form line, or (`cell`) a compact cell of a row.
function field(label, path, kind, opts) {
  const cls = opts && opts.cell ? "field cell" : "field";
  return h("div", { class: cls, "data-field": path.join(".") }, h("label", {}, label), control(path, kind, opts));
}

function cell(label, path, kind, opts) {
  return field(label, path, kind, { ...(opts || {}), cell: true });
}

// A flag that defaults to false as a checkbox: ticked writes `true`, unticked removes the key.
function boolField(label, path) {
  const input = h("input", { type: "checkbox" });
  input.checked = get(S.doc, path) === true;
  input.dataset.path = path.join(".");
  input.addEventListener("change", () => safeEdit([input.checked ? { path, value: true } : { path, delete: true }]));
  return h("div", { class: "field cell", "data-field": path.join(".") }, h("label", {}, label), input);
}

// `color = [r, g, b]` as a colour picker (absent: the default by kind / palette; × clears it).
function colorField(label, path) {
  const v = get(S.doc, path);
  const hex = (c) => "#" + c.map((x) => Math.max(0, Math.min(255, Number(x) | 0)).toString(16).padStart(2, "0")).join("");
  const input = h("input", { type: "color", value: Array.isArray(v) && v.length === 3 ? hex(v) : "#808080" });
  input.dataset.path = path.join(".");
  input.addEventListener("change", () => {
    const x = input.value;
    const rgb = [1, 3, 5].map((i) => parseInt(x.slice(i, i + 2), 16));
    return safeEdit([{ path, value: rgb }]);
  });
  const clear = v === undefined ? h("span", { class: "help" }, "default")
    : h("button", { type: "button", class: "del", title: "back to the default colour", onclick: () => safeEdit([{ path, delete: true }]) }, "×");
  return h("div", { class: "field cell", "data-field": path.join(".") }, h("label", {}, label), h("span", { class: "with-pick" }, input, clear));
}

function laneEdge(lane) {
  const l = S.map && S.map.lanes.find((x) => x.id === lane);
  return l ? l.edge : lane;
}

// Map picking: the next click on the map snaps to a lane (open to `vclass`) and calls `apply`.
function pick(help, vclass, apply) {
  setMode("pick");
  S.pick = { vclass: vclass === undefined ? EGO_VCLASS() : vclass, apply };
  $("mode-help").textContent = help + " (Esc cancels)";
  status(help);
  canvas.scrollIntoView({ block: "nearest" });
}

// The keys a form shows of a table; any other key is edited as JSON (the fallback).
function extras(obj, known, prefix, cellMode) {
  if (!isObj(obj)) return [];
  return Object.keys(obj).filter((k) => !known.includes(k))
    .map((k) => field(`${k} (JSON)`, [...prefix, k], "json", { cell: cellMode }));
}

// A list of rows (an array of tables, inline or `[[...]]`) with add and remove. `cells(p, item,
// i)` gives a row's cells; `fresh()` a new row.
function rows(title, path, cells, fresh, opts) {
  opts = opts || {};
  const items = get(S.doc, path);
  const box = h("div", { class: "rows", "data-rows": path.join(".") });
  const add = h("button", {
    type: "button", class: "add",
    onclick: () => {
      const v = fresh();
      if (v === undefined) return undefined;
      // A new inline array is written as a value; `[[...]]` tables and existing arrays get a row.
      const floats = !!opts.floats;
      if (Array.isArray(items) || !opts.inline) return safeEdit([{ path, append: v, floats }]);
      return safeEdit([{ path, value: [v], floats }]);
    },
  }, opts.addLabel || "+ add");
  box.append(h("div", { class: "rows-head" }, h("strong", {}, title), add));
  (Array.isArray(items) ? items : []).forEach((item, i) => {
    const p = [...path, i];
    const row = h("div", { class: "rowcard", "data-row": p.join(".") },
      h("span", { class: "idx" }, `${i}`), ...cells(p, item, i),
      // The last row of an inline array takes the key with it (`lane_changes = []` says nothing).
      h("button", {
        type: "button", class: "del", title: `remove ${path.join(".")}[${i}]`,
        onclick: () => safeEdit([{ path: opts.inline && items.length === 1 ? path : p, delete: true }]),
      }, "×"));
    box.append(row);
  });
  if (items !== undefined && !Array.isArray(items)) box.append(field(`${path[path.length - 1]} (JSON)`, path, "json"));
  return box;
}

// A list of ids (lanes or edges) with one input per entry, remove, and add by picking on the map.
function idList(label, path, kind, vclass) {
  const items = get(S.doc, path);
  const box = h("div", { class: "field idlist", "data-field": path.join(".") }, h("label", {}, label));
  const line = h("div", { class: "ids" });
  const holder = h("input", { type: "hidden" });
  holder.dataset.path = path.join(".");
  line.append(holder);
  (Array.isArray(items) ? items : []).forEach((_, i) => {
    const p = [...path, i];
    line.append(h("span", { class: "id field cell", "data-field": p.join(".") }, control(p, "text"),
      h("button", { type: "button", class: "del", title: "remove", onclick: () => safeEdit([{ path: p, delete: true }]) }, "×")));
  });
  line.append(h("button", {
    type: "button", class: "pick", title: `add a ${kind} picked on the map`,
    onclick: () => pick(`${path.join(".")}: click a lane to add its ${kind}`, vclass, (hit) => {
      const id = kind === "lane" ? hit.lane : laneEdge(hit.lane);
      return safeEdit([Array.isArray(items) ? { path, append: id } : { path, value: [id] }]);
    }),
  }, `+ ${kind} (map)`));
  box.append(line);
  return box;
}

// A place: `{ lane, s, offset_m }`, `{ x, y }`, `[x, y]` (`pair`) or "actor_self" (`self`).
function placeKind(v) {
  if (typeof v === "string") return "self";
  if (Array.isArray(v)) return "pair";
  if (isObj(v) && !("lane" in v) && ("x" in v || "y" in v)) return "xy";
  return "lane";
}

function placeField(label, path, opts) {
  opts = opts || {};
  const v = get(S.doc, path);
  const kind = v === undefined && opts.self ? "self" : placeKind(v);
  const kinds = [["lane", "lane + s"], ["xy", "x, y"]];
  if (opts.pair) kinds.push(["pair", "[x, y]"]);
  if (opts.self) kinds.push(["self", "actor_self"]);
  const sel = h("select", {}, ...kinds.map(([k, t]) => h("option", { value: k }, t)));
  sel.value = kind;
  sel.dataset.path = path.join(".");
  const here = () => (opts.point ? opts.point() : null) || [0, 0];
  sel.addEventListener("change", async () => {
    const k = sel.value;
    const [x, y] = here().map(round);
    let nv;
    if (k === "self") nv = "actor_self";
    else if (k === "pair") nv = [x, y];
    else if (k === "xy") nv = { x, y };
    else {
      const hit = await snap(x, y, opts.vclass === undefined ? EGO_VCLASS() : opts.vclass, false).catch(() => null);
      nv = hit && hit.lane ? { lane: hit.lane, s: hit.s } : { lane: "", s: 0.0 };
    }
    await safeEdit([{ path, value: nv, floats: true }]);
  });
  const pickBtn = h("button", {
    type: "button", class: "pick", title: "place it by clicking the map",
    onclick: () => pick(`${path.join(".")}: click the place`, opts.vclass, (hit, x, y) => {
      let nv;
      if (kind === "pair") nv = [round(x), round(y)];
      else if (kind === "xy") nv = { ...(isObj(v) ? v : {}), x: round(x), y: round(y) };
      else {
        if (!hit.lane) return status("no lane there", "bad");
        nv = { lane: hit.lane, s: hit.s };
        if (isObj(v) && v.offset_m !== undefined) nv.offset_m = v.offset_m;
        if (isObj(v) && v.yaw_deg !== undefined) nv.yaw_deg = v.yaw_deg;
        if (opts.keep) for (const key of opts.keep) if (isObj(v) && v[key] !== undefined) nv[key] = v[key];
      }
      return safeEdit([{ path, value: nv, floats: true }]);
    }),
  }, "map");
  const head = h("div", { class: "field place-head", "data-field": path.join(".") }, h("label", {}, label),
    h("span", { class: "with-pick" }, sel, pickBtn));
  const cells = h("div", { class: "cells" });
  if (kind === "lane") {
    cells.append(cell("lane", [...path, "lane"], "lane", { vclass: opts.vclass }), cell("s", [...path, "s"], "number"),
      cell("offset_m", [...path, "offset_m"], "number"));
  } else if (kind === "xy") {
    cells.append(cell("x", [...path, "x"], "number"), cell("y", [...path, "y"], "number"));
  } else if (kind === "pair") {
    cells.append(cell("x", [...path, 0], "number"), cell("y", [...path, 1], "number"));
  }
  if (isObj(v) && (kind === "lane" || kind === "xy")) {
    cells.append(cell("yaw_deg", [...path, "yaw_deg"], "number"));
    for (const k of opts.more || []) cells.append(cell(k, [...path, k], "number"));
    cells.append(...extras(v, ["lane", "s", "offset_m", "x", "y", "yaw_deg", ...(opts.more || [])], path, true));
  }
  return h("div", { class: "place" }, head, cells);
}

// The keys that pick a start trigger's / a brake's form (from the simulator, see FACTS).
const TRIGGERS = () => K().start_triggers;
const BRAKES = () => ["", ...K().brake_triggers];
const BRAKE_KEYS = ["decel_mps2", "to_speed_mps", "hold_s"];

function triggerKind(t) {
  if (!t) return "time_s";
  return TRIGGERS().find((k) => k in t) || "time_s";
}

function defaultPlace() {
  const st = get(S.doc, ["ego", "start"]);
  if (st && st.lane) return { lane: st.lane, s: round((st.s || 0) + 40) };
  return "actor_self";
}

function actorNames(except) {
  return (S.doc.actors || []).map((a, j) => [j, a.name || `actors[${j}]`]).filter(([j]) => j !== except).map(([, n]) => n);
}

// The world point a trigger's `of` resolved to (for switching its form to x, y).
function triggerPoint(i) {
  const g = S.geo && S.geo.actors[i];
  const t = g && g.motion.trigger;
  return t && t.point ? t.point : null;
}

// A start trigger or brake: the kind, then that kind's fields.
function triggerFields(i, prefix, t, choices) {
  const isBrake = prefix[prefix.length - 1] === "brake";
  const box = h("div", { class: "trigger" });
  const kind = isBrake ? (BRAKES().find((k) => k && t && k in t) || "") : triggerKind(t);
  const sel = h("select", {}, ...choices.map((c) => h("option", { value: c }, c || "(none)")));
  sel.value = kind;
  sel.dataset.path = prefix.join(".") + ".kind";
  sel.addEventListener("change", async () => {
    const k = sel.value;
    const keep = {};
    if (isBrake && t) for (const key of BRAKE_KEYS) if (t[key] !== undefined) keep[key] = t[key];
    if (k === "") return safeEdit([{ path: prefix, delete: true }]);
    const first = actorNames(i)[0];
    const v = {
      time_s: { time_s: 0.0 }, ego_within_m: { ego_within_m: 20.0 }, ego_eta_s: { ego_eta_s: 3.0, of: defaultPlace() },
      after: { after: first || "", delay_s: 0.0 }, at_s: { at_s: 10.0 }, after_s: { after_s: 2.0 },
      ego_gap_m: { ego_gap_m: 15.0 }, ego_gap_s: { ego_gap_s: 1.5 }, ego_ttc_s: { ego_ttc_s: 3.0 },
      gap_held_s: { gap_held_s: 3.0 },
    }[k];
    if (isBrake && keep.decel_mps2 === undefined) keep.decel_mps2 = 6.0;
    await safeEdit([{ path: prefix, value: { ...v, ...keep }, floats: true }]);
  });
  box.append(h("div", { class: "field", "data-field": prefix.join(".") }, h("label", {}, isBrake ? "brake when" : "start when"), sel));
  if (!kind) return box;
  const cells = h("div", { class: "cells" });
  if (kind === "after") {
    const names = actorNames(i);
    cells.append(cell("after (actor)", [...prefix, "after"], names.length ? names : "text"),
      cell("delay_s", [...prefix, "delay_s"], "number"), cell("event", [...prefix, "event"], ["", ...K().chain_events]));
  } else {
    cells.append(cell(kind, [...prefix, kind], "number"));
  }
  if (isBrake) for (const key of BRAKE_KEYS) cells.append(cell(key, [...prefix, key], "number"));
  box.append(cells);
  const ofRule = K().of_rules.find((r) => r.table === (isBrake ? "brake" : "start") && r.key === kind);
  if (ofRule) {
    box.append(placeField("of", [...prefix, "of"], { pair: true, self: ofRule.actor_self, point: () => triggerPoint(i) }));
  }
  const known = [...TRIGGERS(), ...BRAKES().filter(Boolean), "of", "delay_s", "event", ...BRAKE_KEYS];
  if (isObj(t)) box.append(...extras(t, known, prefix));
  return box;
}

function paceFields(p, pace) {
  const box = h("div", { class: "pace" });
  if (!isObj(pace)) {
    box.append(h("div", { class: "row" }, h("span", { class: "help" }, "pace: none"),
      h("button", { type: "button", onclick: () => safeEdit([{ path: p, value: { gap_s: 1.5, gap_m: 2.0, min_speed_mps: 1.0 }, floats: true }]) }, "+ gap pace"),
      h("button", { type: "button", onclick: () => safeEdit([{ path: p, value: { meet: defaultPlace() === "actor_self" ? [0.0, 0.0] : defaultPlace(), offset_s: 0.0 }, floats: true }]) }, "+ meet pace")));
    return box;
  }
  const meet = "meet" in pace;
  const cells = h("div", { class: "cells" });
  if (!meet) cells.append(cell("gap_m", [...p, "gap_m"], "number"), cell("gap_s", [...p, "gap_s"], "number"));
  else cells.append(cell("offset_s", [...p, "offset_s"], "number"));
  cells.append(cell("min_speed_mps", [...p, "min_speed_mps"], "number"), cell("max_speed_mps", [...p, "max_speed_mps"], "number"),
    cell("until_s", [...p, "until_s"], "number"));
  box.append(h("div", { class: "rows-head", "data-field": p.join(".") }, h("strong", {}, meet ? "pace (meet)" : "pace (gap)"),
    h("button", { type: "button", class: "del", title: "remove pace", onclick: () => safeEdit([{ path: p, delete: true }]) }, "×")), cells);
  if (meet) box.append(placeField("meet", [...p, "meet"], { pair: true }));
  box.append(...extras(pace, ["gap_m", "gap_s", "min_speed_mps", "max_speed_mps", "until_s", "meet", "offset_s"], p));
  return box;
}

function routeFields(p, route, vclass) {
  const box = h("div", { class: "route" });
  const byEdges = isObj(route) && "edges" in route;
  box.append(h("div", { class: "rows-head" }, h("strong", {}, byEdges ? "route (edges)" : "route (lanes)")));
  if (byEdges) box.append(idList("edges", [...p, "edges"], "edge", vclass), field("start_lane", [...p, "start_lane"], "lane", { vclass }));
  else box.append(idList("lanes", [...p, "lanes"], "lane", vclass));
  box.append(h("div", { class: "cells" }, cell("start_s", [...p, "start_s"], "number"), cell("end_s", [...p, "end_s"], "number"),
    cell("offset_m", [...p, "offset_m"], "number")));
  box.append(...extras(route, ["edges", "lanes", "start_lane", "start_s", "end_s", "offset_m"], p));
  return box;
}

function actorForm(a, i) {
  const fs = h("fieldset", { "data-actor": i, class: S.selected === i ? "selected" : "" },
    h("legend", {}, `actors[${i}] ${a.name || ""}`));
  const p = ["actors", i];
  const vclass = vclassFor(a.kind);
  fs.append(field("name", [...p, "name"], "text"),
    field("kind", [...p, "kind"], K().actor_kinds),
    h("div", { class: "cells" }, cell("speed_mps", [...p, "speed_mps"], "number"), cell("accel_mps2", [...p, "accel_mps2"], "number"),
      cell("initial_speed_mps", [...p, "initial_speed_mps"], "number"), cell("at_end", [...p, "at_end"], ["", ...K().at_end]),
      cell("length_m", [...p, "length_m"], "number"), cell("width_m", [...p, "width_m"], "number"), cell("height_m", [...p, "height_m"], "number"),
      colorField("color", [...p, "color"]), boolField("emergency", [...p, "emergency"])));
  if ("behavior" in a) fs.append(field("behavior", [...p, "behavior"], K().behaviors));
  if ("at" in a) fs.append(placeField("at", [...p, "at"], { vclass }));
  if ("waypoints" in a) {
    fs.append(rows("waypoints", [...p, "waypoints"], (wp) => [placeField("", wp, { vclass, more: ["speed_mps"] })],
      () => {
        const last = (a.waypoints || [])[a.waypoints.length - 1];
        return isObj(last) && last.lane ? { lane: last.lane, s: round((last.s || 0) + 10) } : { x: 0.0, y: 0.0 };
      }, { inline: true, floats: true, addLabel: "+ waypoint" }));
  }
  if ("route" in a) fs.append(routeFields([...p, "route"], a.route, vclass));
  fs.append(triggerFields(i, [...p, "start"], a.start, TRIGGERS()));
  fs.append(triggerFields(i, [...p, "brake"], a.brake, BRAKES()));
  fs.append(paceFields([...p, "pace"], a.pace));
  if ("route" in a || "lane_changes" in a) {
    fs.append(rows("lane_changes", [...p, "lane_changes"], (lc) => [cell("at_s", [...lc, "at_s"], "number"),
      cell("to_lane", [...lc, "to_lane"], "lane", { vclass }), cell("length_m", [...lc, "length_m"], "number")],
    () => ({ at_s: 20.0, to_lane: "", length_m: 20.0 }), { inline: true, floats: true, addLabel: "+ lane change" }));
  }
  fs.append(...extras(a, K().actor_keys, p));
  fs.append(h("button", { type: "button", onclick: () => safeEdit([{ path: ["actors", i], delete: true }]) }, "Delete actor"));
  return fs;
}

function renderForm() {
  const form = $("form");
  form.replaceChildren();
  if (!S.doc) return;
  const gen = h("fieldset", {}, h("legend", {}, "Scenario"));
  gen.append(field("id", ["id"], "text"), field("name", ["name"], "text"),
    field("category", ["category"], (S.info && S.info.categories) || []),
    field("description", ["description"], "text"), field("map", ["map"], "text"),
    field("reference_duration_s", ["reference_duration_s"], "number"), field("duration_s", ["duration_s"], "number"),
    field("seed", ["seed"], "int"));
  gen.append(...extras(S.doc, ["version", "id", "name", "category", "description", "map", "reference_duration_s", "duration_s",
    "seed", "ego", "actors", "obstacles", "lights", "traffic", "signs", "conditions"], []));
  const ego = h("fieldset", {}, h("legend", {}, "Ego"));
  const egoPoint = (key) => () => {
    if (!S.geo) return null;
    return key === "start" ? [S.geo.ego.start.x, S.geo.ego.start.y] : S.geo.ego.destination;
  };
  ego.append(placeField("start", ["ego", "start"], { point: egoPoint("start") }),
    placeField("destination", ["ego", "destination"], { point: egoPoint("destination") }),
    idList("route_edges", ["ego", "route_edges"], "edge", EGO_VCLASS()), field("speed_mps", ["ego", "speed_mps"], "number"));
  ego.append(h("div", { class: "cells" }, colorField("color", ["ego", "color"])));
  ego.append(...extras(S.doc.ego, ["start", "destination", "route_edges", "speed_mps", "color"], ["ego"]));
  // Light and weather: pictures only (docs/rendering.md#conditions); the preview draws them.
  const cond = h("fieldset", {}, h("legend", {}, "[conditions]"));
  cond.append(h("div", { class: "cells" },
    cell("time_of_day", ["conditions", "time_of_day"], ["", ...K().times_of_day]),
    cell("weather", ["conditions", "weather"], ["", ...K().weathers])),
  ...(isObj(S.doc.conditions) ? extras(S.doc.conditions, ["time_of_day", "weather"], ["conditions"], true) : []));
  form.append(gen, ego, cond);
  (S.doc.actors || []).forEach((a, i) => form.append(actorForm(a, i)));
  (S.doc.obstacles || []).forEach((o, i) => {
    const fs = h("fieldset", {}, h("legend", {}, `obstacles[${i}] ${o.name || ""}`));
    const p = ["obstacles", i];
    fs.append(field("kind", [...p, "kind"], K().obstacle_kinds),
      placeField("at", [...p, "at"], { vclass: null }), field("name", [...p, "name"], "text"),
      h("div", { class: "cells" }, cell("length_m", [...p, "length_m"], "number"), cell("width_m", [...p, "width_m"], "number"),
        cell("height_m", [...p, "height_m"], "number"), colorField("color", [...p, "color"]),
        boolField("emergency", [...p, "emergency"])),
      ...extras(o, ["kind", "at", "name", "length_m", "width_m", "height_m", "color", "emergency"], p),
      h("button", { type: "button", onclick: () => safeEdit([{ path: ["obstacles", i], delete: true }]) }, "Delete obstacle"));
    form.append(fs);
  });
  const signs = h("fieldset", {}, h("legend", {}, "[[signs]]"));
  signs.append(rows("signs", ["signs"], (p) => [cell("kind", [...p, "kind"], K().sign_kinds),
    placeField("at", [...p, "at"], {}), ...extras(get(S.doc, p), ["kind", "at"], p, true)],
  () => ({ kind: K().sign_kinds[0], at: defaultPlace() === "actor_self" ? { x: 0.0, y: 0.0 } : defaultPlace() }), { floats: true, addLabel: "+ sign" }));
  form.append(signs);
  renderLights();
}

// -- lights and traffic ------------------------------------------------------------------------
const LINK = { r: LIGHT.red, s: LIGHT.red, y: LIGHT.yellow, g: LIGHT.green, G: LIGHT.green, u: LIGHT.yellow, o: LIGHT.off, O: LIGHT.off };

function timeMax() {
  return Number($("time").max) || 60;
}

// A light's program over episode time: one column per phase as the world runs it (its schedule
// from `_core.scenario_geometry`), one row per link index, and a "now" marker at the slider.
function lightTimeline(prog) {
  const wrap = h("div", { class: "timeline-strip", "data-tls": prog.tl_id });
  const c = h("canvas", { width: 400, height: 36 });
  wrap.append(c, h("i", { class: "now", "data-tls": prog.tl_id }), h("div", { class: "help now-text", "data-tls": prog.tl_id }));
  const g = c.getContext("2d");
  const tmax = timeMax();
  const links = Math.max(1, ...prog.phases.map((p) => p.state.length));
  const rowH = c.height / links;
  for (const [t0, t1, i] of prog.schedule) {
    const x0 = (t0 / tmax) * c.width, x1 = (Math.min(t1, tmax) / tmax) * c.width;
    const st = prog.phases[i].state;
    for (let k = 0; k < links; k++) {
      g.fillStyle = LINK[st[k]] || LIGHT.off;
      g.fillRect(x0, k * rowH, Math.max(1, x1 - x0), Math.max(1, rowH - (links > 8 ? 0 : 1)));
    }
    g.fillStyle = "rgba(0,0,0,.35)";
    g.fillRect(x0, 0, 1, c.height);
  }
  c.title = `${prog.tl_id}: phases over t = 0…${tmax} s (rows: link indices)`;
  return wrap;
}

// The phase at time t of a light's schedule (a lookup in the world's schedule).
function phaseAt(prog, t) {
  for (const [t0, t1, i] of prog.schedule) if (t >= t0 && t < t1) return { i, left: t1 - t };
  return null;
}

// Moves the "now" markers to the slider's time (the world's colours at t when the scene is in).
function updateNow() {
  const t = Number($("time").value);
  const tmax = timeMax();
  for (const el of document.querySelectorAll(".timeline-strip .now")) {
    el.style.left = `${(100 * Math.min(t, tmax)) / tmax}%`;
    el.dataset.time = String(t);
  }
  if (!S.geo || !S.geo.lights) return;
  for (const prog of S.geo.lights) {
    const el = document.querySelector(`.now-text[data-tls="${CSS.escape(prog.tl_id)}"]`);
    if (!el) continue;
    const ph = phaseAt(prog, t);
    let msg = ph ? `t = ${t.toFixed(2)} s: phase ${ph.i} (${prog.phases[ph.i].state}), ${ph.left.toFixed(1)} s left` : "";
    if (S.scene && Math.abs(S.scene.time_s - t) < 0.3) {
      const heads = S.scene.lights.filter((l) => l.tl_id === prog.tl_id).map((l) => `${l.lane} ${l.color}`);
      if (heads.length) msg += `; world: ${heads.join(", ")}`;
    }
    el.textContent = msg;
  }
}

function lightForm(prog, idx) {
  const box = h("div", { class: "light", "data-light": prog.id });
  const world = S.geo && S.geo.lights ? S.geo.lights.find((l) => l.tl_id === prog.id) : null;
  const cycle = world ? world.cycle_s : prog.cycle_s;
  box.append(h("div", { class: "rows-head" }, h("strong", {}, prog.id),
    h("span", {}, idx >= 0 ? `override: cycle ${cycle.toFixed(0)} s, offset ${world ? world.offset_s.toFixed(1) : "?"} s`
      : `map program: cycle ${prog.cycle_s.toFixed(0)} s, offset ${prog.offset_s} s`)));
  if (world) box.append(lightTimeline(world));
  if (idx < 0) {
    box.append(h("button", { type: "button", onclick: () => safeEdit([{ path: ["lights"], append: { tls: prog.id, offset_s: 0.0 }, floats: true }]) },
      `Override ${prog.id}`));
    return box;
  }
  const p = ["lights", idx];
  const o = S.doc.lights[idx];
  box.append(h("div", { class: "cells" }, cell("offset_s", [...p, "offset_s"], "number"), cell("start_phase", [...p, "start_phase"], "int"),
    cell("phase_elapsed_s", [...p, "phase_elapsed_s"], "number")));
  if (Array.isArray(o.phases)) {
    box.append(rows("phases", [...p, "phases"], (ph) => [cell("duration_s", [...ph, "duration_s"], "number"),
      cell("state", [...ph, "state"], "text", { placeholder: "e.g. GGrr" })],
    () => ({ state: (o.phases[o.phases.length - 1] || prog.phases[0]).state, duration_s: 5.0 }), { inline: true, floats: true, addLabel: "+ phase" }));
    box.append(h("button", { type: "button", onclick: () => safeEdit([{ path: [...p, "phases"], delete: true }]) }, "Back to the map's phases"));
  } else {
    const copy = prog.phases.map((ph) => ({ state: ph.state, duration_s: ph.duration_s }));
    box.append(h("button", { type: "button", onclick: () => safeEdit([{ path: [...p, "phases"], value: copy, floats: true }]) }, "Edit phases (copy the map's)"));
  }
  box.append(...extras(o, ["tls", "offset_s", "start_phase", "phase_elapsed_s", "phases"], p),
    h("button", { type: "button", onclick: () => safeEdit([{ path: ["lights", idx], delete: true }]) }, `Remove override of ${prog.id}`));
  return box;
}

const DEPART = ["depart_lane", "depart_pos_m", "depart_speed", "max_speed_mps", "speed_factor"];

function departCells(p) {
  // depart_lane: an index of the first edge's lanes (picked on the map) or a keyword.
  return [cell("depart_lane", [...p, "depart_lane"], "laneindex", { placeholder: "best", list: "depart-lanes" }),
    cell("depart_pos_m", [...p, "depart_pos_m"], "number"),
    cell("depart_speed", [...p, "depart_speed"], "numkw", { placeholder: "max", list: "depart-speeds" }),
    cell("max_speed_mps", [...p, "max_speed_mps"], "number"), cell("speed_factor", [...p, "speed_factor"], "number")];
}

function trafficForm() {
  const tr = h("fieldset", { id: "traffic" }, h("legend", {}, "[traffic]"));
  const t = S.doc.traffic;
  tr.append(h("datalist", { id: "vtypes" }, ...Object.keys(K().builtin_vtypes).map((v) => h("option", { value: v }))),
    h("datalist", { id: "depart-lanes" }, ...K().depart_lanes.map((v) => h("option", { value: v }))),
    h("datalist", { id: "depart-speeds" }, ...K().depart_speeds.map((v) => h("option", { value: v }))));
  tr.append(field("mode", ["traffic", "mode"], ["", ...K().traffic_modes]), field("warmup_s", ["traffic", "warmup_s"], "number"),
    field("vtypes", ["traffic", "vtypes"], "text", { placeholder: "shipped vtypes.add.xml" }));
  const pv = ["traffic", "vehicles"];
  tr.append(rows("vehicles", pv, (p) => [cell("id", [...p, "id"], "text"), cell("vtype", [...p, "vtype"], "text", { list: "vtypes" }),
    cell("depart_s", [...p, "depart_s"], "number"), ...departCells(p), idList("route", [...p, "route"], "edge", vtypeClass(get(S.doc, [...p, "vtype"]))),
    ...extras(get(S.doc, p), ["id", "vtype", "route", "depart_s", ...DEPART], p, true)],
  () => ({ id: `veh${((t && t.vehicles) || []).length}`, route: [] }), { addLabel: "+ vehicle" }));
  const pf = ["traffic", "flows"];
  tr.append(rows("flows", pf, (p, f) => {
    const rate = f && "probability" in f ? "probability" : "vehs_per_hour";
    const rateSel = h("select", { title: "exactly one of vehs_per_hour and probability" },
      h("option", { value: "vehs_per_hour" }, "vehs_per_hour"), h("option", { value: "probability" }, "probability"));
    rateSel.value = rate;
    rateSel.addEventListener("change", () => {
      const other = rateSel.value;
      if (other === rate) return undefined;
      return safeEdit([{ path: [...p, rate], delete: true }, { path: [...p, other], value: other === "probability" ? 0.1 : 300 }]);
    });
    const rateCell = h("div", { class: "field cell", "data-field": [...p, rate].join(".") }, rateSel, control([...p, rate], "number"));
    return [cell("id", [...p, "id"], "text"), cell("vtype", [...p, "vtype"], "text", { list: "vtypes" }),
      cell("from", [...p, "from"], "edge"), cell("to", [...p, "to"], "edge"), rateCell,
      cell("begin_s", [...p, "begin_s"], "number"), cell("end_s", [...p, "end_s"], "number"), cell("number", [...p, "number"], "int"),
      ...departCells(p), idList("via", [...p, "via"], "edge", vtypeClass(f && f.vtype)),
      ...extras(f, ["id", "vtype", "from", "to", "via", "vehs_per_hour", "probability", "begin_s", "end_s", "number", ...DEPART], p, true)];
  }, () => ({ id: `flow${((t && t.flows) || []).length}`, from: "", to: "", vehs_per_hour: 300 }), { addLabel: "+ flow" }));
  const pr = ["traffic", "random"];
  const rnd = get(S.doc, pr);
  const rbox = h("div", { class: "rows", "data-rows": "traffic.random" });
  if (!isObj(rnd)) {
    rbox.append(h("div", { class: "rows-head" }, h("strong", {}, "random trips"),
      h("button", { type: "button", class: "add", onclick: () => safeEdit([{ path: pr, value: { density_per_km: 10.0 }, table: true, floats: true }]) }, "+ random trips")));
  } else {
    rbox.append(h("div", { class: "rows-head" }, h("strong", {}, "random trips"),
      h("button", { type: "button", class: "del", title: "remove random trips", onclick: () => safeEdit([{ path: pr, delete: true }]) }, "×")));
    const mix = isObj(rnd.mix) ? rnd.mix : {};
    const name = h("input", { type: "text", placeholder: "vtype", list: "vtypes", size: 6 });
    rbox.append(h("div", { class: "cells" }, cell("density_per_km", [...pr, "density_per_km"], "number"),
      cell("within_m", [...pr, "within_m"], "number"), cell("min_route_m", [...pr, "min_route_m"], "number")),
    h("div", { class: "rowcard mix", "data-field": "traffic.random.mix" }, h("span", { class: "idx" }, "mix"),
      ...Object.keys(mix).map((k) => h("span", { class: "id" }, cell(k, [...pr, "mix", k], "number"),
        h("button", { type: "button", class: "del", title: `remove ${k}`, onclick: () => safeEdit([{ path: [...pr, "mix", k], delete: true }]) }, "×"))),
      name, h("button", { type: "button", onclick: () => name.value.trim() && safeEdit([{ path: [...pr, "mix", name.value.trim()], value: 1.0, floats: true }]) }, "+ vtype")),
    ...extras(rnd, ["density_per_km", "within_m", "min_route_m", "mix"], pr));
  }
  tr.append(rbox);
  if (isObj(t)) tr.append(...extras(t, ["mode", "warmup_s", "vtypes", "vehicles", "flows", "random"], ["traffic"]));
  return tr;
}

function renderLights() {
  const box = $("lights");
  box.replaceChildren(h("strong", {}, "Traffic lights"));
  if (!S.map || !S.doc) return;
  const overrides = S.doc.lights || [];
  for (const prog of S.map.programs) box.append(lightForm(prog, overrides.findIndex((l) => l.tls === prog.id)));
  // Overrides of lights the map lacks (the validator says so) stay editable.
  overrides.forEach((o, i) => {
    if (!S.map.programs.some((p) => p.id === o.tls)) box.append(field(`lights[${i}] (JSON)`, ["lights", i], "json"));
  });
  box.append(trafficForm());
  updateNow();
}

function renderSummary() {
  const el = $("summary");
  if (!S.geo) {
    el.textContent = "no valid scenario yet";
    return;
  }
  const s = S.geo.summary;
  el.replaceChildren(h("div", {}, h("strong", {}, s.id), ` (${s.category})`),
    h("div", { id: "route-info" }, `route ${s.route_length_m.toFixed(1)} m over ${s.route_edges.length} edges, T_ref ${s.reference_duration_s.toFixed(1)} s`),
    h("div", {}, `scenario duration ${S.geo.scenario_duration_s.toFixed(1)} s; ${s.actors} actors, ${s.obstacles} obstacles; traffic: ${s.traffic}`),
    ...(S.error ? [h("div", { class: "help" }, "(drawn: the last valid state)")] : []));
}

function fieldPath(field) {
  // `actors[0].start.ego_eta_s` → `actors.0.start.ego_eta_s`
  return field.replace(/\[(\d+)\]/g, ".$1");
}

function showError() {
  for (const el of document.querySelectorAll(".invalid, .warned")) el.classList.remove("invalid", "warned");
  for (const el of document.querySelectorAll(".field-error, .field-warning")) el.remove();
  const box = $("error-box");
  const errors = S.error ? S.errors : [];
  box.hidden = !errors.length;
  box.replaceChildren(...errors.map((e) => h("div", { class: "error-line" }, e.message)));
  const wbox = $("warning-box");
  wbox.hidden = !S.warnings.length;
  wbox.replaceChildren(...S.warnings.map((w) => h("div", { class: "warning-line" }, "warning: " + w.message)));
  let first = true;
  for (const e of errors) {
    const f = markField(e.field, "invalid", "field-error", e.message);
    if (f && first) f.scrollIntoView({ block: "nearest" });
    if (f) first = false;
  }
  for (const w of S.warnings) markField(w.field, "warned", "field-warning", "warning: " + w.message);
}

// Shows a message at the field it names: the key's input, else the nearest enclosing one (a
// row, a table) that has one.
function markField(field, cls, msgCls, message) {
  if (!field) return null;
  let p = fieldPath(field);
  while (p) {
    const q = CSS.escape(p);
    const input = document.querySelector(`[data-path="${q}"], [data-row="${q}"], [data-rows="${q}"]`);
    if (input) {
      const f = input.closest(".field") || input;
      f.classList.add(cls);
      f.append(h("div", { class: msgCls }, message));
      return f;
    }
    p = p.includes(".") ? p.slice(0, p.lastIndexOf(".")) : "";
  }
  return null;
}

// -- preview, run, probe -----------------------------------------------------------------------
let previewTimer = null;
function schedulePreview() {
  clearTimeout(previewTimer);
  previewTimer = setTimeout(preview, 120);
}

function driver() {
  return $("driver").value;
}

// The chosen driver's episode of this text: the slider runs from its first decision to its
// last, where a marker says how it ended.
async function ensureEpisode(buf) {
  buf = buf || buffer();
  const key = buf.text + "|" + driver();
  if (S.episode && S.episode.key === key) return S.episode;
  const ep = await api("/api/episode", { ...buf, driver: driver() });
  if (S.text + "|" + driver() !== key) return S.episode; // edited meanwhile: the next preview asks
  S.episode = { ...ep, key };
  const slider = $("time");
  const t = Number(slider.value);
  slider.min = String(ep.start_s);
  slider.max = String(ep.end_s);
  slider.value = String(Math.min(Math.max(t, ep.start_s), ep.end_s));
  const end = $("time-end");
  end.textContent = `${ep.driver} ends at ${ep.end_s.toFixed(2)} s: ${ep.termination} (S_R4 ${ep.score.toFixed(1)})`;
  end.className = ep.termination === "destination_reached" ? "good" : "bad";
  end.dataset.endS = String(ep.end_s);
  renderLights();
  return S.episode;
}

// For tests: the slider's range is this text's episode with the chosen driver.
window.editor.episodeReady = () => !!S.episode && S.episode.key === S.text + "|" + driver();

let previewSeq = 0;
async function preview() {
  if (S.error || !S.path) return;
  const seq = ++previewSeq;
  // The buffer as it is now: an edit meanwhile schedules its own preview.
  const buf = buffer();
  try {
    await ensureEpisode(buf);
    if (seq !== previewSeq || buf.text !== S.text) return;
    await showAt(Number($("time").value), buf);
  } catch (e) {
    if (buf.text === S.text) status("preview: " + e.message, "bad");
  }
}

// The scene, front camera and BEV at time t, driven by the chosen driver; every label shows
// the time of the decision it was taken at.
async function showAt(t, buf) {
  const body = { ...(buf || buffer()), time_s: t, driver: driver() };
  const [scene, front, bev] = await Promise.all([api("/api/scene", body),
    api("/api/frame", { ...body, view: "front" }), api("/api/frame", { ...body, view: "bev" })]);
  if (body.text !== S.text) return; // edited meanwhile: not this buffer's scene
  S.scene = scene;
  $("time-out").textContent = scene.time_s.toFixed(2);
  draw();
  updateNow();
  for (const [view, r] of [["front", front], ["bev", bev]]) {
    const img = $(view);
    if (img.src) URL.revokeObjectURL(img.src);
    img.src = URL.createObjectURL(r.blob);
    img.dataset.time = r.time;
    img.dataset.driver = body.driver;
    $(view + "-label").textContent = `${view === "front" ? "front camera" : "bird's-eye view"}, ${body.driver}, t = ${Number(r.time).toFixed(2)} s`;
  }
}

function drawTimeline() {
  const c = $("timeline");
  const g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  if (!S.run) return;
  const states = S.run.states;
  const tmax = states[states.length - 1].time_s;
  g.fillStyle = "#ddd";
  g.fillRect(0, 18, c.width, 4);
  for (const e of S.run.score.events) {
    const x = (e.time / tmax) * (c.width - 4) + 2;
    g.fillStyle = e.type === "destination_reached" ? "#2e7d32" : e.type.includes("collision") ? "#c62828" : "#f9a825";
    g.fillRect(x - 1, 8, 3, 24);
    g.fillStyle = "#222";
    g.fillText(e.type, Math.min(x + 3, c.width - 110), 10);
  }
}

async function runDriver() {
  if (S.error) return status("fix the error first", "bad");
  const driver = $("driver").value;
  await ensureEpisode();
  status(`running ${driver}…`);
  S.run = await api("/api/run", { ...buffer(), driver });
  const sc = S.run.score;
  $("run-result").replaceChildren(
    h("div", { id: "run-score" }, `${driver}: S_R4 ${sc.score_composed.toFixed(1)}, ${sc.termination_reason} at ${sc.meta.duration_game.toFixed(1)} s`),
    h("div", { class: "help" }, `route ${sc.score_route.toFixed(1)}, events: ${sc.events.map((e) => `${e.type}@${e.time.toFixed(1)}s`).join(", ") || "none"}`));
  drawTimeline();
  status("run done", "good");
}

// Play: the chosen driver's episode decision by decision, the map, the camera and the BEV
// together (each frame as the world rendered it); Play again stops.
let playing = null;
async function play() {
  if (playing) {
    playing.stop = true;
    return;
  }
  if (!S.run || S.run.driver !== driver()) await runDriver();
  if (!S.run) return;
  const me = { stop: false };
  playing = me;
  $("btn-play").textContent = "Stop";
  try {
    const text = S.text;
    const states = S.run.states;
    // The current slider position onwards (from the start when it is at the end).
    let i = states.findIndex((st) => st.time_s >= Number($("time").value) - 1e-9);
    if (i < 0 || i >= states.length - 1) i = 0;
    for (; i < states.length && !me.stop && S.text === text; i += 2) {
      const t = states[i].time_s;
      $("time").value = String(t);
      await showAt(t);
    }
    if (!me.stop && S.text === text) {
      const last = states[states.length - 1].time_s;
      $("time").value = String(last);
      await showAt(last);
    }
  } finally {
    playing = null;
    $("btn-play").textContent = "Play";
  }
}

async function probe() {
  if (S.error) return status("fix the error first", "bad");
  status("probing…");
  const d = await api("/api/probe", buffer());
  const rows = d.probe.map((p) => h("tr", {}, h("td", {}, p.cell), h("td", {}, p.score.toFixed(1)), h("td", {}, p.termination)));
  $("probe-result").replaceChildren(h("table", { id: "probe-table" }, h("tr", {}, h("th", {}, "driver"), h("th", {}, "S_R4"), h("th", {}, "end")), ...rows));
  status("probe done", "good");
}

// -- files -------------------------------------------------------------------------------------
async function save(path, create) {
  const at = create ? $("saveas-path") : $("btn-save");
  saveError(null);
  if (!S.path && !create) return status("nothing to save: open or create a scenario first", "bad");
  if (!path) {
    saveError("give a path relative to the root, e.g. " + ($("saveas-path").placeholder || "name.toml"));
    return status("not saved: no path given", "bad");
  }
  let d;
  try {
    d = await api("/api/save", { path, text: S.text, create: !!create });
  } catch (e) {
    // Refused (a path outside the root, an existing name, ...): the server's reason, at the field.
    saveError(e.message, at);
    return status("not saved: " + e.message, "bad");
  }
  if (d.saved) {
    S.path = path;
    S.dirty = false;
    showPath();
    await refreshFiles();
    status("saved " + path, "good");
  } else {
    S.error = d.error;
    S.errors = d.errors || [d.error];
    showError();
    status(`not saved: invalid, ${S.errors.length} error${S.errors.length === 1 ? "" : "s"} (see the fields)`, "bad");
  }
}

function saveError(msg, at) {
  const el = $("save-error");
  el.hidden = !msg;
  el.textContent = msg || "";
  $("saveas-path").classList.toggle("invalid-input", !!msg && at === $("saveas-path"));
}

async function refreshFiles() {
  S.info = await api("/api/info");
  const sel = $("file-list");
  sel.replaceChildren(h("option", { value: "" }, "open a file…"), ...S.info.files.map((f) => h("option", { value: f }, f)));
  if (S.path) sel.value = S.path;
  const cat = $("new-category");
  if (!cat.options.length) cat.append(...S.info.categories.map((c) => h("option", { value: c }, c)));
  // "New" starts from the category's template, or an empty map picked here.
  const maps = $("new-map");
  if (maps.options.length <= 1) {
    const specs = [...S.info.builtin_maps];
    if (S.info.default_map && !specs.includes(S.info.default_map)) specs.unshift(S.info.default_map);
    maps.append(...specs.map((m) => h("option", { value: m }, `empty map: ${m}`)));
  }
  const drv = $("driver");
  if (!drv.options.length) drv.append(...S.info.drivers.map((d) => h("option", { value: d }, d)));
}

async function newScenario() {
  if (!mayDiscard("start a new scenario")) return status("kept the unsaved changes", "");
  const id = $("new-id").value.trim() || "new_scenario";
  const category = $("new-category").value;
  const map = $("new-map").value;
  const body = map ? { id, category, template: false, map } : { id, category, template: true, keep_actors: $("new-actors").checked };
  const d = await api("/api/new", body);
  S.mapKey = null;
  S.dirty = true;
  S.selected = null;
  S.scene = null;
  S.geo = null;
  clearPreview();
  S.undo = [];
  S.redo = [];
  updateUndo();
  await setBuffer(d);
  $("file-list").value = "";
  $("saveas-path").value = d.path;
  saveError(null);
  status(map ? `new ${category} scenario on ${map} (unsaved): place the ego's start and destination`
    : `new ${category} scenario from its template${$("new-actors").checked ? "" : ", no actors"} (unsaved)`);
}

// -- wiring --------------------------------------------------------------------------------------
for (const b of document.querySelectorAll("#tools button[data-mode]")) b.addEventListener("click", () => setMode(b.dataset.mode));
$("file-list").addEventListener("change", guard(async (ev) => {
  const want = ev.target.value;
  if (!want) return;
  if (!mayDiscard("open " + want)) {
    ev.target.value = S.path || "";
    return status("kept the unsaved changes", "");
  }
  await openFile(want);
}, "open"));
$("btn-save").addEventListener("click", guard(() => save(S.path, false), "save"));
$("btn-saveas").addEventListener("click", guard(() => save($("saveas-path").value.trim(), true), "save as"));
$("btn-undo").addEventListener("click", guard(undo, "undo"));
$("btn-redo").addEventListener("click", guard(redo, "redo"));
$("btn-fit-route").addEventListener("click", () => { fitRoute(); draw(); });
$("btn-fit-map").addEventListener("click", () => { fitView(); draw(); });
$("new-map").addEventListener("change", () => { $("new-actors").disabled = !!$("new-map").value; });
$("driver").addEventListener("change", () => {
  S.run = null;
  $("run-result").textContent = "";
  drawTimeline();
  schedulePreview();
});
window.addEventListener("beforeunload", (ev) => {
  if (!S.dirty) return undefined;
  ev.preventDefault();
  ev.returnValue = "";
  return "";
});
window.addEventListener("unhandledrejection", (ev) => status("error: " + (ev.reason && ev.reason.message), "bad"));
$("btn-new").addEventListener("click", () => newScenario().catch((e) => status(e.message, "bad")));
$("btn-run").addEventListener("click", () => runDriver().catch((e) => status(e.message, "bad")));
$("btn-play").addEventListener("click", () => play().catch((e) => status(e.message, "bad")));
$("btn-probe").addEventListener("click", () => probe().catch((e) => status(e.message, "bad")));
$("btn-apply-text").addEventListener("click", guard(async () => {
  if (!S.path) return status("open or create a scenario first", "bad");
  const text = $("toml").value;
  const before = S.text;
  const d = await api("/api/validate", { path: S.path, text });
  remember(before, text);
  S.dirty = true;
  await setBuffer({ ...d, text });
  bufferStatus("text applied");
}, "apply text"));
$("time").addEventListener("input", () => {
  // The label keeps the shown frame's own time until the new frame is in.
  updateNow();
  schedulePreview();
});
window.addEventListener("resize", draw);

// A new `#path` in the address bar opens that file (asking first about unsaved edits).
window.addEventListener("hashchange", guard(async () => {
  const want = decodeURIComponent(location.hash.slice(1));
  if (!want || want === S.path) return;
  if (!mayDiscard("open " + want)) return status("kept the unsaved changes", "");
  await openFile(want);
}, "open"));

(async () => {
  busy(0);
  updateUndo();
  try {
    FACTS = await api("/api/facts");
    fillKindPickers();
    await refreshFiles();
    setMode("select");
    const want = decodeURIComponent(location.hash.slice(1));
    if (want) await openFile(want);
  } catch (e) {
    status(e.message, "bad");
  } finally {
    document.body.dataset.ready = "1";
  }
})();
