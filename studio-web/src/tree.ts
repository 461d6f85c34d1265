// The tree pane: the compiled behaviour tree (POST /api/tree) laid out by elkjs (layered, left to right: a
// mission's tree is wide and shallow, so its steps stack down the pane and scroll like the text) and drawn as SVG.
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
  const laid = await elk.layout(graph as any);
  if (ticket !== drawn) return;  // a newer tree came while this one was laid out
  const byId = new Map(data.nodes.map((n) => [String(n.id), n]));
  const W = (laid.width ?? 0) + 20;
  const H = (laid.height ?? 0) + 20;
  // A deep tree is shrunk to the pane's width (down to 80 %: the labels stay readable); deeper still, it scrolls.
  const scale = Math.max(0.75, Math.min(1, (host.clientWidth - 20) / W || 1));
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
