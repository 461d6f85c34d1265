// The mission studio's page: Files, Editor (+ Problems), Map, Tree and Try it, on the API of docs/studio.md.
// The text in the editor is the one truth: the map, the tree and the problems are redrawn from it (debounced)
// whenever it changes, and a map edit comes back as new text that goes through the editor's undo stack.
import "./style.css";
import { api, ApiError, filePath, withToken } from "./api";
import { createEditor, monaco, replaceText, selectAt, showMarkers, useSchema, type Problem } from "./editor";
import { StudioMap, type MapData, type Point } from "./map";
import { drawTree, type TreeData } from "./tree";

/** beastbt's validation runs this long after typing stops (the issue asks for at most 300 ms). */
const VALIDATE_DEBOUNCE_MS = 250;
/** How often the run panel asks for the run's state (ms). */
const TRY_POLL_MS = 400;

const $ = <T extends HTMLElement = HTMLElement>(id: string) => document.getElementById(id) as T;

interface FileEntry { path: string; kind: string; size?: number; version?: string }

/** One open file: its model (with its own undo stack) and the version it was read or last saved at. */
interface OpenFile {
  path: string;
  kind: string;
  version: string | null;
  savedText: string;
  model: monaco.editor.ITextModel;
  viewState: monaco.editor.ICodeEditorViewState | null;
}

const state = {
  files: [] as FileEntry[],
  open: new Map<string, OpenFile>(),
  current: null as OpenFile | null,
  problems: [] as Problem[],
  tab: "map",
  checkTicket: 0,
  treeTicket: 0,
  treeStale: true,
};

// ---------------------------------------------------------------- status line
let statusTimer = 0;
/** One line of news in the bar: ok and info fade after 5 s, an error stays until the next news. */
function status(message: string, kind: "info" | "ok" | "error" | "busy" = "info", sticky = false): void {
  const el = $("status");
  el.textContent = message;
  el.className = `status ${kind}`;
  window.clearTimeout(statusTimer);
  if (!sticky && kind !== "error") statusTimer = window.setTimeout(() => { el.textContent = ""; }, 5000);
}

/** An error a teacher can read: what failed and the studio's own words why. */
function fail(what: string, e: unknown): void {
  const message = e instanceof Error ? e.message : String(e);
  status(`${what}: ${message}`, "error");
}

// ---------------------------------------------------------------- editor
const editor = createEditor($("editor"));
editor.addCommand(monaco.KeyMod.CtrlCmd | monaco.KeyCode.KeyS, () => { void save(); });
window.addEventListener("keydown", (e) => {
  if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === "s") { e.preventDefault(); void save(); }
});
$("undo").addEventListener("click", () => { editor.focus(); editor.trigger("studio", "undo", null); });
$("redo").addEventListener("click", () => { editor.focus(); editor.trigger("studio", "redo", null); });

let checkTimer = 0;
editor.onDidChangeModelContent(() => {
  markDirty();
  window.clearTimeout(checkTimer);
  checkTimer = window.setTimeout(() => { void check(); }, VALIDATE_DEBOUNCE_MS);
});

/** Mark the open file, and each file in the list, that has text not saved yet. */
function markDirty(): void {
  const cur = state.current;
  const dirty = !!cur && cur.model.getValue() !== cur.savedText;
  $("dirty").hidden = !dirty;
  document.querySelectorAll<HTMLElement>(".file-list li").forEach((li) => {
    const f = state.open.get(li.dataset.path ?? "");
    li.classList.toggle("dirty", !!f && f.model.getValue() !== f.savedText);
  });
}

window.addEventListener("beforeunload", (e) => {
  for (const f of state.open.values()) {
    if (f.model.getValue() !== f.savedText) { e.preventDefault(); e.returnValue = ""; return; }
  }
});

