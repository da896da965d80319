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
};
window.editor = { S };

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
    if (type.startsWith("image/")) {
      if (!r.ok) throw new Error(await r.text());
      return { blob: await r.blob(), time: r.headers.get("X-Scene-Time") };
    }
    const d = type.includes("json") ? await r.json() : { error: await r.text() };
    if (!r.ok && !("ok" in d)) throw new Error(d.error || r.statusText);
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
  } else {
    S.error = d.error;
  }
  $("path").textContent = S.path ? S.path + (S.dirty ? " *" : "") : "";
  $("toml").value = S.text;
  await ensureMap();
  renderForm();
  renderSummary();
  showError();
  draw();
  if (!S.error) {
    S.run = null;
    $("run-result").textContent = "";
    $("probe-result").textContent = "";
    drawTimeline();
    const dur = S.geo.scenario_duration_s;
    $("time").max = String(Math.max(5, Math.ceil(dur * 2)));
    schedulePreview();
  }
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
    fitView();
  } catch (e) {
    status("map: " + e.message, "bad");
  }
}

async function edit(edits) {
  const d = await api("/api/edit", { ...buffer(), edits });
  if (d.error && !("ok" in d)) throw new Error(d.error);
  S.dirty = true;
  await setBuffer(d);
  status(S.error ? "invalid: see the field" : "ok", S.error ? "bad" : "good");
}

async function openFile(rel) {
  const d = await api("/api/file?" + new URLSearchParams({ path: rel }));
  S.dirty = false;
  S.mapKey = null;
  S.selected = null;
  await setBuffer({ ...d, path: rel });
  status("opened " + rel, "good");
}

// -- view ----------------------------------------------------------------------------------------
const canvas = $("map");
const ctx = canvas.getContext("2d");

function fitView() {
  if (!S.map) return;
  const [x0, y0, x1, y1] = S.map.bounds;
  resizeCanvas();
  const s = Math.min(canvas.width / (x1 - x0 + 20), canvas.height / (y1 - y0 + 20));
  S.view.scale = s;
  S.view.ox = (x0 + x1) / 2 - canvas.width / 2 / s;
  S.view.oy = (y0 + y1) / 2 + canvas.height / 2 / s;
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
  if (!S.map) return;
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
  S.pending = [];
  for (const b of document.querySelectorAll("#tools button[data-mode]")) {
    b.classList.toggle("active", b.dataset.mode === mode);
  }
  $("mode-help").textContent = HELP[mode] || "";
  draw();
}

