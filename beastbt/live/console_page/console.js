// beastbt operator console: the page's script. No framework, no CDN: it works offline in a field.
// Contract: GET /api/state, GET /api/map, WS /api/ws (state), WS /api/video (JPEG or H.264 frames),
// POST /api/<control>.
"use strict";

// The token (a console off loopback, or --console-token always) comes once in the address. The server has set
// its cookie with this page; the token leaves the address bar at once (no history entry, no bookmark, no copy
// and paste that gives it away) and stays with this tab only, to be sent in the requests themselves.
const TOKEN_KEY = "beastbt_console_token";
const token = (() => {
  const params = new URLSearchParams(location.search);
  const given = params.get("token");
  if (given) {
    try { sessionStorage.setItem(TOKEN_KEY, given); } catch (e) { /* storage off: the cookie carries it */ }
    params.delete("token");
    const rest = params.toString();
    history.replaceState(null, "", location.pathname + (rest ? "?" + rest : "") + location.hash);
    return given;
  }
  try { return sessionStorage.getItem(TOKEN_KEY); } catch (e) { return null; }
})();
const withToken = (path) => token ? path + (path.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token) : path;
const wsUrl = (path) => (location.protocol === "https:" ? "wss://" : "ws://") + location.host + withToken(path);
const authHeaders = () => token ? {"Authorization": "Bearer " + token} : {};
const $ = (id) => document.getElementById(id);
const ENDED = new Set(["succeeded", "failed", "aborted"]);

let state = null;
let mapLayers = null;
let mapVersion = -1;
let trail = [];
let mapDirty = true;

// ---- controls -------------------------------------------------------------------------------
async function post(path, body) {
  try {
    // Always JSON, same origin: what the server asks of a control (a page on another site can send neither).
    const r = await fetch("/api/" + path, {method: "POST", body: JSON.stringify(body || {}),
                                          headers: {"Content-Type": "application/json", ...authHeaders()},
                                          credentials: "same-origin", cache: "no-store"});
    const answer = await r.json().catch(() => ({}));
    if (!r.ok) notice(answer.error || ("HTTP " + r.status));
    return answer;
  } catch (e) { notice("the robot did not answer: " + e); return {}; }
}
function notice(text) {
  const n = $("notice");
  n.textContent = text; n.hidden = false;
  clearTimeout(notice.timer); notice.timer = setTimeout(() => { n.hidden = true; }, 5000);
}
$("pause").onclick = () => post("pause");
$("resume").onclick = () => post("resume");
$("abort").onclick = () => { if (confirm("Abort the mission? The robot stops and the run ends.")) post("abort"); };
$("estop").onclick = () => post("estop");
$("estop-reset").onclick = () => post("estop/reset");
$("answer-yes").onclick = () => state && state.question && post("answer", {id: state.question.id, choice: "yes"});
$("answer-no").onclick = () => state && state.question && post("answer", {id: state.question.id, choice: "no"});
document.addEventListener("keydown", (e) => { if (e.key === " " && e.target === document.body) { e.preventDefault(); post("estop"); } });

// ---- state ------------------------------------------------------------------------------------
function connectState() {
  const ws = new WebSocket(wsUrl("/api/ws"));
  ws.onopen = () => { const n = $("notice"); if (n.classList.contains("link")) { n.hidden = true; n.classList.remove("link"); } };
  ws.onmessage = (ev) => render(JSON.parse(ev.data));
  ws.onclose = () => {
    if (state && ENDED.has(state.status)) { $("status").title = "the run has ended"; return; }
    const n = $("notice");
    n.textContent = "connection to the robot lost: retrying (the robot stops by itself if you were driving)";
    n.classList.add("link"); n.hidden = false;
    setTimeout(connectState, 1000);
  };
}

function fmtTime(s) {
  if (s == null) return "-";
  s = Math.round(s);
  return s >= 60 ? Math.floor(s / 60) + " min " + (s % 60) + " s" : s + " s";
}

function render(s) {
  state = s;
  $("mission").textContent = s.mission;
  const st = $("status");
  st.textContent = s.estop && !ENDED.has(s.status) ? "e-stop" : s.status;
  st.className = "status " + s.status;
  // Ended: the outcome, and the step it ended in; paused, the state's step says so and names the step (both).
  const over = ENDED.has(s.status);
  $("step-label").textContent = over ? "" : "step:";
  $("step").textContent = over && s.ended_at ? `${s.step} · last step: ${s.ended_at}` : s.step;
  const p = s.progress || {};
  const frac = p.total ? Math.min(1, p.done / p.total) : 0;
  $("progress-fill").style.width = (ENDED.has(s.status) && s.status === "succeeded" ? 100 : frac * 100) + "%";
  $("progress-text").textContent = p.total ? `${p.done}/${p.total} steps` + (p.eta_s != null && p.done < p.total ? ` · ETA ${fmtTime(p.eta_s)}` : "")
                                            : `${p.done || 0} steps`;
  const b = s.battery;
  $("battery").textContent = b ? `battery ${b.volts.toFixed(1)} V (${Math.round(b.percent)} %)` : "battery -";
  $("battery").classList.toggle("low", !!b && b.percent < 20);
  $("clock").textContent = "t " + s.time_s.toFixed(1) + " s";
  const ended = ENDED.has(s.status);
  $("pause").disabled = ended || s.status === "paused";
  $("resume").disabled = ended || s.status !== "paused" || s.paused_by !== "operator";
  $("abort").disabled = ended;
  $("estop").disabled = ended;
  $("estop").classList.toggle("latched", s.estop);
  $("estop-reset").disabled = !s.estop || ended;
  const q = s.question;
  $("question").hidden = !q;
  if (q) $("question-text").textContent = q.text;
  const pose = s.pose;
  showPose(s);
  if (pose) {
    const last = trail[trail.length - 1];
    if (!last || Math.hypot(pose.x - last[0], pose.y - last[1]) > 0.05) trail.push([pose.x, pose.y]);
  }
  if (s.map_version !== mapVersion) { mapVersion = s.map_version; loadMap(); }
  renderTree(s.tree);
  renderEvents(s.events || []);
  renderTuning(s.tuning, ended);
  renderPhotos(s.photos, s.alert);
  mapDirty = true;
  if (over) endVideo(s);
}

// ---- live tuning -----------------------------------------------------------------------------------
// The knobs come from GET /api/tuning (title, unit, range, default, the profile's value) and again whenever the
// state's tuning.version changes; the state carries the values and which groups the running steps use. A slider
// sends POST /api/tuning {name, value} as it moves (at most every 100 ms, and once more where it stops): the run
// takes it at its next tick. A value the run refuses shows its answer (the range) as a notice.
const tuning = {knobs: new Map(), version: -1, loading: false, rows: new Map(), shown: "", line: [], lastLineT: null};
const GROUP_NAMES = {limits: "speed limits", line_follower: "line follower", collision_monitor: "collision monitor",
                     local_planner: "local planner", navigation: "navigation", localisation: "localisation"};
const fmtKnob = (k, v) => (k.integer ? String(Math.round(v)) : (+v).toFixed(Math.max(0, -Math.floor(Math.log10(k.step || 0.01)))))
                          + (k.unit ? " " + k.unit : "");