// ---------------------------------------------------------------- problems
function showProblems(problems: Problem[]): void {
  state.problems = problems;
  if (state.current) showMarkers(state.current.model, problems.filter((p) => !(p as any).file));
  const list = $("problems");
  list.replaceChildren();
  const errors = problems.filter((p) => p.severity === "error").length;
  const others = problems.length - errors;
  const count = (n: number, word: string) => `${n} ${word}${n === 1 ? "" : "s"}`;
  $("problem-count").textContent = [errors ? count(errors, "error") : "", others ? count(others, "warning") : ""]
    .filter(Boolean).join(", ");
  if (!problems.length) {
    const li = document.createElement("li");
    li.className = state.current ? "none" : "none muted";
    li.textContent = !state.current ? "Open a file to check it."
      : state.current.kind === "mission" ? "No problems: the mission is ready to try." : "No problems.";
    list.appendChild(li);
    return;
  }
  for (const p of problems) {
    const li = document.createElement("li");
    li.className = `problem ${p.severity}`;
    li.setAttribute("data-testid", "problem");
    li.dataset.line = String(p.line);
    li.dataset.column = String(p.column);
    li.tabIndex = 0;
    const where = document.createElement("span");
    where.className = "where";
    where.textContent = `${(p as any).file ? (p as any).file + ":" : ""}${p.line}:${p.column}`;
    const sev = document.createElement("span");
    sev.className = "sev";
    sev.textContent = p.severity;
    const msg = document.createElement("span");
    msg.className = "msg";
    msg.textContent = p.message;
    li.append(sev, where, msg);
    if (p.hint) {
      const hint = document.createElement("div");
      hint.className = "hint-text";
      hint.textContent = `hint: ${p.hint}`;
      li.appendChild(hint);
    }
    // A problem in another file (the mission's world) opens that file when it is in the folder.
    const other: string | undefined = (p as any).file;
    const jump = async () => {
      if (other) {
        if (!state.files.some((f) => f.path === other)) return;
        await openFile(other);
      }
      selectAt(editor, p.line, p.column, p.end_line, p.end_column);
    };
    li.addEventListener("click", () => void jump());
    li.addEventListener("keydown", (e) => { if (e.key === "Enter") void jump(); });
    list.appendChild(li);
  }
}

/** Validate the text, then redraw the map (and the tree when it shows): each answer for the text it was asked for. */
async function check(): Promise<void> {
  const cur = state.current;
  if (!cur) return;
  const ticket = ++state.checkTicket;
  const text = cur.model.getValue();
  state.treeStale = true;
  try {
    const answer = await api<{ problems: Problem[] }>("validate", { text, path: cur.path, robot: robot() });
    if (ticket !== state.checkTicket) return;
    showProblems(answer.problems ?? []);
  } catch (e) {
    if (ticket === state.checkTicket) fail("checking failed", e);
  }
  if (cur.kind === "mission" || cur.kind === "world") void redrawMap(ticket, text);
  if (state.tab === "tree") void redrawTree();
}

// ---------------------------------------------------------------- map
const studioMap = new StudioMap($("map"), {
  addPlace: (at) => void mapEdit({ op: "add_place", ...at }, (a) => `place ${a.name ?? ""} added`),
  movePlace: (name, to) => void mapEdit({ op: "move_place", name, ...to }, () => `place ${name} moved`),
  addFence: (polygon) => void mapEdit({ op: "add_fence", keep: "out", polygon }, () => "keep-out fence added"),
  addRoute: (places) => void mapEdit({ op: "add_route", places }, () => `route ${places.join(" → ")} added`),
  selectLine: (line) => selectAt(editor, line),
}, {
  hint: $("hint"),
  finish: $<HTMLButtonElement>("finish"),
  cancel: $<HTMLButtonElement>("cancel"),
  buttons: { place: $<HTMLButtonElement>("add-place"), fence: $<HTMLButtonElement>("draw-fence"),
    route: $<HTMLButtonElement>("make-route") },
});
$<HTMLInputElement>("tiles").addEventListener("change", (e) => {
  const box = e.target as HTMLInputElement;
  studioMap.setTiles(box.checked, () => {
    box.checked = false;
    status("the online map could not be loaded (no internet here?): the map stays offline", "error");
  });
});

/** The map's tools work once the open file's map is drawn (a click before would land on the wrong map). */
function setMapReady(ready: boolean): void {
  $("map").dataset.ready = ready ? "true" : "false";
  for (const id of ["add-place", "draw-fence", "make-route"]) $<HTMLButtonElement>(id).disabled = !ready;
}
setMapReady(false);

/** Draw the map of `text` (the answer is dropped when the text changed meanwhile). */
async function redrawMap(ticket: number, text: string): Promise<void> {
  const cur = state.current;
  if (!cur) return;
  try {
    const data = await api<MapData>("map", { text, path: cur.path });
    if (ticket !== state.checkTicket) return;
    studioMap.draw(data);
    $("map").dataset.places = String(data?.places?.length ?? 0);
    setMapReady(cur.kind === "mission");
    if (cur.kind === "world") $("hint").textContent = "The world's plan as the text says it (walls, obstacles, start).";
    else studioMap.showHint();
  } catch (e) {
    if (ticket === state.checkTicket) status(`the map cannot be drawn yet: ${(e as Error).message}`, "info");
  }
}

/** Send one map edit to /api/edit and put the answer into the editor as one undoable edit. */
async function mapEdit(edit: Record<string, unknown>, done: (answer: { name?: string }) => string): Promise<void> {
  const cur = state.current;
  if (!cur) { status("open a mission first", "error"); return; }
  const text = cur.model.getValue();
  try {
    const answer = await api<{ text: string; name?: string }>("edit", { text, path: cur.path, edit });
    if (cur.model.getValue() !== text) { status("the text changed meanwhile: do it again", "error"); return; }
    editor.setModel(cur.model);
    replaceText(editor, answer.text, "map");
    status(`${done(answer)} (Undo takes it back)`, "ok");
    window.clearTimeout(checkTimer);
    void check();
  } catch (e) {
    fail("the map edit was not made", e);
    void check();
  }
}

