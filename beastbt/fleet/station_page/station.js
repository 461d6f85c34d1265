// beastbt station: the robots' table (those that need attention first), the map, stop all, and missions sent by
// a file picker (a tablet has no drag and drop) or by a drop on a robot's row.
"use strict";
const $ = (id) => document.getElementById(id);
const COLOURS = {running: "#f2c744", paused: "#4aa3ff", succeeded: "#4caf50", failed: "#e5534b",
                 aborted: "#e5534b", lost: "#777", idle: "#9aa0a6"};
const ENDED = new Set(["idle", "succeeded", "failed", "aborted"]);
/** How long a success stays in the notice (ms); an error stays until the next news. */
const OK_FOR_MS = 8000;
let robots = [];
let noticeTimer = 0;
let pickFor = null;  // the robot whose Send mission… button opened the file picker

/** One line of news under the header: `kind` "ok" (green, fades) or "error" (red, stays); no text hides it. */
function notice(text, kind) {
  const n = $("notice");
  clearTimeout(noticeTimer);
  n.textContent = text || "";
  n.className = "notice " + (kind || "error");
  n.dataset.kind = kind || "error";
  n.hidden = !text;
  if (text && kind === "ok") noticeTimer = setTimeout(() => { n.hidden = true; }, OK_FOR_MS);
}

async function post(path, body, type) {
  let r;
  try {
    r = await fetch(path, {method: "POST", headers: {"Content-Type": type || "application/json"},
                           body: body === undefined ? "{}" : body});
  } catch (e) {
    notice("the station does not answer: " + e.message, "error");
    return {};
  }
  let answer = {};
  try { answer = await r.json(); } catch (e) { answer = {error: r.statusText}; }
  if (!r.ok) notice((answer.error || "refused") + (answer.errors ? "\n" + answer.errors : ""), "error");
  else notice("");
  return answer;
}

function cell(row, text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  row.appendChild(td);
  return td;
}

function button(parent, label, action, opts) {
  const b = document.createElement("button");
  b.textContent = label;
  b.addEventListener("click", action);
  if (opts && opts.control) b.dataset.control = opts.control;
  if (opts && opts.cls) b.className = opts.cls;
  if (opts && opts.disabled) { b.disabled = true; b.title = opts.why || ""; }
  parent.appendChild(b);
  return b;
}

const DONE = {pause: "paused", resume: "resumed", abort: "aborted", estop: "e-stop latched",
              estop_reset: "e-stop reset", answer: "answer sent"};

function control(name, c, body) {
  return () => post(`/api/robots/${encodeURIComponent(name)}/${c}`, body === undefined ? "{}" : JSON.stringify(body))
    .then((a) => { if (a.ok) notice(`${name}: ${DONE[c] || c}`, "ok"); });
}

function sendMission(name, file) {
  const zip = file.name.toLowerCase().endsWith(".zip");
  file.arrayBuffer().then((data) => post(`/api/robots/${encodeURIComponent(name)}/mission`, data,
                                         zip ? "application/zip" : "application/yaml"))
    .then((a) => { if (a.ok) notice(`${name}: mission '${a.started}' started`, "ok"); });
}

$("mission-file").addEventListener("change", (e) => {
  const file = e.target.files[0];
  const name = pickFor;
  pickFor = null;
  e.target.value = "";  // the same file may be sent again
  if (file && name) sendMission(name, file);
});

/** The robot's console address if the page may link it: http(s) only, with no user or password in it. The station
 * has checked it is on the robot's own address (docs/fleet.md); this is the page's own guard. */
function consoleHref(r) {
  if (typeof r.console_url !== "string") return null;
  let url;
  try { url = new URL(r.console_url); } catch (e) { return null; }
  if (url.protocol !== "http:" && url.protocol !== "https:") return null;
  if (url.username || url.password) return null;
  return url.href;
}