async function loadTuning(version) {
  if (tuning.loading) return;
  tuning.loading = true;
  try {
    const r = await fetch("/api/tuning", {headers: authHeaders(), cache: "no-store"});
    if (r.ok) {
      const t = await r.json();
      tuning.knobs = new Map(t.knobs.map((k) => [k.name, k]));
      tuning.version = version;
      tuning.shown = "";  // lay the sliders out again
      $("tuning-info").textContent = t.profile_file ? "profile: " + t.profile_file : "the knobs the running steps use";
    }
  } catch (e) { /* the next state tries again */ }
  tuning.loading = false;
}
function knobRow(k) {
  const box = $("knobs");
  const label = document.createElement("label");
  label.textContent = k.title; label.title = k.name; label.htmlFor = "knob-" + k.name;
  const input = document.createElement("input");
  input.type = "range"; input.id = "knob-" + k.name; input.dataset.testid = "knob-" + k.name; input.dataset.knob = k.name;
  input.min = k.min_exclusive ? k.min + k.step : k.min; input.max = k.max; input.step = k.step; input.value = k.value;
  const val = document.createElement("span");
  val.className = "val"; val.dataset.testid = "knob-value-" + k.name;
  const hint = document.createElement("div");
  hint.className = "hint";
  hint.textContent = `${k.range}` + (k.default != null ? ` · default ${fmtKnob(k, k.default)}` : "")
                     + ` · profile ${fmtKnob(k, k.profile)}`;
  let sentAt = 0, timer = null;
  const row = {input, val, sent: k.value};
  const send = () => {
    clearTimeout(timer); timer = null;
    const value = Number(input.value);
    if (value === row.sent) return;  // the change event where the last input already sent it
    sentAt = performance.now(); row.sent = value;
    post("tuning", {name: k.name, value});
  };
  input.addEventListener("input", () => {
    val.textContent = fmtKnob(k, input.value);
    const wait = 100 - (performance.now() - sentAt);
    if (wait <= 0) send(); else if (!timer) timer = setTimeout(send, wait);
  });
  input.addEventListener("change", send);
  box.append(label, input, val, hint);
  tuning.rows.set(k.name, row);
}
function renderTuning(t, ended) {
  $("tuning").hidden = !t;
  if (!t) return;
  if (t.version !== tuning.version) loadTuning(t.version);
  const active = new Set(t.active);
  const names = [...tuning.knobs.values()].filter((k) => active.has(k.group)).map((k) => k.name);
  const key = names.join(",");
  if (key !== tuning.shown) {  // the running steps changed (a line followed, a place driven to): other sliders
    $("knobs").textContent = "";
    tuning.rows.clear();
    let group = "";
    for (const name of names) {
      const k = tuning.knobs.get(name);
      if (k.group !== group) {
        group = k.group;
        const h = document.createElement("div");
        h.className = "group"; h.textContent = GROUP_NAMES[group] || group;
        $("knobs").append(h);
      }
      knobRow(k);
    }
    tuning.shown = key;
  }
  const changed = new Set(t.changed);
  for (const [name, row] of tuning.rows) {
    const v = t.values[name];
    if (v == null) continue;
    if (document.activeElement !== row.input) {  // never under the operator's finger
      row.input.value = v; row.sent = v; row.val.textContent = fmtKnob(tuning.knobs.get(name), v);
    }
    row.val.classList.toggle("changed", changed.has(name));
    row.input.disabled = ended;
  }
  $("tuning-save").disabled = ended || !changed.size;
  $("tuning-reset").disabled = ended || !changed.size;
  plotLine(t.line, active.has("line_follower"));
}
$("tuning-save").onclick = async () => {
  const a = await post("tuning/save");
  if (a.ok) notice(a.saved && a.saved.length ? `saved to ${a.profile_file}: ${a.saved.join(", ")}` : "nothing to save");
};
$("tuning-reset").onclick = () => post("tuning/reset");
// The line follower's error beside its gains: the detector's offset at the look-ahead (cm), the last 10 s.
function plotLine(line, following) {
  const box = $("line-plot-box");
  if (line && line.t !== tuning.lastLineT) {
    tuning.lastLineT = line.t;
    tuning.line.push([line.t, line.offset_m]);
    while (tuning.line.length && tuning.line[0][0] < line.t - 10) tuning.line.shift();
  }
  box.hidden = !following && !tuning.line.length;
  if (box.hidden) return;
  const c = $("line-plot"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  const pts = tuning.line;
  if (!pts.length) return;
  const t1 = pts[pts.length - 1][0], t0 = t1 - 10;
  const peak = Math.max(2, ...pts.filter((p) => p[1] != null).map((p) => Math.abs(p[1] * 100)));
  const y = (cm) => c.height / 2 - cm / peak * (c.height / 2 - 8), x = (t) => (t - t0) / 10 * c.width;
  g.strokeStyle = "#3a3f46"; g.beginPath(); g.moveTo(0, y(0)); g.lineTo(c.width, y(0)); g.stroke();
  g.strokeStyle = "#4aa3ff"; g.lineWidth = 2; g.beginPath();
  let open = false;
  for (const [t, off] of pts) {
    if (off == null) { open = false; continue; }  // the line out of sight: a gap
    if (open) g.lineTo(x(t), y(off * 100)); else g.moveTo(x(t), y(off * 100));
    open = true;
  }
  g.stroke();
  g.fillStyle = "#9aa0a6"; g.font = "11px system-ui";
  g.fillText(`±${peak.toFixed(1)} cm`, 4, 12);
  const last = pts[pts.length - 1][1];
  $("line-plot-info").textContent = "line error " + (last == null ? "(out of sight)" : (last * 100).toFixed(1) + " cm")
                                    + ", last 10 s";
}

// Which way the robot faces, in the words of the frame the map is drawn in. On a run with a position on Earth
// (a GPS fix) it is the compass heading, clockwise from north ("heading 90° E"); on a map or odometry run there is
// no north, so it is the yaw, counter-clockwise from the map's +x axis ("yaw 0° (+x)"), as the mission's map
// places and the plan are written. The word carries a tooltip saying which.
const COMPASS = ["N", "NE", "E", "SE", "S", "SW", "W", "NW"];
const AXES = ["+x", "+x+y", "+y", "−x+y", "−x", "−x−y", "−y", "+x−y"];
function onEarth(s) {  // a GPS fix, and no saved map whose frame the places are written in
  return !!(s.gps && s.gps.fix && !(mapLayers && mapLayers.saved_map));
}
function facing(s) {
  const p = s.pose;
  if (onEarth(s)) {
    const h = ((p.heading_deg % 360) + 360) % 360;
    return {word: "heading", text: `${h.toFixed(0)}° ${COMPASS[Math.round(h / 45) % 8]}`,
            title: "heading: compass degrees clockwise from north (0° N, 90° E)"};
  }
  let y = ((p.yaw_deg % 360) + 360) % 360;
  const axis = AXES[Math.round(y / 45) % 8];
  if (y > 180) y -= 360;
  return {word: "yaw", text: `${y.toFixed(0)}° (${axis})`,
          title: "yaw: degrees counter-clockwise from the map's +x axis (0° faces +x, 90° faces +y); no compass here"};
}
function showPose(s) {
  const el = $("pose-text"), pose = s.pose;
  if (!pose) { el.textContent = "pose -"; return; }
  const f = facing(s);
  const word = document.createElement("abbr");
  word.title = f.title;
  word.dataset.testid = "facing";
  word.textContent = f.word;
  el.replaceChildren(`x ${pose.x.toFixed(2)} m  y ${pose.y.toFixed(2)} m  `, word, ` ${f.text}  ` +
    `${s.speed_mps.toFixed(2)} m/s` + (s.gps ? `  GPS ${s.gps.sats ?? "?"} sats ±${s.gps.accuracy_m} m` : "  no GPS") +
    (s.teleop ? "  TELEOP" : ""));
  el.title = f.title;
}

let eventsKey = "";
function renderEvents(events) {
  const key = events.length ? events[events.length - 1].time_s + events[events.length - 1].text : "";
  if (key === eventsKey) return;
  eventsKey = key;
  const ol = $("events");
  ol.textContent = "";
  for (const e of events.slice().reverse()) {  // newest first
    const li = document.createElement("li");
    li.className = e.kind;
    const t = document.createElement("span"); t.className = "t"; t.textContent = e.time_s.toFixed(1) + " s";
    const k = document.createElement("span"); k.className = "k"; k.textContent = e.kind;
    li.append(t, k, document.createTextNode(e.text));
    li.title = e.text;
    ol.appendChild(li);
  }
}

// ---- photos and the alert's banner ----------------------------------------------------------------
// The state lists the newest photos ({name, time_s, url}, newest last) and the newest alert ({time_s, text, photo});
// the pictures come from GET /api/photos/NAME.jpg (the run folder's own JPEG). An <img> is only given a new address
// when its photo changes: the page does not fetch a picture again ten times a second.
let photosKey = "";
let alertKey = "";
let alertDismissed = "";
function photoSrc(url) { return withToken(url); }
function setPhoto(img, p) {
  const src = photoSrc(p.url);
  if (img.dataset.src !== src) { img.dataset.src = src; img.src = src; }
  img.dataset.name = p.name; img.dataset.time = p.time_s;
  img.alt = `photo ${p.name} at ${p.time_s.toFixed(1)} s`;
}
function openPhoto(img) {
  if (!img.dataset.src) return;
  $("photo-full").src = img.dataset.src;
  $("photo-full-caption").textContent = `${img.dataset.name} · ${Number(img.dataset.time).toFixed(1)} s`;
  $("photo-view").hidden = false;
}
function closePhoto() { $("photo-view").hidden = true; }
$("photo-latest").onclick = (e) => openPhoto(e.currentTarget);
$("alert-photo").onclick = (e) => openPhoto(e.currentTarget);
$("photo-view").onclick = closePhoto;
document.addEventListener("keydown", (e) => { if (e.key === "Escape") closePhoto(); });
$("alert-dismiss").onclick = () => { alertDismissed = alertKey; $("alert").hidden = true; };

function renderPhotos(photos, alert) {
  const shown = ((photos && photos.latest) || []).filter((p) => p.url);
  const key = (photos ? photos.count : 0) + ":" + shown.map((p) => p.url).join(",");
  if (key !== photosKey) {
    photosKey = key;
    $("photos").hidden = !shown.length;
    if (shown.length) {
      const newest = shown[shown.length - 1];
      setPhoto($("photo-latest"), newest);
      $("photo-caption").textContent = `${newest.name} · ${newest.time_s.toFixed(1)} s`;
      $("photos-info").textContent = `${photos.count} taken`;
      const strip = $("photo-strip");
      strip.textContent = "";
      for (const p of shown.slice(0, -1).reverse()) {  // the ones before the newest, newest first
        const img = document.createElement("img");
        setPhoto(img, p);
        img.title = `${p.name} · ${p.time_s.toFixed(1)} s`;
        img.onclick = () => openPhoto(img);
        strip.appendChild(img);
      }
    }
  }
  const aKey = alert ? alert.time_s + alert.text : "";
  if (aKey !== alertKey) {
    alertKey = aKey;
    $("alert").hidden = !alert || aKey === alertDismissed;
    if (alert) {
      $("alert-text").textContent = alert.text;
      $("alert-time").textContent = `at ${alert.time_s.toFixed(1)} s`;
      const img = $("alert-photo");
      img.hidden = !alert.photo;
      if (alert.photo) setPhoto(img, {name: alert.text, time_s: alert.time_s, url: alert.photo});
    }
  }
}

// ---- tree --------------------------------------------------------------------------------------
let treeIds = "";
const treeRows = new Map();
let foldDone = false;
$("show-global").onchange = () => { mapDirty = true; };
$("tree-fold").onclick = () => { foldDone = !foldDone; $("tree-fold").textContent = foldDone ? "unfold" : "fold done"; treeIds = ""; state && renderTree(state.tree); };

function renderTree(nodes) {
  const ids = nodes.map((n) => n.id).join(",");
  if (ids !== treeIds) buildTree(nodes, ids);
  const byId = new Map(nodes.map((n) => [n.id, n]));
  let tip = null;
  for (const n of nodes) {
    const row = treeRows.get(n.id);
    if (!row) continue;
    row.div.className = "node " + n.status;
    if (n.status === "running") { tip = n; }
  }
  // The running branch: from the deepest running node up to the root.
  for (const r of treeRows.values()) r.div.classList.remove("on-path");
  let deepest = null;
  for (const n of nodes) if (n.status === "running" && (!deepest || n.id.length >= deepest.id.length)) deepest = n;
  for (let n = deepest; n; n = n.parent != null ? byId.get(n.parent) : null) {
    const row = treeRows.get(n.id);
    if (row) { row.div.classList.add("on-path"); row.li.classList.remove("folded"); }
  }
  if (deepest && deepest.id !== renderTree.lastTip) {
    renderTree.lastTip = deepest.id;
    const row = treeRows.get(deepest.id);
    if (row) followInTree(row.div);
  }
  $("tree-info").textContent = `${nodes.length} nodes`;
}

// Scroll the tree panel, and only it, to show a row: scrollIntoView would scroll the page too (on a phone the
// question went under the header, on a desktop the panel titles). The row is kept in the part of the panel that is
// on the screen (the whole panel when little of it is), a third of the way down: the steps done above, the next below.
function followInTree(div) {
  const t = $("tree"), row = div.getBoundingClientRect(), box = t.getBoundingClientRect();
  let top = Math.max(box.top, $("top").getBoundingClientRect().bottom), bottom = Math.min(box.bottom, innerHeight);
  if (bottom - top < 3 * row.height) { top = box.top; bottom = box.bottom; }
  if (row.top < top || row.bottom > bottom) t.scrollTop += row.top - (top + (bottom - top) / 3);
}

function buildTree(nodes, ids) {
  treeIds = ids;
  treeRows.clear();
  const root = $("tree");
  root.textContent = "";
  const lists = new Map();
  const top = document.createElement("ul");
  root.appendChild(top);
  const children = new Map();
  for (const n of nodes) { if (n.parent != null) children.set(n.parent, (children.get(n.parent) || 0) + 1); }
  for (const n of nodes) {
    const li = document.createElement("li");
    const div = document.createElement("div");
    div.dataset.nodeId = n.id;
    const twist = document.createElement("span");
    twist.className = "twist";
    twist.textContent = children.get(n.id) ? "▾" : "·";
    twist.onclick = () => { li.classList.toggle("folded"); twist.textContent = li.classList.contains("folded") ? "▸" : "▾"; };
    const name = document.createElement("span");
    name.textContent = n.name;
    const kind = document.createElement("span");
    kind.className = "kind";
    kind.textContent = n.kind;
    div.append(twist, name, kind);
    li.appendChild(div);
    if (children.get(n.id)) {
      const ul = document.createElement("ul");
      li.appendChild(ul);
      lists.set(n.id, ul);
      if (foldDone && n.status !== "running" && n.parent != null) { li.classList.add("folded"); twist.textContent = "▸"; }
    }
    (n.parent != null && lists.get(n.parent) || top).appendChild(li);
    treeRows.set(n.id, {li, div});
  }
}

// ---- map -----------------------------------------------------------------------------------------
async function loadMap() {
  try {
    const r = await fetch("/api/map", {headers: authHeaders(), cache: "no-store"});
    if (!r.ok) return;
    mapLayers = await r.json();
    if (mapLayers.trail && mapLayers.trail.length > trail.length) trail = mapLayers.trail.slice();
    mapDirty = true;
  } catch (e) { /* the next state retries */ }
}

function mapBounds() {
  const xs = [], ys = [];
  const add = (p) => { if (p) { xs.push(p[0]); ys.push(p[1]); } };
  if (mapLayers) {
    for (const w of mapLayers.walls) { add([w[0], w[1]]); add([w[2], w[3]]); }
    for (const o of mapLayers.obstacles || []) (o.corners || o.path || [o.xy]).forEach(add);
    for (const t of mapLayers.track) t.points.forEach(add);
    for (const p of mapLayers.places) add(p.xy);
    for (const w of mapLayers.waypoints) add(w.xy);
    for (const f of mapLayers.fences) f.points.forEach(add);
    if (mapLayers.start) add([mapLayers.start.x, mapLayers.start.y]);
    const m = mapLayers.saved_map;
    if (m) {  // the saved map's four corners on the plan
      const c = Math.cos(m.yaw_rad), s = Math.sin(m.yaw_rad);
      for (const [u, v] of [[0, 0], [m.width_m, 0], [0, m.height_m], [m.width_m, m.height_m]]) {
        add([m.corner[0] + c * u - s * v, m.corner[1] + s * u + c * v]);
      }
    }
  }
  trail.forEach(add);
  if (state && state.pose) add([state.pose.x, state.pose.y]);
  if (!xs.length) return {x0: -5, x1: 5, y0: -5, y1: 5};
  const pad = 1.0, least = 6.0;  // metres: a robot that has not moved yet is not drawn a metre long
  let x0 = Math.min(...xs) - pad, x1 = Math.max(...xs) + pad, y0 = Math.min(...ys) - pad, y1 = Math.max(...ys) + pad;
  if (x1 - x0 < least) { const c = (x0 + x1) / 2; x0 = c - least / 2; x1 = c + least / 2; }
  if (y1 - y0 < least) { const c = (y0 + y1) / 2; y0 = c - least / 2; y1 = c + least / 2; }
  return {x0, x1, y0, y1};
}

function drawMap() {
  requestAnimationFrame(drawMap);
  if (!mapDirty) return;
  mapDirty = false;
  const c = $("map"), g = c.getContext("2d");
  const W = c.width, H = c.height;
  g.fillStyle = "#101214"; g.fillRect(0, 0, W, H);
  const b = mapBounds();
  const scale = Math.min(W / (b.x1 - b.x0), H / (b.y1 - b.y0));
  const ox = (W - scale * (b.x1 - b.x0)) / 2, oy = (H - scale * (b.y1 - b.y0)) / 2;
  const px = (x, y) => [ox + (x - b.x0) * scale, H - (oy + (y - b.y0) * scale)];  // ENU: north up
  // grid: 1 m, or 10 m when the plan is large
  const step = (b.x1 - b.x0) > 60 ? 10 : 1;
  g.strokeStyle = "#1d2126"; g.lineWidth = 1;
  for (let x = Math.ceil(b.x0 / step) * step; x <= b.x1; x += step) { const [a] = px(x, 0); g.beginPath(); g.moveTo(a, 0); g.lineTo(a, H); g.stroke(); }
  for (let y = Math.ceil(b.y0 / step) * step; y <= b.y1; y += step) { const [, a] = px(0, y); g.beginPath(); g.moveTo(0, a); g.lineTo(W, a); g.stroke(); }
  const poly = (pts, closed) => { g.beginPath(); pts.forEach((p, i) => { const [x, y] = px(p[0], p[1]); i ? g.lineTo(x, y) : g.moveTo(x, y); }); if (closed) g.closePath(); g.stroke(); };
  const ring = (xy, r) => { const [x, y] = px(xy[0], xy[1]); g.beginPath(); g.arc(x, y, Math.max(2, r * scale), 0, 2 * Math.PI); };
  const ob = state && state.obstacles;
  const walking = !!(ob && ob.persons);  // the persons where they are now come with the state
  if (mapLayers) {
    drawSavedMap(g, mapLayers.saved_map, px, scale, c);
    g.strokeStyle = "#9aa0a6"; g.lineWidth = 3;
    for (const w of mapLayers.walls) poly([[w[0], w[1]], [w[2], w[3]]]);
    // obstacles: boxes and posts filled grey; a person's path dotted (and where it sets off, until the state says
    // where it is)
    g.fillStyle = "#9aa0a655"; g.lineWidth = 2;
    for (const o of mapLayers.obstacles || []) {
      if (o.shape === "box") { g.strokeStyle = "#9aa0a6"; poly(o.corners, true); g.fill(); }
      else if (o.shape === "cylinder") { g.strokeStyle = "#9aa0a6"; ring(o.xy, o.radius_m); g.fill(); g.stroke(); }
      else if (o.shape === "person") {
        g.strokeStyle = "#c58af9"; g.setLineDash([2, 4]); poly(o.path); g.setLineDash([]);
        if (!walking) { ring(o.path[0], o.radius_m); g.stroke(); }
      }
    }
    g.strokeStyle = "#e0e0e0"; g.lineWidth = Math.max(1.5, 0.02 * scale);
    for (const t of mapLayers.track) poly(t.points, t.closed);
    for (const f of mapLayers.fences) {
      if (f.points.some((p) => !p)) continue;
      g.strokeStyle = f.keep === "out" ? "#e5534b" : "#4caf50"; g.lineWidth = 2; g.setLineDash([6, 4]); poly(f.points, true); g.setLineDash([]);
    }
    g.font = "12px sans-serif";
    for (const p of mapLayers.places) {
      if (!p.xy) continue;
      const [x, y] = px(p.xy[0], p.xy[1]);
      g.fillStyle = "#4aa3ff"; g.beginPath(); g.arc(x, y, 4, 0, 2 * Math.PI); g.fill();
      g.fillText(p.name, x + 6, y - 6);
    }
    const wps = mapLayers.waypoints.filter((w) => w.xy);
    if (wps.length) {
      g.strokeStyle = "#4aa3ff88"; g.lineWidth = 1.5; g.setLineDash([4, 4]); poly(wps.map((w) => w.xy)); g.setLineDash([]);
      for (const w of wps) {
        const [x, y] = px(w.xy[0], w.xy[1]);
        if (w.tolerance_m) { g.strokeStyle = "#4aa3ff"; g.beginPath(); g.arc(x, y, w.tolerance_m * scale, 0, 2 * Math.PI); g.stroke(); }
      }
    }
    if (mapLayers.start) {
      const [x, y] = px(mapLayers.start.x, mapLayers.start.y);
      g.strokeStyle = "#9aa0a6"; g.strokeRect(x - 5, y - 5, 10, 10);
    }
  }
  drawGlobalCostmap(g, ob && ob.global_costmap, px, scale, c);
  if (trail.length > 1) { g.strokeStyle = "#f2c744aa"; g.lineWidth = 2; poly(trail); }
  drawObstacles(g, ob, poly, ring, px, c);
  if (state && state.gps && state.gps.xy) {
    const [x, y] = px(state.gps.xy[0], state.gps.xy[1]);
    g.fillStyle = "#ff7ab412"; g.strokeStyle = "#ff7ab488"; g.lineWidth = 1;
    g.beginPath(); g.arc(x, y, Math.max(3, state.gps.accuracy_m * scale), 0, 2 * Math.PI); g.fill(); g.stroke();
    g.fillStyle = "#ff7ab4"; g.beginPath(); g.arc(x, y, 3, 0, 2 * Math.PI); g.fill();
  }
  if (state && state.pose) {
    const p = state.pose, yaw = p.yaw_deg * Math.PI / 180;
    const [x, y] = px(p.x, p.y);
    const r = Math.max(9, 0.15 * scale);
    g.save(); g.translate(x, y); g.rotate(-yaw);
    g.fillStyle = state.estop ? "#e5534b" : "#f2c744"; g.strokeStyle = "#000";
    g.beginPath(); g.moveTo(r, 0); g.lineTo(-r * 0.7, r * 0.6); g.lineTo(-r * 0.4, 0); g.lineTo(-r * 0.7, -r * 0.6); g.closePath();
    g.fill(); g.stroke(); g.restore();
  }
  // scale bar and north
  g.fillStyle = "#9aa0a6"; g.font = "12px sans-serif";
  const bar = step * scale; g.fillRect(10, H - 14, bar, 3); g.fillText(step + " m", 14 + bar, H - 9);
  const geo = state && onEarth(state);  // up is north on Earth; on a map it is the map's +y
  g.fillText(geo ? "N ↑" : "+y ↑", W - 36, 16);
  $("map-info").textContent = mapLayers && mapLayers.datum ? `ENU metres from ${mapLayers.datum.lat.toFixed(5)}, ${mapLayers.datum.lon.toFixed(5)}` : "ENU metres (odometry)";
}

// An image on the plan ({png, corner, yaw_rad, width_m, height_m}): decoded once per new png, placed by its
// lower-left corner and turned by its yaw on the plan. "WxH" in pixels once drawn, "" when not (yet).
function placedImage(cache, g, m, px, scale) {
  if (m.png !== cache.src) {
    cache.src = m.png; cache.image = new Image();
    cache.image.onload = () => { mapDirty = true; };
    cache.image.src = m.png;
  }
  const image = cache.image;
  if (!image.complete || !image.naturalWidth) return "";
  const [x, y] = px(m.corner[0], m.corner[1]);
  g.save(); g.translate(x, y); g.rotate(-m.yaw_rad); g.imageSmoothingEnabled = false;
  g.drawImage(image, 0, -m.height_m * scale, m.width_m * scale, m.height_m * scale);
  g.restore();
  return `${image.naturalWidth}x${image.naturalHeight}`;
}

// The mission's saved map (map:) under everything else; canvas.dataset.savedMap says it was drawn (the tests read it).
const savedMapCache = {src: "", image: null};
function drawSavedMap(g, m, px, scale, canvas) {
  canvas.dataset.savedMap = m ? placedImage(savedMapCache, g, m, px, scale) : "";
}

// The global costmap's marked cells (what the LiDAR has seen and go_to plans round), a faint layer over the maps,
// shown while the "global costmap" box is ticked; canvas.dataset.globalCostmap says it was drawn.
const globalCostmapCache = {src: "", image: null};
function drawGlobalCostmap(g, m, px, scale, canvas) {
  canvas.dataset.globalCostmap = m && $("show-global").checked ? placedImage(globalCostmapCache, g, m, px, scale) : "";
}

// What the robot sees and plans (the state's "obstacles", plan metres): the local costmap's occupied cells, the
// collision monitor's zones round the robot (the acting one bold and filled), the local planner's path, the
// LiDAR's returns, the persons where they are. What was drawn is counted on the canvas's data attributes (the tests read them).
const ZONE_COLOURS = {slow: "#ff9f1a", stop: "#e5534b"};
const ZONE_ACTIVE = {stop: new Set(["stop", "silent"]), slow: new Set(["slow", "approach"])};
function drawObstacles(g, ob, poly, ring, px, canvas) {
  const drawn = {zones: [], active: "", plan: 0, scan: 0, persons: 0, costmap: 0, path: 0};
  if (ob && ob.path) {  // the path planned on the saved map, or the way round on GPS, under what the robot sees now
    g.strokeStyle = "#4a7dff"; g.lineWidth = 3; g.setLineDash([]); poly(ob.path);
    drawn.path = ob.path.length;
  }
  if (ob && ob.costmap) {  // the cells an obstacle is in or the footprint would touch: where the planner will not go
    g.fillStyle = "#d04ae8bb";
    const side = Math.max(3, ob.costmap.resolution_m * (px(1, 0)[0] - px(0, 0)[0]));
    for (const p of ob.costmap.cells) { const [x, y] = px(p[0], p[1]); g.fillRect(x - side / 2, y - side / 2, side, side); }
    drawn.costmap = ob.costmap.cells.length;
  }
  if (ob && ob.zones) {
    for (const name of ["slow", "stop"]) {
      const z = ob.zones[name];
      if (!z) continue;
      const on = ZONE_ACTIVE[name].has(ob.zones.action);
      g.strokeStyle = ZONE_COLOURS[name]; g.lineWidth = on ? 3 : 1; g.setLineDash(on ? [] : [4, 3]);
      poly(z, true); g.setLineDash([]);
      if (on) { g.fillStyle = ZONE_COLOURS[name] + "40"; g.fill(); drawn.active = name; }
      drawn.zones.push(name);
    }
  }
  if (ob && ob.plan) {
    g.strokeStyle = ob.blocked ? "#e5534b" : "#3ddc84"; g.lineWidth = 3; poly(ob.plan);
    drawn.plan = ob.plan.length;
  }
  if (ob && ob.scan) {
    g.fillStyle = "#ff4d4d";
    for (const p of ob.scan) { const [x, y] = px(p[0], p[1]); g.fillRect(x - 1.5, y - 1.5, 3, 3); }
    drawn.scan = ob.scan.length;
  }
  if (ob && ob.persons) {
    g.fillStyle = "#c58af988"; g.strokeStyle = "#c58af9"; g.lineWidth = 2;
    for (const p of ob.persons) { ring(p, p[2]); g.fill(); g.stroke(); }
    drawn.persons = ob.persons.length;
  }
  canvas.dataset.zones = drawn.zones.join(",");
  canvas.dataset.zoneActive = drawn.active;
  canvas.dataset.planPoints = drawn.plan;
  canvas.dataset.scanPoints = drawn.scan;
  canvas.dataset.persons = drawn.persons;
  canvas.dataset.costmapCells = drawn.costmap;
  canvas.dataset.pathPoints = drawn.path;
  canvas.dataset.personsXy = ob && ob.persons ? ob.persons.map((p) => p[0].toFixed(2) + " " + p[1].toFixed(2)).join(",") : "";
}

// ---- video -------------------------------------------------------------------------------------
// JPEG frames are drawn as they come, the newest winning. H.264 (beastbt/live/console_video.py: header quality
// 0xFF01 keyframe, 0xFF02 delta) is decoded in order, from a keyframe on, by WebCodecs' VideoDecoder, or where
// there is none (WebCodecs needs a secure page: https, or localhost) by Media Source Extensions (each unit a
// fragment of an MP4, played by a hidden <video> whose frames are drawn here). The page says on opening whether
// it decodes H.264; one that cannot gets JPEG. videoStats.codec says which came last, .player how H.264 played.
const videoStats = {frames: 0, bytes: 0, ages: [], window: [], codec: "", drawn: 0, h264: "", player: ""};
window.beastbtVideoStats = videoStats;  // read by the benchmark and the tests
const H264_KEY = 0xFF01, H264_DELTA = 0xFF02;
const MSE_PROBE = 'video/mp4; codecs="avc1.42E01F"';
let h264Support = null;
// [true, "", "webcodecs" or "mse"], or [false, why].
async function h264Supported() {
  let why = window.isSecureContext ? "this browser has no WebCodecs"
    : "WebCodecs needs a secure page (https, or the console on localhost)";
  if (typeof VideoDecoder !== "undefined") {
    try {
      if ((await VideoDecoder.isConfigSupported({codec: "avc1.42E01F", optimizeForLatency: true})).supported) {
        return [true, "", "webcodecs"];
      }
      why = "WebCodecs here does not decode H.264";
    } catch (e) { why = String(e); }
  }
  if (window.MediaSource && MediaSource.isTypeSupported(MSE_PROBE)) return [true, "", "mse"];
  return [false, why + (window.MediaSource ? "; its MSE does not play H.264" : "; no MSE either")];
}
// The codec string WebCodecs wants (avc1.PPCCLL) from the keyframe's sequence parameter set.
function avc1Codec(data) {
  for (let i = 0; i + 6 < data.length; i++) {
    if (data[i] === 0 && data[i + 1] === 0 && data[i + 2] === 1 && (data[i + 3] & 0x1f) === 7) {
      const hex = (b) => b.toString(16).padStart(2, "0").toUpperCase();
      return "avc1." + hex(data[i + 4]) + hex(data[i + 5]) + hex(data[i + 6]);
    }
  }
  return null;
}
// The NAL units of an Annex B access unit, without their start codes.
function nalUnits(data) {
  const starts = [];
  for (let i = 0; i + 2 < data.length; i++) {
    if (data[i] === 0 && data[i + 1] === 0 && data[i + 2] === 1) { starts.push(i + 3); i += 2; }
  }
  return starts.map((s, k) => {
    let end = k + 1 < starts.length ? starts[k + 1] - 3 : data.length;
    while (k + 1 < starts.length && end > s && data[end - 1] === 0) end -= 1;  // a 4-byte start code's zero
    return data.subarray(s, end);
  });
}
// The picture's size from a sequence parameter set (ITU-T H.264 7.3.2.1.1), for the MP4's sample entry.
function spsSize(sps) {
  const r = []; let zeros = 0;
  for (const byte of sps) {  // the raw bits: without the emulation-prevention bytes
    if (zeros >= 2 && byte === 3) { zeros = 0; continue; }
    r.push(byte); zeros = byte === 0 ? zeros + 1 : 0;
  }
  let pos = 8;
  const bit = () => (r[pos >> 3] >> (7 - (pos++ & 7))) & 1;
  const bits = (n) => { let v = 0; for (let i = 0; i < n; i++) v = v * 2 + bit(); return v; };
  const ue = () => { let z = 0; while (!bit() && z < 32) z++; return 2 ** z - 1 + bits(z); };
  const se = () => { const k = ue(); return k & 1 ? (k + 1) / 2 : -k / 2; };
  const profile = bits(8); bits(16); ue();
  let chroma = 1;
  if ([100, 110, 122, 244, 44, 83, 86, 118, 128, 138, 139, 134, 135].includes(profile)) {
    chroma = ue(); if (chroma === 3) bit();
    ue(); ue(); bit();
    if (bit()) {
      for (let i = 0; i < (chroma !== 3 ? 8 : 12); i++) {
        if (!bit()) continue;
        let last = 8, next = 8;
        for (let j = 0; j < (i < 6 ? 16 : 64); j++) { if (next) next = (last + se() + 256) % 256; last = next || last; }
      }
    }
  }
  ue();
  const poc = ue();
  if (poc === 0) ue(); else if (poc === 1) { bit(); se(); se(); const n = ue(); for (let i = 0; i < n; i++) se(); }
  ue(); bit();
  const wMbs = ue() + 1, hUnits = ue() + 1, frameMbsOnly = bit();
  if (!frameMbsOnly) bit();
  bit();
  let crop = [0, 0, 0, 0];
  if (bit()) crop = [ue(), ue(), ue(), ue()];
  const cx = chroma === 0 || chroma === 3 ? 1 : 2, cy = (chroma === 1 ? 2 : 1) * (2 - frameMbsOnly);
  return [wMbs * 16 - cx * (crop[0] + crop[1]), (2 - frameMbsOnly) * hUnits * 16 - cy * (crop[2] + crop[3])];
}
// A fragmented MP4, just enough for MSE: an initialisation segment, then one fragment (moof + mdat) per picture.
function be(v, n) {  // v as n bytes, big-endian (up to 2^53)
  const a = new Uint8Array(n);
  for (let i = n - 1; i >= 0; i--) { a[i] = v % 256; v = Math.floor(v / 256); }
  return a;
}
const ascii = (t) => Uint8Array.from(t, (ch) => ch.charCodeAt(0));
function cat(...parts) {
  const out = new Uint8Array(parts.reduce((a, p) => a + p.length, 0));
  let o = 0;
  for (const p of parts) { out.set(p, o); o += p.length; }
  return out;
}
const box = (type, ...parts) => cat(be(8 + parts.reduce((a, p) => a + p.length, 0), 4), ascii(type), ...parts);
const fullBox = (type, version, flags, ...parts) => box(type, be(version, 1), be(flags, 3), ...parts);
function mp4Init(sps, pps, width, height) {
  const matrix = cat(be(0x10000, 4), be(0, 12), be(0x10000, 4), be(0, 12), be(0x40000000, 4));
  const avcC = box("avcC", Uint8Array.of(1, sps[1], sps[2], sps[3], 0xff, 0xe1), be(sps.length, 2), sps,
                   Uint8Array.of(1), be(pps.length, 2), pps);
  const avc1 = box("avc1", be(0, 6), be(1, 2), be(0, 16), be(width, 2), be(height, 2), be(0x480000, 4),
                   be(0x480000, 4), be(0, 4), be(1, 2), be(0, 32), be(0x18, 2), be(0xffff, 2), avcC);
  const stbl = box("stbl", fullBox("stsd", 0, 0, be(1, 4), avc1), fullBox("stts", 0, 0, be(0, 4)),
                   fullBox("stsc", 0, 0, be(0, 4)), fullBox("stsz", 0, 0, be(0, 8)), fullBox("stco", 0, 0, be(0, 4)));
  const minf = box("minf", fullBox("vmhd", 0, 1, be(0, 8)),
                   box("dinf", fullBox("dref", 0, 0, be(1, 4), fullBox("url ", 0, 1))), stbl);
  const mdia = box("mdia", fullBox("mdhd", 0, 0, be(0, 8), be(90000, 4), be(0, 4), be(0x55c4, 2), be(0, 2)),
                   fullBox("hdlr", 0, 0, be(0, 4), ascii("vide"), be(0, 12), ascii("video"), be(0, 1)), minf);
  const tkhd = fullBox("tkhd", 0, 3, be(0, 8), be(1, 4), be(0, 8), be(0, 8), be(0, 8), matrix,
                       be(width * 65536, 4), be(height * 65536, 4));
  const mvhd = fullBox("mvhd", 0, 0, be(0, 8), be(1000, 4), be(0, 4), be(0x10000, 4), be(0x100, 2), be(0, 10),
                       matrix, be(0, 24), be(2, 4));
  const mvex = box("mvex", fullBox("trex", 0, 0, be(1, 4), be(1, 4), be(0, 12)));
  return cat(box("ftyp", ascii("isom"), be(512, 4), ascii("isomiso2avc1mp41")),
             box("moov", mvhd, box("trak", tkhd, mdia), mvex));
}
function mp4Fragment(seq, time, duration, sample, key) {
  const moof = (offset) => box("moof", fullBox("mfhd", 0, 0, be(seq, 4)), box("traf",
    fullBox("tfhd", 0, 0x020000, be(1, 4)), fullBox("tfdt", 1, 0, be(time, 8)),
    fullBox("trun", 0, 0x000701, be(1, 4), be(offset, 4), be(duration, 4), be(sample.length, 4),
            be(key ? 0x02000000 : 0x01010000, 4))));
  return cat(moof(moof(0).length + 8), box("mdat", sample));
}
// Plays H.264 units through MSE; each frame the <video> shows is drawn on the canvas with its overlay.
function msePlayer(refuse) {
  const video = document.createElement("video");
  video.muted = true; video.playsInline = true; video.autoplay = true;
  video.style.cssText = "position:fixed;left:0;top:0;width:2px;height:2px;opacity:0;pointer-events:none";
  document.body.appendChild(video);
  const ms = new MediaSource();
  video.addEventListener("error", () => refuse(`MSE could not play the H.264: ${video.error && video.error.message}`));
  video.src = URL.createObjectURL(ms);
  const p = {sb: null, queue: [], seq: 0, time: 0, lastMs: null, meta: [], codec: "", open: false};
  const pump = () => {
    if (!p.sb || p.sb.updating || ms.readyState !== "open") return;
    const b = video.buffered;
    if (b.length && video.currentTime - b.start(0) > 10) { p.sb.remove(0, video.currentTime - 5); return; }
    if (p.queue.length) p.sb.appendBuffer(p.queue.shift());
    if (b.length && b.end(b.length - 1) - video.currentTime > 0.5) video.currentTime = b.end(b.length - 1) - 0.05;
  };
  ms.addEventListener("sourceopen", () => { p.open = true; pump(); });
  const draw = (now, md) => {
    const t = Math.round(md.mediaTime * 90000);
    let m = null;
    for (const [ticks, meta] of p.meta) { if (ticks <= t + 1) m = meta; else break; }
    if (m) showFrame(video, video.videoWidth, video.videoHeight, m.overlay, m.capturedMs, H264_KEY, "h264");
    video.requestVideoFrameCallback(draw);
  };
  video.requestVideoFrameCallback(draw);
  return {
    push(data, key, overlay, capturedMs) {
      const units = nalUnits(data);
      if (!p.sb) {
        if (!key || !p.open) return;  // waits for a keyframe, with its SPS and PPS
        const sps = units.find((u) => (u[0] & 0x1f) === 7), pps = units.find((u) => (u[0] & 0x1f) === 8);
        if (!sps || !pps) return;
        p.codec = avc1Codec(data);
        const type = `video/mp4; codecs="${p.codec}"`;
        if (!MediaSource.isTypeSupported(type)) { refuse(`this browser's MSE does not play ${p.codec}`); return; }
        const [w, h] = spsSize(sps);
        p.sb = ms.addSourceBuffer(type);
        p.sb.mode = "segments";
        p.sb.addEventListener("updateend", pump);
        p.sb.addEventListener("error", () => refuse("MSE could not play the H.264"));
        p.queue.push(mp4Init(sps, pps, w, h));
      }
      const duration = Math.round(90 * (p.lastMs === null ? 66 : Math.min(500, Math.max(5, capturedMs - p.lastMs))));
      p.lastMs = capturedMs;
      const sample = cat(...units.filter((u) => ![7, 8, 9].includes(u[0] & 0x1f)).flatMap((u) => [be(u.length, 4), u]));
      p.meta.push([p.time, {overlay, capturedMs}]);
      if (p.meta.length > 200) p.meta.shift();
      p.seq += 1;
      p.queue.push(mp4Fragment(p.seq, p.time, duration, sample, key));
      p.time += duration;
      pump();
      video.play().catch(() => {});
    },
    close() { try { video.pause(); video.remove(); URL.revokeObjectURL(video.src); } catch (e) { /* gone */ } },
  };
}
// One decoded frame (an ImageBitmap or a VideoFrame) on the canvas, with its overlay; the stats for the tests.
function showFrame(image, width, height, overlay, capturedMs, quality, codec) {
  const c = $("video");
  // The camera's own frame, as large as the canvas (16:9, 1280 wide) holds it with its own shape: a 4:3
  // camera gets black bars. The overlay is drawn at the canvas's size, so it stays sharp on a small picture.
  const g = c.getContext("2d");
  const fit = Math.min(c.width / width, c.height / height);
  const w = width * fit, h = height * fit, x = (c.width - w) / 2, y = (c.height - h) / 2;
  if (w < c.width || h < c.height) { g.fillStyle = "#000"; g.fillRect(0, 0, c.width, c.height); }
  g.drawImage(image, x, y, w, h);
  if (overlay) drawOverlay(g, x, y, w, h, overlay, c.width);
  videoStats.detections = state && state.detections ? drawDetections(g, x, y, w, h, state.detections) : 0;
  videoStats.overlay = overlay; videoStats.quality = quality;  // 0: the camera's own JPEG; 0xFF01/2: H.264
  videoStats.codec = codec; videoStats.drawn += 1; videoStats.size = [width, height];
  if (state && ENDED.has(state.status)) { endVideo(state); return; }  // a frame sent before the end
  const age = Date.now() - capturedMs;
  videoStats.ages.push(age);
  if (videoStats.ages.length > 500) videoStats.ages.shift();
  const kbps = videoStats.window.reduce((a, w) => a + w[1], 0) * 8 / 1000;
  $("video-info").textContent = `${videoStats.window.length} fps · ${(kbps / 1000).toFixed(2)} Mbit/s · ` +
    `${Math.round(age)} ms old` + (codec === "h264" ? " · H.264" : "");
}
function connectVideo() {
  const ws = new WebSocket(wsUrl("/api/video"));
  ws.binaryType = "arraybuffer";
  let busy = false;
  const h264 = {decoder: null, codec: "", meta: new Map(), failed: false, player: "", mse: null};
  const refuseH264 = (why) => {  // from now on this viewer gets JPEG
    h264.failed = true; videoStats.h264 = why;
    if (h264.decoder && h264.decoder.state !== "closed") h264.decoder.close();
    if (h264.mse) h264.mse.close();
    if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({accept: ["jpeg"], why}));
  };
  ws.onopen = async () => {
    const [ok, why, player] = await (h264Support || (h264Support = h264Supported()));
    videoStats.h264 = ok ? "" : why;
    h264.player = videoStats.player = ok ? player : "";
    const said = ok ? {accept: ["h264", "jpeg"]} : {accept: ["jpeg"], why};
    if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(said));
  };
  const decodeH264 = (buf, view, overlayLength, capturedMs, quality) => {
    const data = new Uint8Array(buf, 16 + overlayLength);
    const key = quality === H264_KEY;
    if (h264.failed) return;
    if (h264.player === "mse") {
      const text = overlayLength ? new TextDecoder().decode(new Uint8Array(buf, 16, overlayLength)) : "";
      const overlay = text ? JSON.parse(text) : null;
      if (!h264.mse) h264.mse = msePlayer(refuseH264);
      h264.mse.push(data, key, overlay, capturedMs);
      return;
    }
    if (key) {
      const codec = avc1Codec(data);
      if (codec && (codec !== h264.codec || !h264.decoder || h264.decoder.state === "closed")) {
        if (h264.decoder && h264.decoder.state !== "closed") h264.decoder.close();
        h264.codec = codec;
        h264.decoder = new VideoDecoder({
          output: (frame) => {
            const m = h264.meta.get(frame.timestamp) || {overlay: null, capturedMs: Date.now()};
            h264.meta.delete(frame.timestamp);
            try {
              showFrame(frame, frame.displayWidth, frame.displayHeight, m.overlay, m.capturedMs, H264_KEY, "h264");
            } finally { frame.close(); }
          },
          error: (e) => refuseH264(`this browser cannot decode ${codec}: ${e.message || e}`),
        });
        h264.decoder.configure({codec, optimizeForLatency: true});
      }
    }
    if (!h264.decoder || h264.decoder.state !== "configured") return;  // waits for a keyframe
    const seq = view.getUint32(8, true);
    const overlay = overlayLength ? JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 16, overlayLength))) : null;
    h264.meta.set(seq, {overlay, capturedMs});
    if (h264.meta.size > 100) h264.meta.delete(h264.meta.keys().next().value);
    h264.decoder.decode(new EncodedVideoChunk({type: key ? "key" : "delta", timestamp: seq, data}));
  };
  ws.onmessage = async (ev) => {
    if (typeof ev.data === "string") { $("video-info").textContent = ev.data; return; }  // why there is no video
    const buf = ev.data;
    const view = new DataView(buf);
    const capturedMs = view.getFloat64(0, true);
    const quality = view.getUint16(12, true);
    const overlayLength = view.getUint16(14, true);  // header: time f64, seq u32, quality u16, overlay length u16
    const now = Date.now();
    videoStats.frames += 1; videoStats.bytes += buf.byteLength;
    videoStats.window.push([now, buf.byteLength]);
    while (videoStats.window.length && now - videoStats.window[0][0] > 1000) videoStats.window.shift();
    if (quality >= 0xFF00) {  // H.264: every unit is decoded, in order (a skipped one breaks the ones after it)
      try { decodeH264(buf, view, overlayLength, capturedMs, quality); } catch (e) { refuseH264(String(e)); }
      return;
    }
    if (busy) return;  // still drawing the last one: the newest wins
    busy = true;
    try {
      const overlay = overlayLength
        ? JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 16, overlayLength))) : null;
      const bitmap = await createImageBitmap(new Blob([new Uint8Array(buf, 16 + overlayLength)], {type: "image/jpeg"}));
      showFrame(bitmap, bitmap.width, bitmap.height, overlay, capturedMs, quality, "jpeg");
      bitmap.close();
    } catch (e) { /* a frame that does not decode is skipped */ }
    busy = false;
  };
  ws.onclose = () => {
    if (h264.decoder && h264.decoder.state !== "closed") h264.decoder.close();
    if (h264.mse) h264.mse.close();
    if (!(state && ENDED.has(state.status))) setTimeout(connectVideo, 1000);
  };
}