function vclassFor(kind) {
  if (kind === "pedestrian") return "pedestrian";
  if (kind === "cyclist") return "bicycle";
  if (kind === "bus") return "bus";
  if (kind === "truck") return "truck";
  if (kind === "motorcycle") return "motorcycle";
  return "passenger";
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

window.addEventListener("mouseup", async (ev) => {
  const d = drag;
  drag = null;
  if (!d) return;
  if (d.handle) {
    const [px, py] = eventPos(ev);
    const [x, y] = toWorld(px, py);
    const hit = await snap(x, y, "passenger", false);
    const i = d.handle.actor;
    const of = hit.lane ? { lane: hit.lane, s: hit.s } : [round(x), round(y)];
    await edit([{ path: ["actors", i, "start", "of"], value: of }]);
    return;
  }
  if (d.pan && !d.moved && ev.target === canvas) {
    const [px, py] = eventPos(ev);
    selectAt(px, py);
  }
});

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

canvas.addEventListener("click", async (ev) => {
  if (S.mode === "select") return;
  const [px, py] = eventPos(ev);
  const [x, y] = toWorld(px, py);
  if (S.mode === "ego-start" || S.mode === "ego-dest") {
    const hit = await snap(x, y, "passenger", false);
    if (!hit.lane) return status("no drivable lane there", "bad");
    const key = S.mode === "ego-start" ? "start" : "destination";
    await edit([{ path: ["ego", key], value: { lane: hit.lane, s: hit.s } }]);
  } else if (S.mode === "obstacle") {
    const hit = await snap(x, y, null, false);
    if (!hit.lane) return status("no lane there", "bad");
    await edit([{ path: ["obstacles"], append: { kind: $("obstacle-kind").value, at: { lane: hit.lane, s: hit.s } } }]);
  } else if (S.mode === "actor") {
    const kind = $("actor-kind").value;
    const hit = await snap(x, y, vclassFor(kind), false);
    if (!hit.lane) return status("no lane open to a " + kind + " there", "bad");
    S.pending.push({ x, y, lane: hit.lane, s: hit.s });
    draw();
  }
});

canvas.addEventListener("dblclick", () => finishActor());
window.addEventListener("keydown", (ev) => {
  if (ev.target.tagName === "INPUT" || ev.target.tagName === "TEXTAREA") return;
  if (ev.key === "Enter") finishActor();
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
  await edit([{ path: ["actors"], append: actor }]);
  S.selected = n;
  setMode("select");
  renderForm();
}

// -- forms -------------------------------------------------------------------------------------
function h(tag, attrs, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null) el.setAttribute(k, v);
  }
  for (const c of children) if (c !== null && c !== undefined) el.append(c);
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

// One input bound to a key path. kind: "number", "text", "json" or a list of choices.
function field(label, path, kind) {
  const value = get(S.doc, path);
  let input;
  if (Array.isArray(kind)) {
    input = h("select", {}, ...kind.map((c) => h("option", { value: c }, c === "" ? "(default)" : c)));
    input.value = value === undefined ? "" : String(value);
  } else {
    input = h("input", { type: "text" });
    input.value = value === undefined ? "" : kind === "json" ? JSON.stringify(value) : String(value);
  }
  input.dataset.path = path.join(".");
  input.addEventListener("change", async () => {
    const raw = input.value.trim();
    if (raw === "") return edit([{ path, delete: true }]).catch((e) => status(e.message, "bad"));
    let v = raw;
    if (kind === "number") v = Number(raw);
    if (kind === "json") {
      try {
        v = JSON.parse(raw);
      } catch (e) {
        return status(`${path.join(".")}: not JSON (${e.message})`, "bad");
      }
    }
    if (kind === "number" && !Number.isFinite(v)) v = raw; // the validator says what is wrong
    await edit([{ path, value: v }]).catch((e) => status(e.message, "bad"));
  });
  return h("div", { class: "field", "data-field": path.join(".") }, h("label", {}, label), input);
}

const TRIGGERS = ["time_s", "ego_within_m", "ego_eta_s", "after"];
const BRAKES = ["", "at_s", "after_s", "ego_within_m", "ego_gap_m", "ego_gap_s", "ego_ttc_s", "ego_eta_s", "gap_held_s", "after"];

function triggerKind(t) {
  if (!t) return "time_s";
  return TRIGGERS.find((k) => k in t) || "time_s";
}

function defaultPlace() {
  const st = get(S.doc, ["ego", "start"]);
  if (st && st.lane) return { lane: st.lane, s: round((st.s || 0) + 40) };
  return "actor_self";
}

function triggerFields(i, prefix, t, choices) {
  const box = h("div", {});
  const kind = prefix[prefix.length - 1] === "brake" ? (BRAKES.find((k) => k && t && k in t) || "") : triggerKind(t);
  const sel = h("select", {}, ...choices.map((c) => h("option", { value: c }, c || "(none)")));
  sel.value = kind;
  sel.dataset.path = prefix.join(".") + ".kind";
  sel.addEventListener("change", async () => {
    const k = sel.value;
    const keep = {};
    if (prefix[prefix.length - 1] === "brake" && t) {
      for (const key of ["decel_mps2", "to_speed_mps", "hold_s"]) if (t[key] !== undefined) keep[key] = t[key];
    }
    if (k === "") return edit([{ path: prefix, delete: true }]);
    const first = (S.doc.actors || []).map((a, j) => a.name || `actors[${j}]`).find((_, j) => j !== i);
    const v = {
      time_s: { time_s: 0.0 }, ego_within_m: { ego_within_m: 20.0 }, ego_eta_s: { ego_eta_s: 3.0, of: defaultPlace() },
      after: { after: first || "", delay_s: 0.0 }, at_s: { at_s: 10.0 }, after_s: { after_s: 2.0 },
      ego_gap_m: { ego_gap_m: 15.0 }, ego_gap_s: { ego_gap_s: 1.5 }, ego_ttc_s: { ego_ttc_s: 3.0 },
      gap_held_s: { gap_held_s: 3.0 },
    }[k];
    if (prefix[prefix.length - 1] === "brake" && keep.decel_mps2 === undefined) keep.decel_mps2 = 6.0;
    await edit([{ path: prefix, value: { ...v, ...keep } }]);
  });
  box.append(h("div", { class: "field", "data-field": prefix.join(".") }, h("label", {}, prefix[prefix.length - 1]), sel));
  if (kind) {
    if (kind !== "after") box.append(field(kind, [...prefix, kind], "number"));
    if (kind === "after") {
      box.append(field("after (actor)", [...prefix, "after"], "text"));
      box.append(field("delay_s", [...prefix, "delay_s"], "number"));
      box.append(field("event", [...prefix, "event"], ["", "start", "brake", "end"]));
    }
    if (["ego_within_m", "ego_eta_s"].includes(kind)) box.append(field("of", [...prefix, "of"], "json"));
  }
  return box;
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
    field("seed", ["seed"], "number"));
  const ego = h("fieldset", {}, h("legend", {}, "Ego"));
  ego.append(field("start", ["ego", "start"], "json"), field("destination", ["ego", "destination"], "json"),
    field("route_edges", ["ego", "route_edges"], "json"), field("speed_mps", ["ego", "speed_mps"], "number"));
  form.append(gen, ego);
  (S.doc.actors || []).forEach((a, i) => {
    const fs = h("fieldset", { "data-actor": i, class: S.selected === i ? "selected" : "" },
      h("legend", {}, `actors[${i}] ${a.name || ""}`));
    const p = ["actors", i];
    fs.append(field("name", [...p, "name"], "text"),
      field("kind", [...p, "kind"], ["car", "bus", "truck", "motorcycle", "cyclist", "pedestrian"]),
      field("speed_mps", [...p, "speed_mps"], "number"), field("accel_mps2", [...p, "accel_mps2"], "number"),
      field("initial_speed_mps", [...p, "initial_speed_mps"], "number"),
      field("at_end", [...p, "at_end"], ["", "stop", "remove"]));
    if ("waypoints" in a) fs.append(field("waypoints", [...p, "waypoints"], "json"));
    if ("route" in a) fs.append(field("route", [...p, "route"], "json"));
    fs.append(h("div", { class: "help" }, "start trigger"), triggerFields(i, [...p, "start"], a.start, TRIGGERS));
    if (a.brake) {
      fs.append(h("div", { class: "help" }, "brake"), triggerFields(i, [...p, "brake"], a.brake, BRAKES),
        field("decel_mps2", [...p, "brake", "decel_mps2"], "number"),
        field("to_speed_mps", [...p, "brake", "to_speed_mps"], "number"), field("hold_s", [...p, "brake", "hold_s"], "number"));
    } else {
      fs.append(triggerFields(i, [...p, "brake"], undefined, BRAKES));
    }
    fs.append(field("pace", [...p, "pace"], "json"), field("lane_changes", [...p, "lane_changes"], "json"));
    fs.append(h("button", { onclick: () => edit([{ path: ["actors", i], delete: true }]) }, "Delete actor"));
    form.append(fs);
  });
  (S.doc.obstacles || []).forEach((o, i) => {
    const fs = h("fieldset", {}, h("legend", {}, `obstacles[${i}] ${o.name || ""}`));
    const p = ["obstacles", i];
    fs.append(field("kind", [...p, "kind"], ["cone", "barrier", "static_object", "car", "bus", "truck", "motorcycle", "cyclist", "pedestrian"]),
      field("at", [...p, "at"], "json"), field("name", [...p, "name"], "text"),
      h("button", { onclick: () => edit([{ path: ["obstacles", i], delete: true }]) }, "Delete obstacle"));
    form.append(fs);
  });
  renderLights();
}