function nameCell(row, r) {
  const td = cell(row, "");
  const href = consoleHref(r);
  if (href) {
    const a = document.createElement("a");
    a.href = href; a.target = "_blank"; a.rel = "noopener noreferrer"; a.textContent = r.name;
    a.title = `the robot's operator console: ${href}`;
    a.dataset.testid = "console-link";
    td.appendChild(a);
    return;
  }
  td.append(r.name);
  if (typeof r.console_url === "string" || r.console_url_problem) {  // shown, never linked
    const note = document.createElement("span");
    note.className = "console-text";
    note.dataset.testid = "console-text";
    note.textContent = typeof r.console_url === "string" ? `console (not linked): ${r.console_url.slice(0, 200)}`
      : "console not linked";
    note.title = r.console_url_problem || "only an http:// or https:// address on the robot itself is linked";
    td.appendChild(note);
  }
}

function statusCell(row, r) {
  const td = cell(row, "", "status-cell");
  const badge = document.createElement("span");
  const estop = r.estop && r.alive;
  const status = r.question && r.alive ? "question" : r.status;
  badge.className = "status " + (estop ? "estop" : status);
  badge.dataset.testid = "status";
  badge.textContent = estop ? "E-STOPPED" : status;
  if (estop) badge.title = `the e-stop is latched (the robot is ${status}): Reset e-stop to let it move again`;
  td.appendChild(badge);
}

function actionsCell(row, r) {
  const td = cell(row, "", "actions");
  const box = document.createElement("div");
  box.className = "buttons";
  td.appendChild(box);
  if (!r.alive) {  // nothing reaches a lost robot: its controls are shown, off
    const why = "this robot is lost: nothing reaches it until it is back on the fleet";
    button(box, "Send mission…", () => {}, {control: "mission", disabled: true, why});
    button(box, "E-stop", () => {}, {control: "estop", cls: "estop", disabled: true, why});
    return;
  }
  if (r.question) {
    const ask = document.createElement("span");
    ask.className = "ask";
    ask.textContent = r.question.text;
    box.appendChild(ask);
    for (const choice of r.question.choices) {
      button(box, choice, control(r.name, "answer", {id: r.question.id, choice}), {control: "answer"});
    }
  }
  if (r.status === "running") button(box, "Pause", control(r.name, "pause"), {control: "pause"});
  if (r.status === "paused") button(box, "Resume", control(r.name, "resume"), {control: "resume"});
  if (r.status === "running" || r.status === "paused") button(box, "Abort", control(r.name, "abort"), {control: "abort"});
  if (ENDED.has(r.status) && !r.estop) {
    button(box, "Send mission…", () => { pickFor = r.name; $("mission-file").click(); }, {control: "mission"});
  }
  if (r.estop) button(box, "Reset e-stop", control(r.name, "estop_reset"), {control: "estop_reset"});
  button(box, "E-stop", control(r.name, "estop"), {control: "estop", cls: "estop"});
}

/** The robot's newest alert (a mission's `alert` step) under its mission, the earlier ones in its tooltip. */
function alertsIn(td, alerts) {
  if (!alerts.length) return;
  const newest = alerts[alerts.length - 1];
  const line = document.createElement("div");
  line.className = "alert";
  line.dataset.testid = "alert";
  line.textContent = `alert: ${newest.text} (t ${Number(newest.time_s).toFixed(1)} s)` +
    (alerts.length > 1 ? ` · ${alerts.length - 1} earlier` : "");
  line.title = alerts.map((a) => `t ${Number(a.time_s).toFixed(1)} s: ${a.text}`).join("\n");
  td.appendChild(line);
}

/** The robot's newest photo (a mission's `photo` step, a JPEG of at most 100 kB the robot sent) under its mission:
 * a thumbnail that opens the picture itself in a tab of its own. */
function photoIn(td, photo) {
  if (!photo) return;
  const box = document.createElement("a");
  box.className = "photo";
  box.href = photo.url;
  box.target = "_blank";
  box.rel = "noopener";
  box.title = `photo ${photo.name} at t ${Number(photo.time_s).toFixed(1)} s (${Math.round(photo.bytes / 1000)} kB)`;
  const img = document.createElement("img");
  img.src = photo.url;
  img.alt = `photo ${photo.name}`;
  img.dataset.testid = "photo";
  const cap = document.createElement("span");
  cap.textContent = `photo ${photo.name} (t ${Number(photo.time_s).toFixed(1)} s)`;
  box.append(img, cap);
  td.appendChild(box);
}