// What the run sends with each frame (beastbt/live/console_video.py overlay_of): a caption, and the detected
// line, its target, a junction and a line end as fractions of the picture.
function drawOverlay(g, x0, y0, w, h, o, width) {
  const unit = Math.max(1, Math.round(w / 320));
  const at = (p) => [x0 + p[0] * w, y0 + p[1] * h];
  g.lineCap = "round"; g.lineJoin = "round";
  if (o.line && o.line.length >= 2) {
    g.strokeStyle = "rgb(0,220,0)"; g.lineWidth = 2 * unit; g.beginPath();
    o.line.forEach((p, i) => { const [x, y] = at(p); if (i) g.lineTo(x, y); else g.moveTo(x, y); });
    g.stroke();
  }
  if (o.target && o.target.length) {
    const [x, y] = at(o.target[0]);
    g.strokeStyle = "rgb(255,0,0)"; g.lineWidth = 2 * unit;
    g.beginPath(); g.arc(x, y, 5 * unit, 0, 2 * Math.PI); g.stroke();
  }
  const cross = (p, colour, r, tilted) => {
    const [x, y] = at(p); g.strokeStyle = colour; g.lineWidth = 2 * unit; g.beginPath();
    if (tilted) { g.moveTo(x - r, y - r); g.lineTo(x + r, y + r); g.moveTo(x - r, y + r); g.lineTo(x + r, y - r); }
    else { g.moveTo(x - r, y); g.lineTo(x + r, y); g.moveTo(x, y - r); g.lineTo(x, y + r); }
    g.stroke();
  };
  if (o.junction && o.junction.length) cross(o.junction[0], "rgb(255,0,255)", 8 * unit, false);
  if (o.end && o.end.length) cross(o.end[0], "rgb(255,128,0)", 6 * unit, true);
  const lines = o.caption || [];
  if (!lines.length) return;
  const size = Math.max(12, Math.round(width / 45)), step = Math.round(size * 1.35);
  g.fillStyle = "rgba(0,0,0,0.5)"; g.fillRect(0, 0, width, step * lines.length + step / 3);
  g.fillStyle = "#ffffff"; g.font = `${size}px sans-serif`;
  lines.forEach((text, i) => g.fillText(text, 6, step * (i + 1) - step / 4));
}