function renderLights() {
  const box = $("lights");
  box.replaceChildren(h("strong", {}, "Traffic lights"));
  if (!S.map || !S.doc) return;
  const overrides = S.doc.lights || [];
  for (const prog of S.map.programs) {
    const idx = overrides.findIndex((l) => l.tls === prog.id);
    const phases = idx >= 0 && overrides[idx].phases ? overrides[idx].phases : prog.phases;
    const cycle = phases.reduce((s, p) => s + p.duration_s, 0);
    const bar = h("div", { class: "lightbar", title: "program over one cycle (map's or override's phases)" });
    for (const p of phases) {
      const st = p.state.toLowerCase();
      const c = st.includes("g") ? LIGHT.green : st.includes("y") ? LIGHT.yellow : LIGHT.red;
      bar.append(h("span", { style: `width:${(100 * p.duration_s) / cycle}%;background:${c}`, title: `${p.state} ${p.duration_s} s` }));
    }
    box.append(h("div", {}, `${prog.id}: cycle ${cycle.toFixed(0)} s, map offset ${prog.offset_s} s`), bar);
    if (idx >= 0) {
      const p = ["lights", idx];
      box.append(field("offset_s", [...p, "offset_s"], "number"), field("start_phase", [...p, "start_phase"], "number"),
        field("phase_elapsed_s", [...p, "phase_elapsed_s"], "number"), field("phases", [...p, "phases"], "json"),
        h("button", { onclick: () => edit([{ path: ["lights", idx], delete: true }]) }, `Remove override of ${prog.id}`));
    } else {
      box.append(h("button", { onclick: () => edit([{ path: ["lights"], append: { tls: prog.id, offset_s: 0.0 } }]) },
        `Override ${prog.id}`));
    }
  }
  if (S.scene) {
    const now = S.scene.lights.map((l) => `${l.lane}: ${l.color}`).join(", ");
    box.append(h("div", { class: "help" }, `at t = ${S.scene.time_s.toFixed(2)} s (from the world): ${now}`));
  }
  const tr = h("fieldset", {}, h("legend", {}, "[traffic]"));
  tr.append(field("mode", ["traffic", "mode"], ["", "sumo", "native", "none"]), field("warmup_s", ["traffic", "warmup_s"], "number"),
    field("vehicles", ["traffic", "vehicles"], "json"), field("flows", ["traffic", "flows"], "json"),
    field("random", ["traffic", "random"], "json"));
  box.append(tr);
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
  for (const el of document.querySelectorAll(".field.invalid")) el.classList.remove("invalid");
  for (const el of document.querySelectorAll(".field-error")) el.remove();
  const box = $("error-box");
  if (!S.error) {
    box.hidden = true;
    return;
  }
  box.hidden = false;
  box.textContent = S.error.message;
  if (!S.error.field) return;
  let p = fieldPath(S.error.field);
  while (p) {
    const input = document.querySelector(`[data-path="${CSS.escape(p)}"]`);
    if (input) {
      const f = input.closest(".field");
      f.classList.add("invalid");
      f.append(h("div", { class: "field-error" }, S.error.message));
      return;
    }
    p = p.includes(".") ? p.slice(0, p.lastIndexOf(".")) : "";
  }
}