// ---------------------------------------------------------------- tree
async function redrawTree(): Promise<void> {
  const cur = state.current;
  if (!cur) return;
  if (cur.kind !== "mission") {
    await drawTree($("tree-view"), null, () => {}, "Only a mission has a tree.");
    return;
  }
  const ticket = ++state.treeTicket;
  state.treeStale = false;
  try {
    const data = await api<TreeData>("tree", { text: cur.model.getValue(), path: cur.path, robot: robot() });
    if (ticket !== state.treeTicket) return;
    await drawTree($("tree-view"), data, (node) => {
      if (node.line) selectAt(editor, node.line, node.column ?? 1, node.end_line ?? undefined,
        node.end_column ?? undefined);
    });
  } catch (e) {
    if (ticket !== state.treeTicket) return;
    const message = e instanceof ApiError && e.status < 500 ? e.message : `the tree cannot be drawn: ${e}`;
    await drawTree($("tree-view"), null, () => {}, `No tree yet: ${message}`);
  }
}

// ---------------------------------------------------------------- tabs
function showTab(tab: string): void {
  state.tab = tab;
  document.querySelectorAll<HTMLElement>(".tab").forEach((b) => b.classList.toggle("active", b.dataset.tab === tab));
  document.querySelectorAll<HTMLElement>(".tab-body").forEach((b) => { b.hidden = b.dataset.body !== tab; });
  if (tab === "map") studioMap.resize();
  if (tab === "tree" && state.treeStale) void redrawTree();
}
document.querySelectorAll<HTMLElement>(".tab").forEach((b) => {
  b.addEventListener("click", () => showTab(b.dataset.tab!));
});

// ---------------------------------------------------------------- files
async function loadFiles(): Promise<void> {
  try {
    const answer = await api<{ files: FileEntry[]; folder?: string }>("files");
    state.files = answer.files ?? [];
    if (answer.folder) document.title = `beastbt studio — ${answer.folder}`;
    renderFiles();
  } catch (e) {
    fail("the files cannot be listed", e);
  }
}

const KIND_TITLES: Record<string, string> = { mission: "Missions", test: "Tests", world: "Worlds", robot: "Robots",
  other: "Other" };

/** The file list, grouped by kind: missions, worlds, robots, other. */
function renderFiles(): void {
  const list = $("file-list");
  list.replaceChildren();
  for (const kind of ["mission", "test", "world", "robot", "other"]) {
    const files = state.files.filter((f) => (KIND_TITLES[f.kind] ? f.kind : "other") === kind);
    if (!files.length) continue;
    const head = document.createElement("li");
    head.className = "group";
    head.textContent = KIND_TITLES[kind];
    list.appendChild(head);
    for (const f of files) {
      const li = document.createElement("li");
      li.className = "file";
      li.dataset.path = f.path;
      li.setAttribute("data-testid", "file");
      li.title = f.path;
      li.textContent = f.path;
      li.tabIndex = 0;
      li.classList.toggle("current", state.current?.path === f.path);
      li.addEventListener("click", () => void openFile(f.path));
      li.addEventListener("keydown", (e) => { if (e.key === "Enter") void openFile(f.path); });
      list.appendChild(li);
    }
  }
  if (!state.files.length) {
    const li = document.createElement("li");
    li.className = "none";
    li.textContent = "No missions here yet: make one from a template above.";
    list.appendChild(li);
  }
  markDirty();
}

/** The page's copy of the JSON Schema of a kind of file (absolute: its `$ref`s resolve beside it). */
function schemaFor(kind: string): string | null {
  const name = { mission: "mission", world: "world", robot: "robot", test: "test" }[kind];
  return name ? new URL(`schemas/${name}.schema.json`, location.href).href : null;
}

