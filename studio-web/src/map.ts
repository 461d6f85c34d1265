// The map pane: Leaflet with no tiles by default. A GPS mission is drawn on a latitude/longitude grid drawn here;
// a world-frame mission (x east, y north, metres) on the world's plan, and a mission on a map (`map:`, x forward,
// y left of where mapping began, metres) on its occupancy grid with the world's plan moved onto it, both in
// Leaflet's flat CRS (lat = y, lng = x, metres, y up). Places are draggable markers; "Add place", "Draw fence" and
// "Make route" turn clicks into edits, which the caller sends to /api/edit.
import L from "leaflet";
import "leaflet/dist/leaflet.css";

/** A point as the API takes it: {lat, lon} on a GPS map, {x, y} (m) on a world or a map-frame map. */
export type Point = { lat: number; lon: number } | { x: number; y: number };

/** What /api/map answers (docs/studio.md, Map). */
export interface MapData {
  frame: "gps" | "world" | "map";
  datum?: { lat: number; lon: number } | null;
  places: Array<{ name: string; lat?: number; lon?: number; x?: number; y?: number; line?: number;
    tolerance_m?: number | null; yaw_deg?: number | null; readonly?: boolean; file?: string }>;
  /** The occupancy grid of a map-frame mission: a PNG and its corners [[x0, y0], [x1, y1]] (m). */
  map?: { file?: string; image?: string | null; bounds: number[][]; resolution_m?: number } | null;
  /** The mission's start on the map (map frame). */
  start?: { x: number; y: number; yaw_deg?: number } | null;
  fences: Array<{ name?: string; keep?: string; polygon?: number[][]; circle?: any; line?: number }>;
  routes?: Array<{ places: string[]; points?: number[][]; line?: number }>;
  world?: {
    name?: string; walls?: number[][]; obstacles?: any[]; lines?: any[];
    start?: { x: number; y: number; yaw_deg?: number } | null; bounds?: any;
    map_from_world?: { x: number; y: number; yaw_deg: number } | null;
  } | null;
  problems?: unknown[];
}

/** What the map asks of its owner: each becomes one /api/edit. */
export interface MapEdits {
  addPlace(at: Point): void;
  movePlace(name: string, to: Point): void;
  addFence(polygon: number[][]): void;
  addRoute(places: string[]): void;
  selectLine(line: number): void;
}

type Mode = "none" | "place" | "fence" | "route";
type Frame = "gps" | "world" | "map";
const TILE_URL = "https://tile.openstreetmap.org/{z}/{x}/{y}.png";

export class StudioMap {
  readonly map: L.Map;
  private frame: Frame | null = null;
  /** Where the simulator's world frame lies on a map-frame map (a run's robot is drawn through it). */
  private mapFromWorld: { x: number; y: number; yaw_deg: number } | null = null;
  private layers = L.layerGroup();
  private grid = L.layerGroup();
  private draft = L.layerGroup();
  private tiles: L.TileLayer | null = null;
  private mode: Mode = "none";
  private fencePoints: L.LatLng[] = [];
  private routeNames: string[] = [];
  private placeAt = new Map<string, L.LatLng>();
  private fitted = false;
  private dragging = false;

  constructor(private host: HTMLElement, private edits: MapEdits, private ui: {
    hint: HTMLElement; finish: HTMLButtonElement; cancel: HTMLButtonElement;
    buttons: Record<Exclude<Mode, "none">, HTMLButtonElement>;
  }) {
    this.map = this.makeMap("gps");
    // The run panel, the window or a tab switch can change the map's box: Leaflet must measure it again.
    new ResizeObserver(() => this.map.invalidateSize()).observe(host);
    ui.finish.addEventListener("click", () => this.finish());
    ui.cancel.addEventListener("click", () => this.setMode("none"));
    ui.buttons.place.addEventListener("click", () => this.setMode(this.mode === "place" ? "none" : "place"));
    ui.buttons.fence.addEventListener("click", () => this.setMode(this.mode === "fence" ? "none" : "fence"));
    ui.buttons.route.addEventListener("click", () => this.setMode(this.mode === "route" ? "none" : "route"));
    document.addEventListener("keydown", (e) => {
      if (e.key === "Escape" && this.mode !== "none") this.setMode("none");
    });
    this.setMode("none");
  }