// -- preview, run, probe -----------------------------------------------------------------------
let previewTimer = null;
function schedulePreview() {
  clearTimeout(previewTimer);
  previewTimer = setTimeout(preview, 120);
}

async function preview() {
  if (S.error || !S.path) return;
  const t = Number($("time").value);
  const body = { ...buffer(), time_s: t, driver: "expert" };
  try {
    S.scene = await api("/api/scene", body);
    $("time-out").textContent = S.scene.time_s.toFixed(2);
    draw();
    renderLights();
    for (const view of ["front", "bev"]) {
      const r = await api("/api/frame", { ...body, view });
      const img = $(view);
      if (img.src) URL.revokeObjectURL(img.src);
      img.src = URL.createObjectURL(r.blob);
      img.dataset.time = r.time;
    }
  } catch (e) {
    status("preview: " + e.message, "bad");
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
  status(`running ${driver}…`);
  S.run = await api("/api/run", { ...buffer(), driver });
  const sc = S.run.score;
  $("run-result").replaceChildren(
    h("div", { id: "run-score" }, `${driver}: S_R4 ${sc.score_composed.toFixed(1)}, ${sc.termination_reason} at ${sc.meta.duration_game.toFixed(1)} s`),
    h("div", { class: "help" }, `route ${sc.score_route.toFixed(1)}, events: ${sc.events.map((e) => `${e.type}@${e.time.toFixed(1)}s`).join(", ") || "none"}`));
  drawTimeline();
  status("run done", "good");
}

async function play() {
  if (!S.run) await runDriver();
  if (!S.run) return;
  for (const st of S.run.states) {
    S.scene = st;
    $("time").value = String(st.time_s);
    $("time-out").textContent = st.time_s.toFixed(2);
    draw();
    await new Promise((r) => setTimeout(r, 40));
  }
  schedulePreview();
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
  const d = await api("/api/save", { path, text: S.text, create: !!create });
  if (d.saved) {
    S.path = path;
    S.dirty = false;
    $("path").textContent = path;
    status("saved " + path, "good");
    await refreshFiles();
  } else {
    if (d.error && "ok" in d) {
      S.error = d.error;
      showError();
      status("not saved: invalid", "bad");
    } else {
      status("not saved: " + d.error, "bad");
    }
  }
}

async function refreshFiles() {
  S.info = await api("/api/info");
  const sel = $("file-list");
  sel.replaceChildren(h("option", { value: "" }, "open a file…"), ...S.info.files.map((f) => h("option", { value: f }, f)));
  if (S.path) sel.value = S.path;
  const cat = $("new-category");
  if (!cat.options.length) cat.append(...S.info.categories.map((c) => h("option", { value: c }, c)));
}

async function newScenario() {
  const id = $("new-id").value.trim() || "new_scenario";
  const category = $("new-category").value;
  const blank = $("new-blank").checked;
  const d = await api("/api/new", { id, category, template: !blank, map: S.info.default_map || undefined });
  if (d.error && !("ok" in d)) return status(d.error, "bad");
  S.mapKey = null;
  S.dirty = true;
  S.selected = null;
  S.scene = null;
  await setBuffer(d);
  $("saveas-path").value = d.path;
  status(`new ${category} scenario (unsaved)`);
}

// -- wiring --------------------------------------------------------------------------------------
for (const b of document.querySelectorAll("#tools button[data-mode]")) b.addEventListener("click", () => setMode(b.dataset.mode));
$("file-list").addEventListener("change", (ev) => ev.target.value && openFile(ev.target.value));
$("btn-save").addEventListener("click", () => S.path && save(S.path, false));
$("btn-saveas").addEventListener("click", () => save($("saveas-path").value.trim(), true));
$("btn-new").addEventListener("click", () => newScenario().catch((e) => status(e.message, "bad")));
$("btn-run").addEventListener("click", () => runDriver().catch((e) => status(e.message, "bad")));
$("btn-play").addEventListener("click", () => play().catch((e) => status(e.message, "bad")));
$("btn-probe").addEventListener("click", () => probe().catch((e) => status(e.message, "bad")));
$("btn-apply-text").addEventListener("click", async () => {
  const d = await api("/api/validate", { path: S.path, text: $("toml").value });
  S.dirty = true;
  await setBuffer({ ...d, text: $("toml").value });
});
$("time").addEventListener("input", () => {
  $("time-out").textContent = Number($("time").value).toFixed(2);
  schedulePreview();
});
window.addEventListener("resize", draw);

(async () => {
  busy(0);
  await refreshFiles();
  setMode("select");
  const want = decodeURIComponent(location.hash.slice(1));
  if (want) await openFile(want);
  document.body.dataset.ready = "1";
})();
