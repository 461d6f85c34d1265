// The tree pane: the compiled behaviour tree (POST /api/tree) laid out by elkjs (layered, left to right: a
// mission's tree is wide and shallow, so its steps stack down the pane and scroll like the text) and drawn as SVG;
// a tree too deep for the pane's width is drawn as an outline instead, so no part of it is cut off.
// Clicking a node selects its step in the text.
import ELK from "elkjs/lib/elk-api.js";

/** A node of /api/tree's answer (docs/studio.md): where its step is written, 1-based. */
export interface TreeNode {
  id: string | number;
  name: string;
  kind?: string;
  line?: number | null;
  column?: number | null;
  end_line?: number | null;
  end_column?: number | null;
}

/** /api/tree's answer: nodes, and edges parent -> child. */
export interface TreeData {
  nodes: TreeNode[];
  edges: Array<[string | number, string | number]>;
}

// The layout runs in its own worker (elk-worker.js, 1.4 MB), loaded when the tree is first shown.
let elk: InstanceType<typeof ELK> | null = null;
const SVG = "http://www.w3.org/2000/svg";
const FONT = "12px system-ui, -apple-system, 'Segoe UI', Roboto, 'Noto Sans', sans-serif";
const MAX_W = 220;
let measurer: CanvasRenderingContext2D | null = null;

/** A label's width in the tree's font (px). */
function textWidth(text: string): number {
  measurer ??= document.createElement("canvas").getContext("2d");
  if (!measurer) return text.length * 6.5;
  measurer.font = FONT;
  return measurer.measureText(text).width;
}
const COMPOSITES = new Set(["sequence", "selector", "fallback", "parallel", "repeat", "retry", "decorator",
  "root", "mission"]);

/** An SVG element with its attributes, appended to `parent` when given. */
function svg<K extends keyof SVGElementTagNameMap>(tag: K, attrs: Record<string, string | number>,
                                                  parent?: Element): SVGElementTagNameMap[K] {
  const el = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, String(v));
  if (parent) parent.appendChild(el);
  return el;
}

let drawn = 0;

interface Box { id: string; x?: number; y?: number; width?: number; height?: number }
interface Section { startPoint: { x: number; y: number }; endPoint: { x: number; y: number };
                    bendPoints?: Array<{ x: number; y: number }> }
/** A laid-out tree (ELK's answer, or the outline's): node boxes and edge polylines, px. */
interface Laid { width?: number; height?: number; children?: Box[]; edges?: Array<{ sections?: Section[] }>;
                 outline?: boolean }

/** Indent per level of the outline (px) and its row pitch (px). */
const INDENT = 18;
const ROW = 34;

/** The tree as an outline no wider than `width` px: each node on its own row in depth-first order, indented by its
 * depth, joined to its parent by an elbow from the parent's left side. */
function outline(data: TreeData, boxes: Array<{ id: string; width: number; height: number }>, width: number): Laid {
  const kids = new Map<string, string[]>();
  const hasParent = new Set<string>();
  for (const [a, b] of data.edges) {
    const list = kids.get(String(a)) ?? [];
    list.push(String(b));
    kids.set(String(a), list);
    hasParent.add(String(b));
  }
  const size = new Map(boxes.map((b) => [b.id, b]));
  const placed = new Map<string, Box>();
  const edges: Array<{ sections: Section[] }> = [];
  let row = 0;
  let right = 0;
  const visit = (id: string, depth: number, parent: Box | null): void => {
    if (placed.has(id)) return;  // a tree has none, but a shared node is drawn once
    const x = depth * INDENT;
    const w = Math.max(50, Math.min(size.get(id)?.width ?? 80, width - x));
    const box = { id, x, y: row * ROW, width: w, height: 28 };
    placed.set(id, box);
    right = Math.max(right, x + w);
    row += 1;
    if (parent) {
      const px = parent.x! + INDENT / 2;
      edges.push({ sections: [{ startPoint: { x: px, y: parent.y! + 28 }, bendPoints: [{ x: px, y: box.y + 14 }],
                                endPoint: { x: box.x, y: box.y + 14 } }] });
    }
    for (const k of kids.get(id) ?? []) visit(k, depth + 1, box);
  };
  for (const n of data.nodes) if (!hasParent.has(String(n.id))) visit(String(n.id), 0, null);
  for (const n of data.nodes) visit(String(n.id), 0, null);  // anything a cycle left out
  return { width: right, height: row * ROW - (ROW - 28), children: [...placed.values()], edges, outline: true };
}