  /** Whether this map is flat, in metres (a world's plan or a map frame), rather than latitude and longitude. */
  private get flat(): boolean { return this.frame === "world" || this.frame === "map"; }

  private makeMap(frame: Frame): L.Map {
    if (this.frame === frame && this.map) return this.map;
    if (this.map) this.map.remove();
    this.frame = frame;
    const flat = frame !== "gps";
    const map = L.map(this.host, {
      crs: flat ? L.CRS.Simple : L.CRS.EPSG3857,
      center: [0, 0],
      zoom: flat ? 3 : 2,
      minZoom: flat ? -3 : 2,
      maxZoom: flat ? 8 : 23,
      zoomSnap: 0.25,
      zoomControl: false,
      attributionControl: false,
      doubleClickZoom: false,
      boxZoom: false,
    });
    (this as any).map = map;
    L.control.zoom({ position: "topright" }).addTo(map);
    this.layers.addTo(map);
    this.grid.addTo(map);
    this.draft.addTo(map);
    // CRS.Simple's distance is in its own units, metres here: the same scale bar reads right on every frame
    L.control.scale({ imperial: false, position: "bottomright" }).addTo(map);
    map.on("click", (e: L.LeafletMouseEvent) => this.clicked(e.latlng));
    map.on("moveend zoomend", () => this.drawGrid());
    this.fitted = false;
    return map;
  }

  /** Online tiles under a GPS map (off by default: a field often has no internet). */
  setTiles(on: boolean, failed?: () => void): void {
    if (this.tiles) { this.tiles.remove(); this.tiles = null; }
    if (on && this.frame === "gps") {
      this.tiles = L.tileLayer(TILE_URL, { maxZoom: 23, maxNativeZoom: 19 }).addTo(this.map);
      this.tiles.bringToBack();
      // No internet (or a page policy that keeps the studio to itself): say so once, and go back to the grid.
      this.tiles.once("tileerror", () => { this.setTiles(false); failed?.(); });
    }
  }

  private datum: { lat: number; lon: number } | null = null;

  /** A point of the API (a [a, b] pair in the frame's order, {lat, lon} or {x, y}) on this map. */
  private toLatLng(p: any): L.LatLng | null {
    if (p == null) return null;
    if (Array.isArray(p)) return this.flat ? L.latLng(p[1], p[0]) : L.latLng(p[0], p[1]);
    if (typeof p.lat === "number" && this.frame === "gps") return L.latLng(p.lat, p.lon ?? p.lng);
    if (typeof p.x === "number") return this.worldToMap(p.x, p.y);
    return null;
  }

  /** A point of the world frame (x east, y north, metres from the datum) on this map; on a map-frame map the
   * API gives everything in the map frame already, so this is a point of that frame. */
  worldToMap(x: number, y: number): L.LatLng | null {
    if (this.flat) return L.latLng(y, x);
    if (!this.datum) return null;
    const R = 6378137;
    const lat = this.datum.lat + (y / R) * 180 / Math.PI;
    const lon = this.datum.lon + (x / (R * Math.cos(this.datum.lat * Math.PI / 180))) * 180 / Math.PI;
    return L.latLng(lat, lon);
  }

  private toPoint(ll: L.LatLng): Point {
    const round = (v: number, digits: number) => Number(v.toFixed(digits));
    return this.flat ? { x: round(ll.lng, 2), y: round(ll.lat, 2) }
      : { lat: round(ll.lat, 7), lon: round(ll.lng, 7) };
  }

  /** A corner for add_fence's polygon: [lat, lon] on a GPS map, [x, y] on a flat map. */
  private toPair(ll: L.LatLng): number[] {
    const p = this.toPoint(ll) as any;
    return this.flat ? [p.x, p.y] : [p.lat, p.lon];
  }

