// beastbt station: the robots' table (those that need attention first), one map, stop all, missions by drop.
"use strict";
const $ = (id) => document.getElementById(id);
const COLOURS = {running: "#f2c744", paused: "#4aa3ff", succeeded: "#4caf50", failed: "#e5534b",
                 aborted: "#e5534b", lost: "#777", idle: "#9aa0a6"};
let robots = [];

function notice(text) {
  const n = $("notice");
  n.textContent = text || "";
  n.hidden = !text;
}

async function post(path, body, type) {
  const r = await fetch(path, {method: "POST", headers: {"Content-Type": type || "application/json"},
                               body: body === undefined ? "{}" : body});
  let answer = {};
  try { answer = await r.json(); } catch (e) { answer = {error: r.statusText}; }
  if (!r.ok) notice((answer.error || "refused") + (answer.errors ? "\n" + answer.errors : ""));
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

function button(td, label, action) {
  const b = document.createElement("button");
  b.textContent = label;
  b.addEventListener("click", action);
  td.appendChild(b);
}

function control(name, c, body) {
  return () => post(`/api/robots/${encodeURIComponent(name)}/${c}`, body === undefined ? "{}" : JSON.stringify(body));
}

function sendMission(name, file) {
  const zip = file.name.toLowerCase().endsWith(".zip");
  file.arrayBuffer().then((data) => post(`/api/robots/${encodeURIComponent(name)}/mission`, data,
                                         zip ? "application/zip" : "application/yaml"))
    .then((a) => { if (a.ok) notice(`${name}: mission '${a.started}' started`); });
}

function render() {
  const body = $("robots").tBodies[0];
  body.textContent = "";
  for (const r of robots) {
    const row = document.createElement("tr");
    row.dataset.robot = r.name;
    if (!r.alive) row.className = "lost";
    const name = cell(row, r.name);
    if (r.console_url) {
      name.textContent = "";
      const a = document.createElement("a");
      a.href = r.console_url; a.target = "_blank"; a.rel = "noopener"; a.textContent = r.name;
      name.appendChild(a);
    }
    const status = r.question && r.alive ? "question" : r.status;
    const st = cell(row, status + (r.estop && r.alive ? " · e-stop" : ""));
    st.innerHTML = "";
    const badge = document.createElement("span");
    badge.className = "status " + status;
    badge.textContent = status + (r.estop && r.alive ? " · e-stop" : "");
    st.appendChild(badge);
    const last = r.last_run ? ` (last: ${r.last_run.mission} ${r.last_run.status})` : "";
    cell(row, (r.mission ? `${r.mission}: ${r.step || "-"}` : "-") + last);
    const p = r.progress;
    cell(row, p ? `${p.done}/${p.total}` : "-");
    cell(row, r.battery ? `${r.battery.percent}% ${r.battery.volts} V` : "-");
    cell(row, r.last_seen_s === null ? "-" : `${r.last_seen_s.toFixed(1)} s`);
    const actions = cell(row, "", "actions");
    if (r.question && r.alive) {
      for (const choice of r.question.choices) {
        button(actions, `${r.question.text} ${choice}`, control(r.name, "answer", {id: r.question.id, choice}));
      }
    }
    button(actions, "Pause", control(r.name, "pause"));
    button(actions, "Resume", control(r.name, "resume"));
    button(actions, "Abort", control(r.name, "abort"));
    button(actions, "Reset e-stop", control(r.name, "estop_reset"));
    button(actions, "E-stop", control(r.name, "estop"));
    row.addEventListener("dragover", (e) => { e.preventDefault(); row.classList.add("drop"); });
    row.addEventListener("dragleave", () => row.classList.remove("drop"));
    row.addEventListener("drop", (e) => {
      e.preventDefault();
      row.classList.remove("drop");
      if (e.dataTransfer.files.length) sendMission(r.name, e.dataTransfer.files[0]);
    });
    body.appendChild(row);
  }
  const alive = robots.filter((r) => r.alive).length;
  $("count").textContent = `${alive} of ${robots.length} on the fleet`;
  drawMap();
}

// Where each robot is on the map, metres east and north: on GPS (every placed robot has a fix) all share one
// frame around their mean position; else each robot's own map frame (a shared simulated world: the same one).
function positions(placed) {
  const fixed = placed.filter((r) => r.gps && r.gps.lat !== null && r.gps.lon !== null);
  if (fixed.length && fixed.length === placed.length) {
    const lat0 = fixed.reduce((a, r) => a + r.gps.lat, 0) / fixed.length;
    const lon0 = fixed.reduce((a, r) => a + r.gps.lon, 0) / fixed.length;
    const m = 111320;  // metres per degree of latitude (equirectangular: a campus is flat enough)
    $("map-info").textContent = "GPS, metres east and north of the robots' mean";
    return fixed.map((r) => ({r, x: (r.gps.lon - lon0) * m * Math.cos(lat0 * Math.PI / 180),
                              y: (r.gps.lat - lat0) * m}));
  }
  $("map-info").textContent = "each robot in its own map frame, metres";
  return placed.map((r) => ({r, x: r.pose.x, y: r.pose.y}));
}

function drawMap() {
  const canvas = $("map"), g = canvas.getContext("2d");
  g.fillStyle = "#101214";
  g.fillRect(0, 0, canvas.width, canvas.height);
  const placed = positions(robots.filter((r) => r.pose));
  if (!placed.length) return;
  let x0 = Math.min(...placed.map((p) => p.x)) - 2, x1 = Math.max(...placed.map((p) => p.x)) + 2;
  let y0 = Math.min(...placed.map((p) => p.y)) - 2, y1 = Math.max(...placed.map((p) => p.y)) + 2;
  const scale = Math.min(canvas.width / (x1 - x0), canvas.height / (y1 - y0));
  const px = (x) => (x - x0) * scale, py = (y) => canvas.height - (y - y0) * scale;
  g.font = "14px system-ui, sans-serif";
  for (const p of placed) {
    const r = p.r, x = px(p.x), y = py(p.y), yaw = r.pose.yaw_deg * Math.PI / 180;
    g.fillStyle = COLOURS[r.alive ? r.status : "lost"] || "#ccc";
    g.beginPath();
    g.arc(x, y, 8, 0, 2 * Math.PI);
    g.fill();
    g.strokeStyle = g.fillStyle;
    g.beginPath();
    g.moveTo(x, y);
    g.lineTo(x + 16 * Math.cos(yaw), y - 16 * Math.sin(yaw));
    g.stroke();
    g.fillText(r.name, x + 11, y - 11);
  }
}

async function poll() {
  try {
    const r = await fetch("/api/robots");
    if (r.ok) { robots = (await r.json()).robots; render(); }
  } catch (e) { $("count").textContent = "station unreachable"; }
  setTimeout(poll, 500);
}

$("estop-all").addEventListener("click", () => post("/api/estop-all", "{}").then((a) => {
  if (a.ok) notice(`stop sent to every robot (${a.robots.length} on the fleet now)`);
}));
poll();