/** Show a file: from memory when it is open already (its unsaved text and undo kept), else read it. */
async function openFile(path: string, given?: { text: string; version: string | null; kind?: string }): Promise<void> {
  if (state.current) state.current.viewState = editor.saveViewState();
  let file = state.open.get(path);
  if (!file) {
    let data = given;
    if (!data) {
      try {
        data = await api<{ text: string; version: string; kind: string }>("files/" + filePath(path));
      } catch (e) {
        fail(`'${path}' cannot be opened`, e);
        return;
      }
    }
    const kind = data.kind ?? state.files.find((f) => f.path === path)?.kind ?? "mission";
    // The model's address is the file's place under the page's: one model per file, and monaco-yaml's schema
    // association (fileMatch) names it. (A modeline's relative schema becomes a file: address whatever this is;
    // yaml-worker.ts reads it from the page's copy.)
    const uri = monaco.Uri.parse(new URL(filePath(path), location.href).href);
    monaco.editor.getModel(uri)?.dispose();
    const model = monaco.editor.createModel(data.text, "yaml", uri);
    model.updateOptions({ tabSize: 2, insertSpaces: true });
    file = { path, kind, version: data.version, savedText: data.text, model, viewState: null };
    state.open.set(path, file);
  }
  state.current = file;
  $("welcome").hidden = true;
  editor.updateOptions({ readOnly: false });
  $<HTMLButtonElement>("save").disabled = false;
  $<HTMLButtonElement>("try").disabled = file.kind !== "mission";
  $("try").title = file.kind === "mission" ? "Run this mission on the simulator" : "Only a mission can be tried";
  $<HTMLButtonElement>("test").disabled = file.kind !== "mission";
  await useSchema(file.model.uri, schemaFor(file.kind));
  editor.setModel(file.model);
  if (file.viewState) editor.restoreViewState(file.viewState);
  $("current-path").textContent = path;
  renderFiles();
  studioMap.refit();
  studioMap.draw(null);
  $("map").dataset.places = "0";
  setMapReady(false);
  showProblems([]);
  state.treeStale = true;
  void check();
  editor.focus();
}

// ---------------------------------------------------------------- templates
async function loadTemplates(): Promise<void> {
  try {
    const answer = await api<{ templates: Array<{ name: string; title: string; description?: string }> }>("templates");
    const select = $<HTMLSelectElement>("template");
    select.replaceChildren();
    for (const t of answer.templates ?? []) {
      const option = document.createElement("option");
      option.value = t.name;
      option.textContent = t.title || t.name;
      option.title = t.description ?? "";
      select.appendChild(option);
    }
  } catch (e) {
    fail("the templates cannot be listed", e);
  }
}

/** `base`.yaml, or `base`_2.yaml, ... : a name no file of the folder has yet. */
function freeName(base: string): string {
  const taken = new Set(state.files.map((f) => f.path));
  const stem = base.replace(/\.ya?ml$/i, "");
  let name = `${stem}.yaml`;
  for (let i = 2; taken.has(name) || state.open.has(name); i++) name = `${stem}_${i}.yaml`;
  return name;
}

/** Make a new mission from the chosen template, save it (a new file) and open it. */
async function createFromTemplate(): Promise<void> {
  const template = $<HTMLSelectElement>("template").value;
  if (!template) return;
  const input = $<HTMLInputElement>("new-name");
  let name = input.value.trim().replace(/\\/g, "/");
  if (!name) name = freeName(`missions/my_${template}`);
  if (!/\.ya?ml$/i.test(name)) name += ".yaml";
  try {
    const answer = await api<{ text: string }>("templates/" + encodeURIComponent(template), { path: name });
    const saved = await api<{ version: string }>("files/" + filePath(name),
      { text: answer.text, version: null }, "PUT");
    input.value = "";
    await loadFiles();
    await openFile(name, { text: answer.text, version: saved.version, kind: "mission" });
    status(`${name} made from the ${template} template`, "ok");
  } catch (e) {
    fail("the new mission was not made", e);
  }
}
$("create").addEventListener("click", () => void createFromTemplate());
$("new-name").addEventListener("keydown", (e) => { if (e.key === "Enter") void createFromTemplate(); });

// ---------------------------------------------------------------- save and conflicts
let diffEditor: monaco.editor.IStandaloneDiffEditor | null = null;
let conflictFor: { file: OpenFile; diskText: string | null } | null = null;

/** PUT the open file with the version it was read at; a 409 opens the conflict view and saves nothing. */
async function save(): Promise<void> {
  const cur = state.current;
  if (!cur) return;
  const text = cur.model.getValue();
  $<HTMLButtonElement>("save").disabled = true;
  try {
    const answer = await api<{ version: string }>("files/" + filePath(cur.path), { text, version: cur.version }, "PUT");
    cur.version = answer.version;
    cur.savedText = text;
    markDirty();
    status(`saved ${cur.path} (the previous version is ${cur.path}.bak)`, "ok");
    void loadFiles();
  } catch (e) {
    if (e instanceof ApiError && e.status === 409) showConflict(cur, e.body?.disk_text ?? null, e.message);
    else fail("not saved", e);
  } finally {
    $<HTMLButtonElement>("save").disabled = false;
  }
}
$("save").addEventListener("click", () => void save());