  /** Draw the mission's places, fences and routes (and the world's plan) afresh from /api/map's answer. */
  draw(data: MapData | null): void {
    if (this.dragging) return;  // a redraw under a dragged marker would drop it
    const frame: Frame = data?.frame === "world" || data?.frame === "map" ? data.frame : "gps";
    if (frame !== this.frame) {
      this.makeMap(frame);
      this.setTiles((document.getElementById("tiles") as HTMLInputElement | null)?.checked ?? false);
    }
    this.layers.clearLayers();
    this.placeAt.clear();
    if (!data) return;
    this.datum = data.datum ?? null;
    this.host.dataset.frame = frame;
    const bounds = L.latLngBounds([]);
    const world = data.world ?? null;
    this.mapFromWorld = frame === "map" ? world?.map_from_world ?? null : null;
    const grid = frame === "map" ? data.map ?? null : null;
    if (grid?.image && grid.bounds?.length === 2) {
      // The grid's image has its top row at the largest y: Leaflet's flat CRS has y up, as the map frame has.
      const [[x0, y0], [x1, y1]] = grid.bounds;
      const corners = L.latLngBounds([y0, x0], [y1, x1]);
      const overlay = L.imageOverlay(grid.image, corners, { className: "occupancy", interactive: false });
      overlay.addTo(this.layers);
      overlay.getElement()?.setAttribute("data-testid", "map-image");
      bounds.extend(corners);
    }
    const plan = { color: "#5f6368", weight: 2, fillColor: "#bdc1c6", fillOpacity: 0.6, interactive: false };
    const xy = (p: any) => Array.isArray(p) ? this.worldToMap(p[0], p[1]) : this.worldToMap(p.x, p.y);
    const pts = (list: any[]) => list.map(xy).filter(Boolean) as L.LatLng[];
    // On a map the world's walls go over the grid's cells, thin and see-through: where they and the map agree
    // the teacher sees one wall; where the map is off, both.
    const wallStyle = grid ? { ...plan, weight: 2, color: "#1967d2", opacity: 0.55 }
      : { ...plan, weight: 4, color: "#3c4043" };
    for (const w of world?.walls ?? []) {
      const line = pts([[w[0], w[1]], [w[2], w[3]]]);
      const wall = L.polyline(line, wallStyle).addTo(this.layers);
      (wall as any).getElement?.()?.setAttribute("data-testid", "wall");
      line.forEach((p) => bounds.extend(p));
    }
    const thing = grid ? { ...plan, color: "#1967d2", fillColor: "#8ab4f8", fillOpacity: 0.25, weight: 1 } : plan;
    for (const o of world?.obstacles ?? []) {
      const outline = Array.isArray(o) ? o : (o?.corners ?? o?.points ?? o?.polygon ?? o?.outline);
      const centre = Array.isArray(o?.xy) ? o.xy : Array.isArray(o?.path) ? o.path[0] : null;
      if (Array.isArray(outline) && outline.length >= 2) {
        const poly = pts(outline);
        L.polygon(poly, thing).addTo(this.layers);
        poly.forEach((p) => bounds.extend(p));
      } else if (o && (typeof o.x === "number" || centre) && o.radius_m) {
        const c = centre ? xy(centre) : xy(o);
        if (c) L.circle(c, { ...thing, radius: o.radius_m }).addTo(this.layers);
      }
    }
    for (const track of world?.lines ?? []) {
      const line = pts(Array.isArray(track) ? track : (track?.points ?? []));
      if (track?.closed && line.length) line.push(line[0]);
      L.polyline(line, { color: "#202124", weight: 3, opacity: 0.8, interactive: false }).addTo(this.layers);
      line.forEach((p) => bounds.extend(p));
    }
    const start = (frame === "map" ? data.start ?? world?.start : world?.start) ?? null;
    const startAt = start ? xy(start) : null;
    if (startAt) {
      L.marker(startAt, {
        icon: L.divIcon({ className: "home-marker", html: '<span class="pt"></span><span class="lbl">start</span>',
          iconSize: [0, 0] }),
        interactive: false, keyboard: false,
      }).addTo(this.layers);
      bounds.extend(startAt);
    }
    for (const fence of data.fences ?? []) {
      const keepIn = fence.keep === "in";
      const style = {
        color: keepIn ? "#188038" : "#d93025", weight: 2, dashArray: keepIn ? "6 4" : undefined,
        fillOpacity: keepIn ? 0.03 : 0.18, interactive: fence.line != null,
      };
      let shape: L.Path | null = null;
      if (fence.polygon?.length) {
        const corners = fence.polygon.map((p) => this.toLatLng(p)).filter(Boolean) as L.LatLng[];
        shape = L.polygon(corners, style);
        corners.forEach((p) => bounds.extend(p));
      } else if (fence.circle) {
        const c = this.toLatLng(fence.circle);
        if (c) { shape = L.circle(c, { ...style, radius: fence.circle.radius_m ?? 1 }); bounds.extend(c); }
      }
      if (!shape) continue;
      shape.addTo(this.layers);
      const el = (shape as any).getElement?.() as SVGElement | undefined;
      el?.setAttribute("data-testid", "fence");
      shape.bindTooltip(`${keepIn ? "keep-in" : "keep-out"} fence ${fence.name ?? ""}`);
      if (fence.line != null) {
        shape.on("click", () => { if (this.mode === "none") this.edits.selectLine(fence.line!); });
      }
    }
    for (const place of data.places ?? []) {
      const at = this.toLatLng(place);
      if (at) this.placeAt.set(place.name, at);
    }
    for (const route of data.routes ?? []) {
      const line = (route.points?.length ? route.points.map((p) => this.toLatLng(p))
        : route.places.map((n) => this.placeAt.get(n))).filter(Boolean) as L.LatLng[];
      L.polyline(line, { color: "#1a73e8", weight: 3, opacity: 0.7, dashArray: "8 6", interactive: false })
        .addTo(this.layers);
    }
    for (const place of data.places ?? []) {
      const at = this.placeAt.get(place.name);
      if (!at) continue;
      if (place.tolerance_m) {
        L.circle(at, { radius: place.tolerance_m, color: "#1a73e8", weight: 1, fillOpacity: 0.08, interactive: false })
          .addTo(this.layers);
      }
      const fixed = place.readonly === true;  // from a places file: the map does not edit another file
      const marker = L.marker(at, {
        draggable: this.mode === "none" && !fixed,
        icon: L.divIcon({
          className: "place-marker",
          html: `<span class="dot"></span><span class="label"></span>`,
          iconSize: [0, 0],
        }),
        title: fixed ? `place ${place.name}, from ${place.file ?? "a places file"}: change it there`
          : `place ${place.name}: drag to move it`,
        keyboard: false,
      }).addTo(this.layers);
      const el = marker.getElement()!;
      el.setAttribute("data-testid", "place-marker");
      el.setAttribute("data-place", place.name);
      if (fixed) { el.classList.add("readonly"); (marker as any).options.fixed = true; }
      (el.querySelector(".label") as HTMLElement).textContent = place.name;
      if (this.routeNames.includes(place.name)) el.classList.add("picked");
      marker.on("click", (e: L.LeafletMouseEvent) => {
        L.DomEvent.stopPropagation(e);
        if (this.mode === "route") this.pickForRoute(place.name, el);
        else if (this.mode === "fence") this.clicked(e.latlng);
        else if (this.mode === "none" && place.line != null) this.edits.selectLine(place.line);
      });
      marker.on("dragstart", () => { this.dragging = true; });
      marker.on("dragend", () => {
        this.dragging = false;
        this.edits.movePlace(place.name, this.toPoint(marker.getLatLng()));
      });
      bounds.extend(at);
    }
    if (!this.fitted) {
      const small = bounds.isValid() && (this.flat
        ? bounds.getNorthEast().distanceTo(bounds.getSouthWest()) < 4
        : this.map.distance(bounds.getNorthEast(), bounds.getSouthWest()) < 5);
      if (small) {
        // one point, or a few close together: show some 100 m round them, room to add places
        this.map.setView(bounds.getCenter(), this.flat ? 5 : 19);
      } else if (bounds.isValid()) {
        this.map.fitBounds(bounds.pad(this.frame === "map" ? 0.05 : 0.2), { maxZoom: this.flat ? 7 : 22 });
      } else if (this.frame === "gps" && this.datum) {
        this.map.setView([this.datum.lat, this.datum.lon], 18);  // nothing placed yet: the world's datum
      } else {
        this.map.setView([0, 0], this.flat ? 3 : 2);
      }
      this.fitted = true;
    }
    this.drawGrid();
  }