/** Lay out and draw `data` into `host`; `select(node)` runs when a node is clicked. */
export async function drawTree(host: HTMLElement, data: TreeData | null, select: (node: TreeNode) => void,
                               message?: string): Promise<void> {
  const ticket = ++drawn;
  if (!data || !data.nodes?.length) {
    host.replaceChildren();
    const p = document.createElement("p");
    p.className = "muted pad";
    p.textContent = message ?? "No tree yet: fix the problems in the text first.";
    host.appendChild(p);
    return;
  }
  const label = (n: TreeNode): string => n.name || n.kind || String(n.id);
  const graph = {
    id: "root",
    layoutOptions: {
      "elk.algorithm": "layered",
      "elk.direction": "RIGHT",
      "elk.layered.spacing.nodeNodeBetweenLayers": "26",
      "elk.spacing.nodeNode": "8",
      "elk.edgeRouting": "ORTHOGONAL",
      "elk.layered.mergeEdges": "true",
      "elk.layered.nodePlacement.strategy": "BRANDES_KOEPF",
      "elk.layered.considerModelOrder.strategy": "NODES_AND_EDGES",
    },
    children: data.nodes.map((n) => ({
      id: String(n.id), width: Math.min(MAX_W, Math.max(50, textWidth(label(n)) + 20)), height: 28,
    })),
    edges: data.edges.map((e, i) => ({ id: `e${i}`, sources: [String(e[0])], targets: [String(e[1])] })),
  };
  elk ??= new ELK({ workerUrl: "elk-worker.js" });
  let laid: Laid = await elk.layout(graph as any) as Laid;
  if (ticket !== drawn) return;  // a newer tree came while this one was laid out
  const byId = new Map(data.nodes.map((n) => [String(n.id), n]));
  // A deep tree is shrunk to the pane's width (down to 75 %: the labels stay readable); deeper still, it is drawn
  // as an outline (one step a row, indented by depth), which fits a narrow pane (a 1024 px screen) whole.
  const room = host.clientWidth - 16;  // inside the view's padding
  let scale = Math.max(0.75, Math.min(1, room / ((laid.width ?? 0) + 20) || 1));
  if (((laid.width ?? 0) + 20) * scale > room) {
    laid = outline(data, graph.children, room - 20);
    scale = 1;
  }
  host.dataset.layout = laid.outline ? "outline" : "layered";
  const W = (laid.width ?? 0) + 20;
  const H = (laid.height ?? 0) + 20;
  const root = svg("svg", { width: W * scale, height: H * scale, viewBox: `-10 -10 ${W} ${H}`, class: "tree-svg" });
  const edges = svg("g", { class: "edges" }, root);
  for (const e of laid.edges ?? []) {
    for (const s of (e as any).sections ?? []) {
      const pts = [s.startPoint, ...(s.bendPoints ?? []), s.endPoint];
      svg("polyline", { points: pts.map((p: any) => `${p.x},${p.y}`).join(" ") }, edges);
    }
  }
  for (const c of laid.children ?? []) {
    const node = byId.get(c.id)!;
    const kind = (node.kind ?? "").toLowerCase();
    const g = svg("g", {
      class: `node ${COMPOSITES.has(kind) ? "composite" : "leaf"}`, transform: `translate(${c.x},${c.y})`,
      "data-testid": "tree-node", "data-node": String(node.id), "data-line": node.line ?? "", tabindex: 0,
      role: "button",
    }, root);
    svg("rect", { width: c.width!, height: c.height!, rx: 6 }, g);
    const t = svg("text", { x: c.width! / 2, y: c.height! / 2 + 4.5, "text-anchor": "middle" }, g);
    let text = label(node);
    while (text.length > 2 && textWidth(text) > c.width! - 14) text = text.slice(0, -2) + "…";
    t.textContent = text;
    const title = svg("title", {}, g);
    const what = node.kind ? ` (${node.kind})` : "";
    title.textContent = `${label(node)}${what}${node.line ? ` — line ${node.line}` : ""}`;
    const pick = () => {
      root.querySelectorAll(".node.selected").forEach((el) => el.classList.remove("selected"));
      g.classList.add("selected");
      select(node);
    };
    g.addEventListener("click", pick);
    g.addEventListener("keydown", (ev) => { if ((ev as KeyboardEvent).key === "Enter") pick(); });
  }
  host.replaceChildren(root);
}