/** Both texts side by side: the disk's and the editor's. */
function showConflict(file: OpenFile, diskText: string | null, message: string): void {
  conflictFor = { file, diskText };
  $("conflict").hidden = false;
  $("conflict").querySelector("p")!.textContent = `${message}.`;
  $<HTMLButtonElement>("take-disk").disabled = diskText === null;
  if (!diffEditor) {
    diffEditor = monaco.editor.createDiffEditor($("conflict-diff"), {
      readOnly: true, automaticLayout: true, renderSideBySide: true, minimap: { enabled: false },
      originalEditable: false, scrollBeyondLastLine: false,
    });
  }
  diffEditor.setModel({
    original: monaco.editor.createModel(diskText ?? "(the file is gone from the disk)", "yaml"),
    modified: monaco.editor.createModel(file.model.getValue(), "yaml"),
  });
  status(`not saved: ${file.path} changed on disk`, "error", true);
}

/** Close the conflict view (the editor's text is untouched). */
function closeConflict(): void {
  $("conflict").hidden = true;
  const models = diffEditor?.getModel();
  diffEditor?.setModel(null);
  models?.original.dispose();
  models?.modified.dispose();
  conflictFor = null;
}

/** The version of the file on disk now (null when it is gone). */
async function diskVersion(path: string): Promise<string | null> {
  try {
    return (await api<{ version: string }>("files/" + filePath(path))).version;
  } catch (e) {
    if (e instanceof ApiError && e.status === 404) return null;
    throw e;
  }
}

$("keep-mine").addEventListener("click", async () => {
  if (!conflictFor) return;
  const { file } = conflictFor;
  try {
    file.version = await diskVersion(file.path);
    closeConflict();
    await save();
  } catch (e) {
    fail("not saved", e);
  }
});
$("take-disk").addEventListener("click", async () => {
  if (!conflictFor || conflictFor.diskText === null) return;
  const { file, diskText } = conflictFor;
  try {
    file.version = await diskVersion(file.path);
    if (state.current !== file) await openFile(file.path);
    replaceText(editor, diskText, "disk");
    file.savedText = diskText;
    markDirty();
    closeConflict();
    status("took the version on disk (Undo brings yours back)", "ok");
  } catch (e) {
    fail("the version on disk cannot be read", e);
  }
});
$("conflict-close").addEventListener("click", () => { closeConflict(); status("not saved yet", "info"); });

// ---------------------------------------------------------------- try it
/** GET /api/try/<id> (docs/studio.md, Try it). */
interface TryState {
  run_id: string;
  state: "running" | "ended" | string;
  exit_code?: number | null;
  summary?: Record<string, any> | null;
  report?: string | null;
  run_folder?: string | null;
  speed?: string;
  output?: string | string[];
}

/** The console's GET /api/state, passed through the studio (docs/console.md), as far as the panel shows it. */
interface LiveState {
  status?: string;
  step?: string;
  time_s?: number;
  progress?: { done?: number; total?: number | null; eta_s?: number | null };
  pose?: { x: number; y: number; yaw_deg?: number };
  question?: { id: string; text: string } | null;
  tree?: Array<{ id: string; status?: string }>;
  /** Added by the studio: mission seconds per wall second, measured, and the wall seconds left at that pace. */
  pace?: { speedup?: number | null; time_left_s?: number | null };
}

const run = {
  id: null as string | null,
  timer: 0,
  ended: false,
  question: null as string | null,
};

/** A call to the running try's part of the API (`/api/try/<id>...`). */
function runApi<T = any>(what: string, body?: unknown): Promise<T> {
  return api<T>(`try/${encodeURIComponent(run.id!)}${what}`, body);
}

/** Start a simulated run of the editor's text (a try still running is stopped first). */
async function tryIt(): Promise<void> {
  const cur = state.current;
  if (!cur) { status("open a mission first", "error"); return; }
  if (run.id && !run.ended) void runApi("/stop", {}).catch(() => {});
  window.clearTimeout(run.timer);
  run.id = null;
  run.ended = false;
  const panel = $("run-panel");
  panel.hidden = false;
  $("test-panel").hidden = true;
  panel.className = "run-panel running";
  delete panel.dataset.result;
  $("run-outcome").textContent = "Starting the simulator…";
  $("run-step").textContent = "-";
  $("run-step-label").textContent = "step";
  $("run-time").textContent = "";
  $("run-details").hidden = true;
  $("run-report").hidden = true;
  $("run-console").hidden = true;
  $("run-question").hidden = true;
  $("run-pause").hidden = false;
  $("run-resume").hidden = true;
  $("run-stop").hidden = false;
  setProgress(null);
  studioMap.showRobot(null);
  showTab("map");
  try {
    // the speed chosen beside Try it; ?max_time=5%20min in the page's address caps the mission time
    const params = new URLSearchParams(location.search);
    const chosen = $<HTMLSelectElement>("try-speed").value;
    const speed = chosen === "max" || chosen === "realtime" ? chosen : Number(chosen);
    const maxTime = params.get("max_time") || undefined;
    const answer = await api<{ run_id: string; console_url?: string }>("try",
      { text: cur.model.getValue(), path: cur.path, speed, max_time: maxTime, robot: robot() });
    run.id = answer.run_id;
    if (answer.console_url) {
      const link = $<HTMLAnchorElement>("run-console");
      link.href = answer.console_url;
      link.hidden = false;
    }
    $("run-outcome").textContent = "Running on the simulator…";
    void pollRun(answer.run_id);
  } catch (e) {
    panel.className = "run-panel failure";
    $("run-outcome").textContent = `The run did not start: ${(e as Error).message}`;
  }
}
$("try").addEventListener("click", () => void tryIt());