  /** The next file's map fits its own content again. */
  refit(): void { this.fitted = false; }

  /** A grid of about six lines across: degrees on a GPS map, metres on a world map, labelled at the edges. */
  private drawGrid(): void {
    this.grid.clearLayers();
    const b = this.map.getBounds();
    if (!b.isValid()) return;
    const span = Math.max(b.getEast() - b.getWest(), b.getNorth() - b.getSouth());
    const raw = span / 6;
    const mag = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) ?? 10 * mag;
    const digits = Math.max(0, -Math.floor(Math.log10(step)));
    const fmt = (v: number, axis: "x" | "y") => this.flat
      ? `${axis} ${v.toFixed(digits)} m`
      : `${Math.abs(v).toFixed(digits)}°${axis === "y" ? (v >= 0 ? "N" : "S") : (v >= 0 ? "E" : "W")}`;
    const line = { color: "#c7ccd1", weight: 1, interactive: false };
    const label = (at: L.LatLngExpression, text: string, cls: string) => L.marker(at, {
      icon: L.divIcon({ className: `grid-label ${cls}`, html: `<span>${text}</span>`, iconSize: [0, 0] }),
      interactive: false, keyboard: false,
    }).addTo(this.grid);
    for (let x = Math.ceil(b.getWest() / step) * step, n = 0; x <= b.getEast() && n < 40; x += step, n++) {
      L.polyline([[b.getSouth(), x], [b.getNorth(), x]], line).addTo(this.grid);
      label([b.getSouth(), x], fmt(x, "x"), "bottom");
    }
    for (let y = Math.ceil(b.getSouth() / step) * step, n = 0; y <= b.getNorth() && n < 40; y += step, n++) {
      L.polyline([[y, b.getWest()], [y, b.getEast()]], line).addTo(this.grid);
      label([y, b.getWest()], fmt(y, "y"), "left");
    }
  }

  private setMode(mode: Mode): void {
    this.mode = mode;
    this.fencePoints = [];
    this.routeNames = [];
    this.draft.clearLayers();
    for (const [m, button] of Object.entries(this.ui.buttons)) button.classList.toggle("active", m === mode);
    this.ui.finish.hidden = mode === "none" || mode === "place";
    this.ui.cancel.hidden = mode === "none";
    this.host.classList.toggle("picking", mode !== "none");
    this.host.querySelectorAll(".place-marker.picked").forEach((el) => el.classList.remove("picked"));
    this.layers.eachLayer((layer) => {
      const m = layer as L.Marker;
      if (m.dragging) {
        if (mode === "none" && !(m.options as any).fixed) m.dragging.enable(); else m.dragging.disable();
      }
    });
    this.showHint();
    this.updateFinish();
  }

  /** The hint line under the tools: what to do in the current mode. */
  showHint(): void {
    this.ui.hint.textContent = {
      none: "Drag a place to move it; click one to find it in the text.",
      place: "Click on the map where the new place is.",
      fence: "Click the corners of the area to keep out of, then Finish.",
      route: "Click the places in the order to visit them, then Finish.",
    }[this.mode];
    this.ui.hint.title = this.ui.hint.textContent ?? "";
  }

  private updateFinish(): void {
    this.ui.finish.disabled = this.mode === "fence" ? this.fencePoints.length < 3
      : this.mode === "route" ? this.routeNames.length < 2 : false;
    if (this.mode === "fence") this.ui.finish.textContent = `Finish fence (${this.fencePoints.length} corners)`;
    if (this.mode === "route") this.ui.finish.textContent = `Finish route (${this.routeNames.join(" → ") || "none"})`;
  }

  private clicked(at: L.LatLng): void {
    if (this.mode === "place") {
      this.setMode("none");
      this.edits.addPlace(this.toPoint(at));
    } else if (this.mode === "fence") {
      this.fencePoints.push(at);
      this.draft.clearLayers();
      L.polygon(this.fencePoints, { color: "#d93025", dashArray: "4 4", fillOpacity: 0.1, interactive: false })
        .addTo(this.draft);
      for (const p of this.fencePoints) {
        L.circleMarker(p, { radius: 4, color: "#d93025", fillOpacity: 1, interactive: false }).addTo(this.draft);
      }
      this.updateFinish();
    }
  }

  private pickForRoute(name: string, el: HTMLElement): void {
    if (this.routeNames[this.routeNames.length - 1] === name) return;
    this.routeNames.push(name);
    el.classList.add("picked");
    this.draft.clearLayers();
    L.polyline(this.routeNames.map((n) => this.placeAt.get(n)!), { color: "#1a73e8", dashArray: "6 4", weight: 3 })
      .addTo(this.draft);
    this.updateFinish();
  }

  private finish(): void {
    if (this.mode === "fence" && this.fencePoints.length >= 3) {
      const points = this.fencePoints.map((p) => this.toPair(p));
      this.setMode("none");
      this.edits.addFence(points);
    } else if (this.mode === "route" && this.routeNames.length >= 2) {
      const names = [...this.routeNames];
      this.setMode("none");
      this.edits.addRoute(names);
    }
  }

  private robot: L.Marker | null = null;
  private trail: L.Polyline | null = null;

  /** The simulated robot of a run (world-frame pose: x east, y north in metres, yaw counter-clockwise from east),
   * with its trail; null takes both away. */
  showRobot(pose: { x: number; y: number; yaw_deg?: number } | null): void {
    if (!pose) {
      this.robot?.remove(); this.trail?.remove();
      this.robot = null; this.trail = null;
      return;
    }
    let { x, y } = pose;
    let yawDeg = pose.yaw_deg ?? 90;
    if (this.mapFromWorld) {  // the simulator's pose is in the world frame: onto the map as the API moved the walls
      const t = this.mapFromWorld, a = t.yaw_deg * Math.PI / 180;
      [x, y] = [t.x + Math.cos(a) * pose.x - Math.sin(a) * pose.y, t.y + Math.sin(a) * pose.x + Math.cos(a) * pose.y];
      yawDeg += t.yaw_deg;
    }
    const at = this.worldToMap(x, y);
    if (!at) return;
    if (!this.robot) {
      this.robot = L.marker(at, {
        icon: L.divIcon({ className: "robot-marker", html: '<span class="arrow"></span>', iconSize: [0, 0] }),
        interactive: false, keyboard: false, zIndexOffset: 1000,
      }).addTo(this.map);
      this.trail = L.polyline([], { color: "#e37400", weight: 3, opacity: 0.8, interactive: false }).addTo(this.map);
    }
    this.robot.setLatLng(at);
    const arrow = this.robot.getElement()?.querySelector(".arrow") as HTMLElement | null;
    if (arrow) arrow.style.transform = `rotate(${90 - yawDeg}deg)`;
    this.trail!.addLatLng(at);
  }

  /** Leaflet measures its box again (after its pane was hidden or resized). */
  resize(): void { this.map.invalidateSize(); }
}