// What the camera's detectors found in the newest frame they looked at (state.detections: beastbt/vision/
// detection_feed.py; pixels of a frame `size` wide and high): tag and QR outlines, the colour blob's box, the
// moving region's box, each labelled. Returns how many things it drew (videoStats.detections, for the tests).
function drawDetections(g, x0, y0, w, h, d) {
  const sx = w / d.size[0], sy = h / d.size[1], unit = Math.max(1, Math.round(w / 320));
  const size = Math.max(12, 8 * unit);
  let drawn = 0;
  const shape = (points, colour, label) => {
    g.strokeStyle = colour; g.lineWidth = 2 * unit; g.beginPath();
    points.forEach((p, i) => { const x = x0 + p[0] * sx, y = y0 + p[1] * sy; if (i) g.lineTo(x, y); else g.moveTo(x, y); });
    g.closePath(); g.stroke();
    const left = Math.min(...points.map((p) => p[0])), top = Math.min(...points.map((p) => p[1]));
    g.font = `${size}px sans-serif`;
    const tx = x0 + left * sx, ty = Math.max(y0 + size + 2, y0 + top * sy - 4);
    g.fillStyle = "rgba(0,0,0,0.6)"; g.fillRect(tx - 2, ty - size, g.measureText(label).width + 4, size + 4);
    g.fillStyle = colour; g.fillText(label, tx, ty);
    drawn += 1;
  };
  const box = (b) => [[b[0], b[1]], [b[0] + b[2], b[1]], [b[0] + b[2], b[1] + b[3]], [b[0], b[1] + b[3]]];
  const COLOURS = {red: "rgb(255,60,60)", green: "rgb(60,255,60)", blue: "rgb(90,140,255)", yellow: "rgb(255,240,30)"};
  (d.tags || []).forEach((t) => shape(t.corners, "rgb(30,230,60)", `tag ${t.id} ${t.distance_m.toFixed(2)} m`));
  (d.qr || []).forEach((q) => shape(q.corners, "rgb(0,200,255)", `qr ${q.text}`));
  (d.colour || []).forEach((b) => shape(box(b.box), COLOURS[b.name] || "rgb(255,60,255)",
                                       `${b.name} ${(b.area_frac * 100).toFixed(1)} %`));
  const m = d.motion;
  if (m && m.box && m.warm) shape(box(m.box), m.moving ? "rgb(255,140,0)" : "rgba(255,215,80,0.6)",
                                  `motion ${(m.area_frac * 100).toFixed(1)} %`);
  return drawn;
}