let drawnKey = "";

/** The table and the maps, drawn again only when something but the "seen" times changed (a button under a finger
 * is not replaced twice a second); the "seen" cells are updated in place. */
function render() {
  const key = JSON.stringify(robots.map((r) => ({...r, last_seen_s: null})));
  if (key === drawnKey) {
    for (const r of robots) {
      const seen = document.querySelector(`tr[data-robot="${CSS.escape(r.name)}"] td.seen`);
      if (seen) seen.textContent = r.last_seen_s === null ? "-" : `${r.last_seen_s.toFixed(1)} s`;
    }
    return;
  }
  drawnKey = key;
  const body = $("robots").tBodies[0];
  body.textContent = "";
  for (const r of robots) {
    const row = document.createElement("tr");
    row.dataset.robot = r.name;
    row.classList.toggle("lost", !r.alive);
    row.classList.toggle("estopped", !!(r.estop && r.alive));
    nameCell(row, r);
    statusCell(row, r);
    const last = r.last_run ? ` (last: ${r.last_run.mission} ${r.last_run.status})` : "";
    const doing = cell(row, (r.mission ? `${r.mission}: ${r.step || "-"}` : "-") + last);
    alertsIn(doing, r.alerts || []);
    photoIn(doing, r.photo);
    const p = r.progress;
    cell(row, p ? `${p.done}/${p.total}` : "-");
    cell(row, r.battery ? `${r.battery.percent}% ${r.battery.volts} V` : "-");
    cell(row, r.last_seen_s === null ? "-" : `${r.last_seen_s.toFixed(1)} s`, "seen");
    actionsCell(row, r);
    if (r.alive) {
      row.addEventListener("dragover", (e) => { e.preventDefault(); row.classList.add("drop"); });
      row.addEventListener("dragleave", () => row.classList.remove("drop"));
      row.addEventListener("drop", (e) => {
        e.preventDefault();
        row.classList.remove("drop");
        if (e.dataTransfer.files.length) sendMission(r.name, e.dataTransfer.files[0]);
      });
    }
    body.appendChild(row);
  }
  const alive = robots.filter((r) => r.alive).length;
  $("count").textContent = `${alive} of ${robots.length} on the fleet`;
  drawMaps();
}

// The map never mixes frames. Robots with a GPS fix share one geographic view: metres east and north of their
// mean (equirectangular: a campus is flat enough). A robot without one is in its own map frame, whose origin and
// axes mean nothing to another robot's: each is drawn in a small view of its own, labelled.
const M_PER_DEG = 111320;  // metres per degree of latitude
const STEPS_M = [0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000];

function hasFix(r) { return !!(r.gps && typeof r.gps.lat === "number" && typeof r.gps.lon === "number"); }

function drawMaps() {
  const onGps = robots.filter(hasFix);
  const lat0 = onGps.reduce((a, r) => a + r.gps.lat, 0) / (onGps.length || 1);
  const lon0 = onGps.reduce((a, r) => a + r.gps.lon, 0) / (onGps.length || 1);
  const k = Math.cos(lat0 * Math.PI / 180);
  const placed = onGps.map((r) => ({r, x: (r.gps.lon - lon0) * M_PER_DEG * k, y: (r.gps.lat - lat0) * M_PER_DEG}));
  const map = $("map");
  map.hidden = !placed.length;
  $("map-none").hidden = !!placed.length;
  map.dataset.frame = "gps";
  map.dataset.robots = placed.map((p) => p.r.name).join(",");
  $("map-info").textContent = placed.length
    ? `robots with a GPS fix: metres east and north of ${lat0.toFixed(5)}, ${lon0.toFixed(5)}` : "";
  if (placed.length) draw(map, placed, "N ↑");

  const local = robots.filter((r) => !hasFix(r) && r.pose);
  $("frames-title").hidden = !local.length;
  const frames = $("frames");
  const views = new Map([...frames.querySelectorAll("figure")].map((f) => [f.dataset.robot, f]));
  for (const r of local) {
    let fig = views.get(r.name);
    views.delete(r.name);
    if (!fig) {
      fig = document.createElement("figure");
      fig.dataset.robot = r.name;
      fig.dataset.testid = "frame-view";
      const cap = document.createElement("figcaption");
      const canvas = document.createElement("canvas");
      canvas.dataset.frame = "map";
      fig.append(cap, canvas);
      frames.appendChild(fig);
    }
    fig.querySelector("figcaption").textContent = `${r.name}: its own map frame, metres`;
    const canvas = fig.querySelector("canvas");
    canvas.dataset.robots = r.name;
    draw(canvas, [{r, x: r.pose.x, y: r.pose.y}], "+y ↑");
  }
  for (const gone of views.values()) gone.remove();
}