/** Follow a try: its state, and while it runs the console's (step, progress, question, pose, tree). */
async function pollRun(id: string): Promise<void> {
  if (run.id !== id) return;
  try {
    const s = await runApi<TryState>("");
    if (run.id !== id) return;
    if (s.state !== "running") {
      showEnded(s);
      return;
    }
    try {
      showLive(await runApi<LiveState>("/console/api/state"));
    } catch { /* the console is starting, or the run just ended: the next poll tells */ }
  } catch (e) {
    fail("the run's state cannot be read", e);
  }
  run.timer = window.setTimeout(() => void pollRun(id), TRY_POLL_MS);
}

/** The progress bar: steps done of the steps a full run takes, and the wall time left at the measured pace (the
 * studio's `pace`: the mission time left over the speed-up, not the mission time itself). */
function setProgress(p: LiveState["progress"] | null, pace?: LiveState["pace"]): void {
  const done = p?.done ?? 0;
  const total = p?.total ?? null;
  $("run-progress-fill").style.width = total ? `${Math.min(100, (100 * done) / total)}%` : "0";
  const text = $("run-progress-text");
  const left = pace?.time_left_s ?? null;
  const speedup = pace?.speedup ?? null;
  text.dataset.timeLeft = left != null ? String(left) : "";
  text.dataset.speedup = speedup != null ? String(speedup) : "";
  text.textContent = p ? (total ? `${done} of ${total} steps` : `${done} steps`)
    + (left != null ? `, about ${formatSeconds(left)} left` : "")
    + (speedup != null && speedup > 0 ? ` (${speedup >= 1.5 ? Math.round(speedup) : speedup.toFixed(1)}× real time)`
      : "") : "";
}

/** `45 s`, `3 min 20 s`. */
function formatSeconds(s: number): string {
  const whole = Math.max(0, Math.round(s));
  return whole < 60 ? `${whole} s` : `${Math.floor(whole / 60)} min ${whole % 60} s`;
}

/** What the run does now: its step, time, progress, question, robot on the map and tree. */
function showLive(live: LiveState): void {
  if (run.ended) return;
  $("run-step").textContent = live.step ?? "-";
  $("run-time").textContent = live.time_s != null ? `${live.time_s.toFixed(1)} s` : "";
  setProgress(live.progress ?? null, live.pace);
  const paused = (live.step ?? "").includes("(paused)");
  $("run-pause").hidden = paused;
  $("run-resume").hidden = !paused;
  if (live.pose) studioMap.showRobot(live.pose);
  if (live.tree) showTreeStatus(live.tree);
  const q = live.question ?? null;
  run.question = q?.id ?? null;
  $("run-question").hidden = !q;
  if (q) $("run-question-text").textContent = q.text;
}

/** The run's node statuses on the Tree tab's nodes (/api/tree's ids are the console's). */
function showTreeStatus(tree: Array<{ id: string; status?: string }> | null): void {
  const status = new Map((tree ?? []).map((n) => [String(n.id), (n.status ?? "").toLowerCase()]));
  document.querySelectorAll<SVGGElement>("#tree-view [data-node]").forEach((g) => {
    const s = status.get(g.dataset.node ?? "") ?? "";
    for (const k of ["running", "success", "failure"]) g.classList.toggle(`run-${k}`, s === k);
  });
}