// At the end no frame comes any more: the last one (captioned "running") gets a band that says the run ended.
function endVideo(s) {
  const c = $("video"), g = c.getContext("2d");
  const lines = [`ended: ${s.status} at t ${s.time_s.toFixed(1)} s`, `last step: ${s.ended_at || "-"}`];
  const text = lines.join(" · ");
  const size = Math.max(14, Math.round(c.height / 16));
  g.fillStyle = "#101214"; g.fillRect(0, 0, c.width, Math.round(size * 3));  // over the caption (two lines of text)
  g.fillStyle = s.status === "succeeded" ? "#4caf50" : "#e5534b"; g.font = `bold ${size}px sans-serif`;
  g.fillText(lines[0], size * 0.5, size * 1.25);
  g.fillStyle = "#ffffff"; g.font = `${size}px sans-serif`;
  g.fillText(lines[1], size * 0.5, size * 2.6);
  c.dataset.ended = text;  // what the band says, for the tests
  $("video-info").textContent = "the run has ended";
}

// ---- driving: the on-page joystick and the browser's gamepad ---------------------------------------
const stick = {linear: 0, angular: 0, held: false, source: null};
let lastSend = 0;
function sendStick(force) {
  const now = performance.now();
  if (!force && now - lastSend < 100) return;
  lastSend = now;
  post("teleop", {linear: stick.linear, angular: stick.angular, deadman: stick.held});
}
setInterval(() => { if (stick.held) sendStick(true); }, 100);  // keep the deadman alive while held