/** Draw `placed` robots ({r, x m, y m}, one frame) on `canvas` at its size on the page (3:2, sharp on any
 * screen), equal scale on both axes, with a scale bar (its length in canvas.dataset.scaleM, m, and .scalePx, CSS px;
 * .perM is CSS px per metre) and which way is up. */
function draw(canvas, placed, up) {
  const W = Math.round(canvas.clientWidth), H = Math.round(W * 2 / 3), dpr = window.devicePixelRatio || 1;
  if (W < 50) return;  // not laid out (hidden)
  if (canvas.width !== Math.round(W * dpr)) { canvas.width = Math.round(W * dpr); canvas.height = Math.round(H * dpr); }
  const g = canvas.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.fillStyle = "#101214";
  g.fillRect(0, 0, W, H);
  const x0 = Math.min(...placed.map((p) => p.x)) - 2, x1 = Math.max(...placed.map((p) => p.x)) + 2;
  const y0 = Math.min(...placed.map((p) => p.y)) - 2, y1 = Math.max(...placed.map((p) => p.y)) + 2;
  const scale = Math.min(W / (x1 - x0), H / (y1 - y0));  // CSS px per metre
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  const px = (x) => W / 2 + (x - cx) * scale, py = (y) => H / 2 - (y - cy) * scale;
  g.font = "12px system-ui, sans-serif";
  for (const p of placed) {
    const r = p.r, x = px(p.x), y = py(p.y);
    g.fillStyle = r.estop && r.alive ? "#ff1f14" : COLOURS[r.alive ? r.status : "lost"] || "#ccc";
    g.beginPath();
    g.arc(x, y, 6, 0, 2 * Math.PI);
    g.fill();
    if (r.pose && typeof r.pose.yaw_deg === "number") {  // yaw: counter-clockwise from +x (east on GPS)
      const yaw = r.pose.yaw_deg * Math.PI / 180;
      g.strokeStyle = g.fillStyle;
      g.lineWidth = 2;
      g.beginPath();
      g.moveTo(x, y);
      g.lineTo(x + 16 * Math.cos(yaw), y - 16 * Math.sin(yaw));
      g.stroke();
    }
    g.fillText(r.name, x + 10, y - 9);
  }
  // the scale bar: the longest round length that fits a quarter of the width
  const step = STEPS_M.filter((s) => s * scale <= W / 4).pop() || STEPS_M[0];
  const bar = step * scale;
  g.fillStyle = "#c9ced6";
  g.fillRect(10, H - 14, bar, 4);
  g.fillRect(10, H - 20, 2, 10);
  g.fillRect(10 + bar - 2, H - 20, 2, 10);
  g.fillText(step >= 1000 ? `${step / 1000} km` : `${step} m`, 16 + bar, H - 9);
  g.fillText(up, W - 36, 16);
  canvas.dataset.scaleM = String(step);
  canvas.dataset.scalePx = String(bar);
  canvas.dataset.perM = String(scale);
}

async function poll() {
  try {
    const r = await fetch("/api/robots");
    if (r.ok) { robots = (await r.json()).robots; render(); }
  } catch (e) { $("count").textContent = "station unreachable"; }
  setTimeout(poll, 500);
}

window.addEventListener("resize", () => { drawnKey = ""; render(); });  // the maps follow the page's width
$("estop-all").addEventListener("click", () => post("/api/estop-all", "{}").then((a) => {
  if (a.ok) notice(`stop sent to every robot (${a.robots.length} on the fleet now)`, "ok");
}));
poll();