/** The run's end: its result, a summary in words, beastbt run's output and the report. */
function showEnded(s: TryState): void {
  run.ended = true;
  window.clearTimeout(run.timer);
  const result: string = s.summary?.status ?? (s.exit_code === 0 ? "success" : "failure");
  const panel = $("run-panel");
  panel.className = `run-panel ${result === "success" ? "success" : "failure"}`;
  panel.dataset.result = result;
  $("run-outcome").textContent = result === "success" ? "✔ The mission succeeded on the simulator"
    : result === "stopped" ? "■ The run was stopped" : `✖ The mission ended in ${result}`;
  $("run-pause").hidden = true;
  $("run-resume").hidden = true;
  $("run-stop").hidden = true;
  $("run-question").hidden = true;
  const dl = $("run-summary");
  dl.replaceChildren();
  const sm = s.summary ?? {};
  const rows: Array<[string, string | undefined]> = [
    ["result", result],
    ["time (simulated)", sm.sim_time_s != null ? `${Number(sm.sim_time_s).toFixed(1)} s` : undefined],
    ["distance driven", sm.distance_m != null ? `${Number(sm.distance_m).toFixed(1)} m` : undefined],
    ["top speed", sm.max_speed_mps != null ? `${Number(sm.max_speed_mps).toFixed(2)} m/s` : undefined],
    ["time (wall)", sm.wall_time_s != null ? `${Number(sm.wall_time_s).toFixed(1)} s` : undefined],
    ["recorded in", s.run_folder ?? undefined],
    ["exit code", s.exit_code != null ? String(s.exit_code) : undefined],
  ];
  for (const [k, v] of rows) {
    if (v === undefined) continue;
    const dt = document.createElement("dt"); dt.textContent = k;
    const dd = document.createElement("dd"); dd.textContent = v;
    dl.append(dt, dd);
  }
  const out = Array.isArray(s.output) ? s.output.join("\n") : (s.output ?? "");
  $("run-output").textContent = out;
  $("run-details").hidden = false;
  if (s.report) {
    const a = $<HTMLAnchorElement>("run-report");
    a.href = withToken(s.report);
    a.hidden = false;
  }
  // beastbt run's own last word: "mission NAME: SUCCESS (all steps done)"
  const lines = out.trim().split("\n").filter(Boolean);
  $("run-step-label").textContent = "";
  $("run-step").textContent = lines.find((l) => /^mission \S+: /.test(l)) ?? lines.pop() ?? "";
  $("run-time").textContent = "";
  setProgress(null);
}

$("run-pause").addEventListener("click", () => void runApi("/console/api/pause", {})
  .catch((e) => fail("not paused", e)));
$("run-resume").addEventListener("click", () => void runApi("/console/api/resume", {})
  .catch((e) => fail("not resumed", e)));
$("run-stop").addEventListener("click", async () => {
  if (!run.id || run.ended) return;
  try { showEnded(await runApi<TryState>("/stop", {})); } catch (e) { fail("not stopped", e); }
});
$("run-close").addEventListener("click", () => {
  showTreeStatus(null);
  if (run.id && !run.ended) void runApi("/stop", {}).catch(() => {});
  window.clearTimeout(run.timer);
  run.id = null;
  $("run-panel").hidden = true;
  studioMap.showRobot(null);
});
for (const [id, choice] of [["run-yes", "yes"], ["run-no", "no"]] as const) {
  $(id).addEventListener("click", () => {
    if (!run.question) return;
    void runApi("/console/api/answer", { id: run.question, choice }).catch((e) => fail("no answer", e));
  });
}

// ---------------------------------------------------------------- test
/** GET /api/test/<id> (docs/studio.md, Test). */
interface TestState {
  test_id: string;
  state: string;
  files: string[];
  exit_code?: number;
  output?: string[];
  results?: Array<{ file: string; test: string; seed: number | null; passed: boolean; message: string | null }>;
}

const tests = { id: null as string | null, timer: 0 };

/** Run the open mission's tests (POST /api/test): each file x seed's result when they end. */
async function testIt(): Promise<void> {
  const cur = state.current;
  if (!cur || cur.kind !== "mission") { status("open a mission first", "error"); return; }
  if (cur.model.getValue() !== cur.savedText) status("the tests run the saved mission: save to test your changes",
    "info");
  window.clearTimeout(tests.timer);
  if (tests.id) void api(`test/${encodeURIComponent(tests.id)}/stop`, {}).catch(() => {});
  tests.id = null;
  const panel = $("test-panel");
  panel.hidden = false;
  $("run-panel").hidden = true;
  panel.className = "run-panel test-panel running";
  delete panel.dataset.result;
  $("test-outcome").textContent = "Running the tests…";
  $("test-results").replaceChildren();
  $("test-details").hidden = true;
  $("test-stop").hidden = false;
  try {
    const answer = await api<{ test_id: string; files: string[] }>("test", { path: cur.path });
    tests.id = answer.test_id;
    $("test-outcome").textContent = `Running ${answer.files.length} test file${answer.files.length === 1 ? "" : "s"}`
      + `: ${answer.files.join(", ")}…`;
    void pollTests(answer.test_id);
  } catch (e) {
    panel.className = "run-panel test-panel failure";
    panel.dataset.result = "none";
    $("test-stop").hidden = true;
    $("test-outcome").textContent = `No test ran: ${(e as Error).message}`;
  }
}
$("test").addEventListener("click", () => void testIt());