const pad = $("joystick"), knob = $("knob");
function padMove(ev) {
  const r = pad.getBoundingClientRect();
  const cx = r.left + r.width / 2, cy = r.top + r.height / 2, R = r.width / 2 - 35;
  let dx = ev.clientX - cx, dy = ev.clientY - cy;
  const d = Math.hypot(dx, dy);
  if (d > R) { dx *= R / d; dy *= R / d; }
  knob.style.left = (r.width / 2 - 35 + dx) + "px"; knob.style.top = (r.height / 2 - 35 + dy) + "px";
  stick.linear = +(-dy / R).toFixed(3); stick.angular = +(-dx / R).toFixed(3);
}
function padRelease() {
  if (stick.source !== "pad") return;
  pad.classList.remove("active");
  knob.style.left = "75px"; knob.style.top = "75px";
  Object.assign(stick, {linear: 0, angular: 0, held: false, source: null});
  sendStick(true);
  $("drive-info").textContent = "hold the pad to drive";
}
pad.addEventListener("pointerdown", (ev) => {
  pad.setPointerCapture(ev.pointerId);
  pad.classList.add("active");
  stick.held = true; stick.source = "pad";
  padMove(ev); sendStick(true);
  $("drive-info").textContent = "driving: release to stop";
});
pad.addEventListener("pointermove", (ev) => { if (stick.source === "pad") { padMove(ev); sendStick(false); } });
pad.addEventListener("pointerup", padRelease);
pad.addEventListener("pointercancel", padRelease);
pad.addEventListener("lostpointercapture", padRelease);
window.addEventListener("blur", () => { padRelease(); if (stick.source === "gamepad") gamepadRelease(); });

const DEADMAN_BUTTON = 4;  // LB on the standard mapping, as teleop_twist_joy's enable button
function gamepadRelease() { Object.assign(stick, {linear: 0, angular: 0, held: false, source: null}); sendStick(true); }
function pollGamepad() {
  requestAnimationFrame(pollGamepad);
  const pads = navigator.getGamepads ? Array.from(navigator.getGamepads()).filter(Boolean) : [];
  const gp = pads[0];
  if (!gp) { if (stick.source === "gamepad") gamepadRelease(); return; }
  const held = !!(gp.buttons[DEADMAN_BUTTON] && gp.buttons[DEADMAN_BUTTON].pressed);
  $("gamepad-info").textContent = `gamepad: ${gp.id.slice(0, 40)}${held ? " · driving" : " · hold LB to drive"}`;
  const dz = (v) => Math.abs(v) < 0.08 ? 0 : v;
  if (held && stick.source !== "pad") {
    stick.source = "gamepad"; stick.held = true;
    stick.linear = +(-dz(gp.axes[1] || 0)).toFixed(3); stick.angular = +(-dz(gp.axes[0] || 0)).toFixed(3);
    sendStick(false);
  } else if (!held && stick.source === "gamepad") {
    gamepadRelease();
  }
}

connectState();
connectVideo();
loadMap();
requestAnimationFrame(drawMap);
requestAnimationFrame(pollGamepad);