async function pollTests(id: string): Promise<void> {
  if (tests.id !== id) return;
  try {
    const s = await api<TestState>(`test/${encodeURIComponent(id)}`);
    if (tests.id !== id) return;
    $("test-output").textContent = (s.output ?? []).join("\n");
    $("test-details").hidden = !(s.output ?? []).length;
    if (s.state !== "running") { showTests(s); return; }
  } catch (e) {
    fail("the tests' state cannot be read", e);
  }
  tests.timer = window.setTimeout(() => void pollTests(id), TRY_POLL_MS);
}

/** Each file x seed: pass or fail, and the first failure in words. */
function showTests(s: TestState): void {
  const results = s.results ?? [];
  const passed = results.filter((r) => r.passed).length;
  const ok = s.exit_code === 0 && results.length > 0;
  const panel = $("test-panel");
  panel.className = `run-panel test-panel ${ok ? "success" : "failure"}`;
  panel.dataset.result = ok ? "passed" : "failed";
  $("test-stop").hidden = true;
  $("test-outcome").textContent = results.length
    ? `${ok ? "✔" : "✖"} ${passed} of ${results.length} seed${results.length === 1 ? "" : "s"} passed`
    : `✖ The tests did not run (exit ${s.exit_code}): see the output`;
  const list = $("test-results");
  list.replaceChildren();
  for (const r of results) {
    const li = document.createElement("li");
    li.className = r.passed ? "pass" : "fail";
    li.setAttribute("data-testid", "test-result");
    li.dataset.file = r.file;
    li.dataset.seed = String(r.seed ?? "");
    li.dataset.passed = String(r.passed);
    li.textContent = `${r.file}: ${r.test}, seed ${r.seed ?? "?"}: ${r.passed ? "passed" : "failed"}`;
    if (!r.passed && r.message) {
      const why = document.createElement("span");
      why.className = "why";
      why.textContent = r.message;
      li.appendChild(why);
    }
    list.appendChild(li);
  }
}

$("test-stop").addEventListener("click", async () => {
  if (!tests.id) return;
  try { showTests(await api<TestState>(`test/${encodeURIComponent(tests.id)}/stop`, {})); }
  catch (e) { fail("not stopped", e); }
});
$("test-close").addEventListener("click", () => {
  window.clearTimeout(tests.timer);
  tests.id = null;
  $("test-panel").hidden = true;
});
$("test-new").addEventListener("click", async () => {
  const cur = state.current;
  if (!cur || cur.kind !== "mission") { status("open a mission first", "error"); return; }
  try {
    const made = await api<{ path: string; text: string; version: string }>("tests/new", { path: cur.path });
    await loadFiles();
    await openFile(made.path, { text: made.text, version: made.version, kind: "test" });
    status(`${made.path} made for ${cur.path}: change what it expects, save, then Test`, "ok");
  } catch (e) {
    if (e instanceof ApiError && e.status === 409 && typeof e.body?.path === "string") {
      await openFile(e.body.path);  // the mission's test is there already: open it
      status(e.message, "info");
    } else {
      fail("no new test", e);
    }
  }
});

// ---------------------------------------------------------------- robot
/** The robot a mission is checked, compiled and tried for (GET /api/robots; the simulator's by default). */
function robot(): string | undefined {
  return $<HTMLSelectElement>("robot").value || undefined;
}

/** The robots to choose from (GET /api/robots). */
async function loadRobots(): Promise<void> {
  try {
    const answer = await api<{ robots: string[] }>("robots");
    const select = $<HTMLSelectElement>("robot");
    select.replaceChildren();
    for (const name of answer.robots ?? []) {
      const option = document.createElement("option");
      option.value = name;
      option.textContent = name;
      select.appendChild(option);
    }
    if ((answer.robots ?? []).includes("sim")) select.value = "sim";
  } catch (e) {
    fail("the robots cannot be listed", e);
  }
}
$("robot").addEventListener("change", () => {
  $("tree-robot").textContent = robot() ?? "sim";
  state.treeStale = true;
  void check();
});

// ---------------------------------------------------------------- start
void loadRobots();
// Nothing to type into, save or try until a file is open: text typed into no file would be lost.
editor.updateOptions({ readOnly: true });
for (const id of ["try", "test", "save"]) $<HTMLButtonElement>(id).disabled = true;
{
  // ?speed=max|realtime|10 in the page's address chooses the try's speed (as the control does)
  const wanted = new URLSearchParams(location.search).get("speed");
  const select = $<HTMLSelectElement>("try-speed");
  if (wanted && [...select.options].some((o) => o.value === wanted)) select.value = wanted;
}
showTab("map");
showProblems([]);
void loadTemplates();
void loadFiles().then(() => {
  const wanted = new URLSearchParams(location.search).get("file") || location.hash.replace(/^#/, "");
  if (wanted && state.files.some((f) => f.path === wanted)) void openFile(wanted);
});
(window as any).studio = { editor, monaco, state, openFile, check };
