// swarmdsl studio: the view, plots and controls shared by the web page and the
// notebook widget. No build step and no libraries: canvas 2D only. The page loads this
// file as a script; the widget sends it as the first part of its ES module. Both give
// a StudioCore a transport ({send(obj)}) and feed it what the server sends: JSON text
// (scene, results) through onText, binary frames through onFrame.
"use strict";

// ---- frames (swarmdsl/studio/wire.py) ----
function decodeFrame(buffer) {
  const bytes = new Uint8Array(buffer);
  if (bytes[0] !== 83 || bytes[1] !== 87 || bytes[2] !== 70 || bytes[3] !== 49) {
    throw new Error("not a studio frame");
  }
  const view = new DataView(buffer);
  const n = view.getUint32(4, true);
  const header = JSON.parse(new TextDecoder().decode(bytes.subarray(8, 8 + n)));
  const types = {float32: Float32Array, uint8: Uint8Array, uint16: Uint16Array,
                 uint32: Uint32Array, int32: Int32Array};
  let offset = Math.ceil((8 + n) / 4) * 4;
  const arrays = {};
  for (const [name, dtype, size] of header.arrays) {
    const T = types[dtype];
    arrays[name] = new T(buffer, offset, size);
    offset = Math.ceil((offset + size * T.BYTES_PER_ELEMENT) / 4) * 4;
  }
  return {header, arrays};
}

function rgb(c) { return `rgb(${c[0]},${c[1]},${c[2]})`; }

// ---- the swarm view (the pygame viewer's layers, viz/frames.py) ----
class ViewRenderer {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.scene = null;
    this.splatAbove = 3000;
    this.fieldCanvas = document.createElement("canvas");
    this.agentCanvas = document.createElement("canvas");
    this.agentImage = null;
    this.gridCanvas = document.createElement("canvas");
    this.gridImage = null;
  }
  setScene(scene) {
    this.scene = scene;
    const lut = new Uint32Array(256);
    const little = new Uint8Array(new Uint32Array([1]).buffer)[0] === 1;
    (scene.lut || []).forEach((c, i) => {
      lut[i] = little ? (255 << 24 | c[2] << 16 | c[1] << 8 | c[0]) >>> 0
                      : (c[0] << 24 | c[1] << 16 | c[2] << 8 | 255) >>> 0;
    });
    this.lut = lut;
    this.little = little;
  }
  transform() {
    const W = this.canvas.width, H = this.canvas.height;
    const [ww, wh] = this.scene.world;
    const s = Math.min(W / ww, H / wh);
    return {s, ox: (W - ww * s) / 2, oy: (H - wh * s) / 2, wh, ww};
  }
  worldAt(px, py) {
    const t = this.transform();
    return [(px - t.ox) / t.s, t.wh - (py - t.oy) / t.s, 12 / t.s];
  }
  draw(frame, opts) {
    const ctx = this.ctx, scene = this.scene, W = this.canvas.width, H = this.canvas.height;
    const col = scene.colours;
    ctx.fillStyle = rgb(col.letterbox);
    ctx.fillRect(0, 0, W, H);
    if (!scene.world) return;
    const t = this.transform();
    const X = x => t.ox + x * t.s, Y = y => t.oy + (t.wh - y) * t.s;
    ctx.fillStyle = rgb(col.background);
    ctx.fillRect(t.ox, t.oy, t.ww * t.s, t.wh * t.s);
    const a = frame.arrays, h = frame.header;
    if (a.field && h.field) this.drawField(a.field, h.field, t, X, Y);
    if (a.grid_points || a.grid_x) this.drawGrid(a, W, H, X, Y);
    if (a.vectors && h.vectors) this.drawVectors(a, h.vectors, X, Y);
    ctx.strokeStyle = rgb(col.border);
    ctx.lineWidth = 1;
    ctx.strokeRect(t.ox + 0.5, t.oy + 0.5, t.ww * t.s - 1, t.wh * t.s - 1);
    const pos = a.pos || new Float32Array(0), n = h.n || 0;
    if (a.links) {
      ctx.strokeStyle = rgb(col.link);
      ctx.beginPath();
      const L = Math.min(a.links.length, 40000);
      for (let i = 0; i < L; i += 2) {
        const p = a.links[i], q = a.links[i + 1];
        ctx.moveTo(X(pos[2 * p]), Y(pos[2 * p + 1]));
        ctx.lineTo(X(pos[2 * q]), Y(pos[2 * q + 1]));
      }
      ctx.stroke();
    }
    const colours = this.colours(frame, opts);
    if (a.believed) {
      ctx.strokeStyle = rgb(col.belief);
      ctx.beginPath();
      for (let i = 0; i < n; i++) {
        ctx.moveTo(X(a.believed[2 * i]), Y(a.believed[2 * i + 1]));
        ctx.lineTo(X(pos[2 * i]), Y(pos[2 * i + 1]));
      }
      ctx.stroke();
    }
    // big swarms' headings come as bytes, 256 to a turn (wire.py: `heading8`)
    const heading = a.heading || Float32Array.from(a.heading8, v => v * Math.PI / 128);
    if (n > this.splatAbove) this.splat(pos, a.heading, a.heading8, colours, n, W, H);
    else this.triangles(pos, heading, colours, n, X, Y, false);
    if (a.believed) this.triangles(a.believed, heading, colours, n, X, Y, true);
    if (opts.regions !== false) this.drawRegions(scene.regions || [], X, Y, t);
    if (h.selected && h.selected.row !== undefined && h.selected.row < n) {
      const r = h.selected.row;
      ctx.strokeStyle = "#ffffff";
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.arc(X(pos[2 * r]), Y(pos[2 * r + 1]), 9, 0, 2 * Math.PI);
      ctx.stroke();
      ctx.lineWidth = 1;
    }
    this.drawLegend(frame, colours, opts);
  }
  colours(frame, opts) {
    // what colours the agents: codes (one per agent) into a palette, with the legend's
    // names; LED colours, when the program sets them, paint over the status codes
    const a = frame.arrays, scene = this.scene;
    if (opts.leaf && a.leaf) {
      return {codes: a.leaf, palette: [scene.colours.no_leaf].concat(scene.leaf_palette),
              names: ["(no leaf)"].concat((scene.leaf_names || []).slice(1)), hideEmpty: true};
    }
    if (opts.kind) return {codes: a.kind, palette: scene.kind_palette, names: scene.kind_names};
    return {codes: a.status, palette: scene.palette, names: scene.status_names,
            led: opts.led !== false ? a.led : undefined};
  }
  colourOf(colours, i) {
    if (colours.led) return [colours.led[3 * i], colours.led[3 * i + 1], colours.led[3 * i + 2]];
    const p = colours.palette;
    return p[colours.codes[i] % p.length] || [200, 200, 200];
  }
  triangles(pos, heading, colours, n, X, Y, hollow) {
    const ctx = this.ctx;
    const len = n < 200 ? 10 : n < 1000 ? 7 : 5;
    const groups = new Map();
    for (let i = 0; i < n; i++) {
      const key = colours.led ? i : colours.codes[i];
      let g = groups.get(key);
      if (!g) { g = []; groups.set(key, g); }
      g.push(i);
    }
    for (const [, members] of groups) {
      const c = rgb(this.colourOf(colours, members[0]));
      ctx.beginPath();
      for (const i of members) {
        const x = X(pos[2 * i]), y = Y(pos[2 * i + 1]);
        if (!isFinite(x) || !isFinite(y)) continue;
        const dx = Math.cos(heading[i]), dy = -Math.sin(heading[i]);
        const w = len * 0.45;
        ctx.moveTo(x + dx * len * 0.6, y + dy * len * 0.6);
        ctx.lineTo(x - dx * len * 0.4 - dy * w, y - dy * len * 0.4 + dx * w);
        ctx.lineTo(x - dx * len * 0.4 + dy * w, y - dy * len * 0.4 - dx * w);
        ctx.closePath();
      }
      if (hollow) { ctx.strokeStyle = c; ctx.stroke(); } else { ctx.fillStyle = c; ctx.fill(); }
    }
  }
  splat(pos, heading, heading8, colours, n, W, H) {
    // big swarms: a 3x3 body and a nose pixel (a body pixel and a nose above 30,000),
    // written into one pixel buffer, as viz/markers.py does
    if (!this.agentImage || this.agentImage.width !== W || this.agentImage.height !== H) {
      this.agentCanvas.width = W;
      this.agentCanvas.height = H;
      this.agentImage = this.agentCanvas.getContext("2d").createImageData(W, H);
      this.agentPixels = new Uint32Array(this.agentImage.data.buffer);
    }
    const px = this.agentPixels;
    px.fill(0);
    const packed = [];
    const pack = c => this.little ? (255 << 24 | c[2] << 16 | c[1] << 8 | c[0]) >>> 0
                                  : (c[0] << 24 | c[1] << 16 | c[2] << 8 | 255) >>> 0;
    if (!colours.led) for (const c of colours.palette) packed.push(pack(c));
    const big = n <= 30000, r = big ? 2 : 1;
    const t = this.transform(), s = t.s, ox = t.ox + 0.5, oy = t.oy + t.wh * s + 0.5;
    const led = colours.led, codes = colours.codes, k = packed.length;
    // the nose pixel's offset for each of 8 headings (y down on the screen)
    const nose = [0, 1, 2, 3, 4, 5, 6, 7].map(j => {
      const a = j * Math.PI / 4;
      return Math.round(-Math.sin(a) * r) * W + Math.round(Math.cos(a) * r);
    });
    for (let i = 0; i < n; i++) {
      const x = (ox + pos[2 * i] * s) | 0, y = (oy - pos[2 * i + 1] * s) | 0;
      if (!(x >= 1 && y >= 1 && x < W - 1 && y < H - 1)) continue;
      const c = led ? pack(this.colourOf(colours, i)) : packed[codes[i] % k];
      const o = y * W + x;
      px[o] = c;
      if (big) {
        px[o - 1] = c; px[o + 1] = c; px[o - W] = c; px[o + W] = c;
        px[o - W - 1] = c; px[o - W + 1] = c; px[o + W - 1] = c; px[o + W + 1] = c;
      }
      const q = o + nose[heading8 ? ((heading8[i] + 16) >> 5) & 7
                                  : Math.round(heading[i] * 1.2732395447351628) & 7];  // 4/pi
      if (q >= 0 && q < px.length) px[q] = c;
    }
    this.agentCanvas.getContext("2d").putImageData(this.agentImage, 0, 0);
    this.ctx.drawImage(this.agentCanvas, 0, 0);
  }
  drawField(values, f, t, X, Y) {
    const fc = this.fieldCanvas;
    if (fc.width !== f.nx || fc.height !== f.ny) { fc.width = f.nx; fc.height = f.ny; }
    const fctx = fc.getContext("2d");
    const img = fctx.createImageData(f.nx, f.ny);
    const out = new Uint32Array(img.data.buffer);
    for (let j = 0; j < f.ny; j++) {               // row 0 of the image is the top
      const src = (f.ny - 1 - j) * f.nx, dst = j * f.nx;
      for (let i = 0; i < f.nx; i++) out[dst + i] = this.lut[values[src + i]];
    }
    fctx.putImageData(img, 0, 0);
    const dx = f.nx > 1 ? (f.x1 - f.x0) / (f.nx - 1) : t.ww;
    const dy = f.ny > 1 ? (f.y1 - f.y0) / (f.ny - 1) : t.wh;
    const ctx = this.ctx;
    ctx.save();
    ctx.beginPath();
    ctx.rect(t.ox, t.oy, t.ww * t.s, t.wh * t.s);
    ctx.clip();
    ctx.imageSmoothingEnabled = false;
    const left = X(f.x0 - dx / 2), top = Y(f.y1 + dy / 2);
    ctx.drawImage(fc, left, top, X(f.x1 + dx / 2) - left, Y(f.y0 - dy / 2) - top);
    ctx.restore();
  }
  drawGrid(a, W, H, X, Y) {
    // one pixel per grid node (a refined grid's every node, else the product of the
    // axes), as viz/layers.py draw_grid_points: written into a pixel buffer
    if (!this.gridImage || this.gridImage.width !== W || this.gridImage.height !== H) {
      this.gridCanvas.width = W;
      this.gridCanvas.height = H;
      this.gridImage = this.gridCanvas.getContext("2d").createImageData(W, H);
      this.gridPixels = new Uint32Array(this.gridImage.data.buffer);
    }
    const px = this.gridPixels, c = this.scene.colours.grid_point;
    const v = this.little ? (255 << 24 | c[2] << 16 | c[1] << 8 | c[0]) >>> 0
                          : (c[0] << 24 | c[1] << 16 | c[2] << 8 | 255) >>> 0;
    px.fill(0);
    const put = (x, y) => {
      x = Math.round(x); y = Math.round(y);
      if (x >= 0 && y >= 0 && x < W && y < H) px[y * W + x] = v;
    };
    if (a.grid_points) {
      const p = a.grid_points;
      for (let i = 0; i < p.length; i += 2) put(X(p[i]), Y(p[i + 1]));
    } else {
      const xs = Array.from(a.grid_x, X), ys = Array.from(a.grid_y, Y);
      for (const y of ys) for (const x of xs) put(x, y);
    }
    this.gridCanvas.getContext("2d").putImageData(this.gridImage, 0, 0);
    this.ctx.drawImage(this.gridCanvas, 0, 0);
  }
  drawVectors(a, f, X, Y) {
    // an arrow per node of the subsampled grid, the longest 0.8 of the spacing
    // (`scale`), with two barbs, as viz/layers.py draw_vectors
    const ctx = this.ctx, v = a.vectors, gx = a.vector_x, gy = a.vector_y;
    ctx.strokeStyle = rgb(this.scene.colours.arrow);
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let j = 0; j < f.ny; j++) {
      for (let i = 0; i < f.nx; i++) {
        const k = 2 * (j * f.nx + i);
        const ax = X(gx[i]), ay = Y(gy[j]);
        const bx = X(gx[i] + v[k] * f.scale), by = Y(gy[j] + v[k + 1] * f.scale);
        const dx = bx - ax, dy = by - ay, n = Math.hypot(dx, dy);
        if (!(n >= 1)) continue;            // too short to see, or not finite
        const ux = dx / n, uy = dy / n, barb = 0.3 * Math.min(n, 12);
        ctx.moveTo(ax, ay);
        ctx.lineTo(bx, by);
        ctx.lineTo(bx - barb * (ux + uy), by - barb * (uy - ux));
        ctx.moveTo(bx, by);
        ctx.lineTo(bx - barb * (ux - uy), by - barb * (uy + ux));
      }
    }
    ctx.stroke();
  }
  drawRegions(regions, X, Y, t) {
    const ctx = this.ctx, col = this.scene.colours;
    ctx.font = "12px sans-serif";
    for (const r of regions) {
      const c = rgb(col.regions[r.kind] || col.region);
      ctx.strokeStyle = c;
      ctx.fillStyle = c;
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      let lx = 0, ly = 0;
      if (r.shape === "circle") {
        ctx.arc(X(r.center[0]), Y(r.center[1]), r.radius * t.s, 0, 2 * Math.PI);
        lx = X(r.center[0]); ly = Y(r.center[1] + r.radius) - 4;
      } else if (r.shape === "rect") {
        ctx.rect(X(r.min[0]), Y(r.max[1]), (r.max[0] - r.min[0]) * t.s,
                 (r.max[1] - r.min[1]) * t.s);
        lx = X((r.min[0] + r.max[0]) / 2); ly = Y(r.max[1]) - 4;
      } else if (r.shape === "polygon") {
        r.points.forEach(([x, y], i) => i ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y)));
        ctx.closePath();
        const top = r.points.reduce((m, p) => p[1] > m[1] ? p : m, r.points[0]);
        lx = X(top[0]); ly = Y(top[1]) - 4;
      }
      ctx.stroke();
      ctx.textAlign = "center";
      ctx.fillText(r.label || r.name || "", lx, ly);
      ctx.textAlign = "start";
    }
    ctx.lineWidth = 1;
  }
  drawLegend(frame, colours, opts) {
    const ctx = this.ctx, scene = this.scene, h = frame.header;
    const {names, codes, palette} = colours;
    const counts = new Array(names.length).fill(0);
    if (codes) for (let i = 0; i < h.n; i++) if (codes[i] < counts.length) counts[codes[i]]++;
    ctx.font = "13px sans-serif";
    ctx.textBaseline = "top";
    let y = 8;
    names.forEach((name, i) => {
      if (colours.hideEmpty && !counts[i]) return;
      const c = palette[i % palette.length] || [200, 200, 200];
      ctx.fillStyle = rgb(c);
      ctx.fillRect(8, y + 2, 10, 10);
      ctx.fillStyle = rgb(scene.colours.text);
      ctx.fillText(`${name} ${counts[i]}`, 24, y);
      y += 17;
    });
    ctx.textAlign = "right";
    ctx.fillText(`tick ${h.tick}`, this.canvas.width - 8, 8);
    if (h.field) ctx.fillText(`${h.field.name} ${h.field.lo.toPrecision(3)}..` +
                              `${h.field.hi.toPrecision(3)} (magma)`,
                              this.canvas.width - 8, this.canvas.height - 20);
    if (h.vectors) ctx.fillText(`${h.vectors.name} arrows, longest ` +
                                `${h.vectors.top.toPrecision(3)}`,
                                this.canvas.width - 8, this.canvas.height - (h.field ? 38 : 20));
    ctx.textAlign = "start";
    ctx.textBaseline = "alphabetic";
  }
}

// ---- live plots ----
class Plot {
  constructor(parent, title, names, colours) {
    this.box = document.createElement("div");
    this.box.className = "plot";
    this.label = document.createElement("div");
    this.label.className = "plot-title";
    this.canvas = document.createElement("canvas");
    this.canvas.width = 280;
    this.canvas.height = 90;
    this.box.append(this.label, this.canvas);
    parent.append(this.box);
    this.title = title;
    this.names = names;
    this.colours = colours;
    this.ticks = [];
    this.series = names.map(() => []);
  }
  add(tick, values) {
    this.ticks.push(tick);
    values.forEach((v, i) => this.series[i].push(v));
    if (this.ticks.length > 4000) {         // halve: every other point
      this.ticks = this.ticks.filter((_, i) => i % 2 === 0 || i === this.ticks.length - 1);
      this.series = this.series.map(s => s.filter((_, i) => i % 2 === 0 || i === s.length - 1));
    }
  }
  draw() {
    const ctx = this.canvas.getContext("2d"), W = this.canvas.width, H = this.canvas.height;
    ctx.fillStyle = "#16181e";
    ctx.fillRect(0, 0, W, H);
    const last = this.series.map(s => s.length ? s[s.length - 1] : null);
    this.label.textContent = this.title + ": " + last.map(
      (v, i) => (this.names.length > 1 ? this.names[i] + " " : "") +
        (v === null ? "–" : Number.isInteger(v) ? String(v) : Number(v).toPrecision(4))
    ).join(", ");
    if (this.ticks.length < 1) return;
    let lo = Infinity, hi = -Infinity;
    for (const s of this.series) for (const v of s) if (v !== null) {
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
    if (!isFinite(lo)) return;
    if (hi === lo) { hi += 0.5; lo -= 0.5; }
    const t0 = this.ticks[0], t1 = Math.max(this.ticks[this.ticks.length - 1], t0 + 1);
    const X = t => 4 + (t - t0) / (t1 - t0) * (W - 8), Y = v => H - 14 - (v - lo) / (hi - lo) * (H - 22);
    this.series.forEach((s, k) => {
      ctx.strokeStyle = rgb(this.colours[k % this.colours.length]);
      ctx.beginPath();
      let pen = false;
      s.forEach((v, i) => {
        if (v === null) { pen = false; return; }
        if (pen) ctx.lineTo(X(this.ticks[i]), Y(v)); else ctx.moveTo(X(this.ticks[i]), Y(v));
        pen = true;
      });
      ctx.stroke();
    });
    ctx.fillStyle = "#9a9cab";
    ctx.font = "10px sans-serif";
    ctx.fillText(`${Number(hi).toPrecision(3)}`, 4, 10);
    ctx.fillText(`${Number(lo).toPrecision(3)}  ticks ${t0}..${this.ticks[this.ticks.length - 1]}`,
                 4, H - 3);
  }
  points() { return this.ticks.length; }
}

// ---- the view, controls, sliders, plots and inspector, bound to a transport ----
class StudioCore {
  constructor(root, transport) {
    this.root = root;
    this.transport = transport;
    this.scene = null;
    this.frame = null;
    this.pending = null;
    this.drawing = false;
    this.received = 0;          // frames come since the last one drawn
    this.opts = {field: null, vectors: null, grid: false, links: false, believed: false, leaf: false, kind: false,
                 regions: true};
    this.frames = 0;            // frames drawn (the benchmark reads it)
    this.lastResult = null;
    this.onScene = null;        // the page adds the editor's part
    this.build();
  }
  el(tag, cls, text) {
    const e = document.createElement(tag);
    if (cls) e.className = cls;
    if (text !== undefined) e.textContent = text;
    return e;
  }
  build() {
    const r = this.root;
    r.classList.add("swarm-studio");
    this.bar = this.el("div", "controls");
    const button = (label, title, fn, id) => {
      const b = this.el("button", "", label);
      b.title = title;
      if (id) b.dataset.role = id;
      b.addEventListener("click", fn);
      this.bar.append(b);
      return b;
    };
    this.playButton = button("▶ play", "play / pause (space)", () =>
      this.send({op: this.scene && this.scene.playing ? "pause" : "play"}), "play");
    button("step", "one tick", () => this.send({op: "step", n: 1}), "step");
    button("−", "half as fast", () => this.speedBy(0.5), "slower");
    this.speedLabel = this.el("span", "speed", "1 tick/frame");
    this.bar.append(this.speedLabel);
    button("+", "twice as fast", () => this.speedBy(2), "faster");
    button("reset", "back to tick 0", () => this.send({op: "reset"}), "reset");
    const seedLabel = this.el("label", "", "seed ");
    this.seedInput = this.el("input");
    this.seedInput.type = "number";
    this.seedInput.min = "0";
    this.seedInput.dataset.role = "seed";
    this.seedInput.addEventListener("change", () =>
      this.send({op: "seed", value: Number(this.seedInput.value)}));
    seedLabel.append(this.seedInput);
    this.bar.append(seedLabel);
    const menu = (key, title) => {       // which field (or vector field) is drawn
      const m = this.el("select");
      m.dataset.role = key;
      m.title = title;
      m.addEventListener("change", () => { this.opts[key] = m.value || null; this.sendLayers(); });
      this.bar.append(m);
      return m;
    };
    this.fieldSelect = menu("field", "field heatmap (f, tab)");
    this.vectorSelect = menu("vectors", "vector field arrows (v)");
    this.toggles = {};
    for (const [key, label] of [["grid", "grid nodes"], ["links", "links"], ["believed", "believed"],
                                ["leaf", "tree leaf"], ["kind", "by kind"]]) {
      const l = this.el("label", "toggle");
      const c = this.el("input");
      c.type = "checkbox";
      c.dataset.role = key;
      c.addEventListener("change", () => { this.opts[key] = c.checked; this.sendLayers(); });
      this.toggles[key] = c;
      l.append(c, " " + label);
      this.bar.append(l);
    }
    this.canvas = this.el("canvas", "view");
    this.canvas.width = 640;
    this.canvas.height = 480;
    this.canvas.addEventListener("click", e => this.click(e));
    this.renderer = new ViewRenderer(this.canvas);
    this.status = this.el("div", "status");
    this.params = this.el("div", "params");
    this.setLine = this.el("code", "set-line");
    this.inspector = this.el("div", "inspector");
    this.plotBox = this.el("div", "plots");
    this.viewBox = this.el("div", "view-box");
    this.viewBox.append(this.bar, this.canvas, this.status);
    this.side = this.el("div", "side");
    this.recordedBox = this.el("div", "plots recorded");
    this.side.append(this.el("h3", "", "params"), this.params,
                     this.el("h3", "", "reproduce"), this.setLine,
                     this.el("h3", "", "agent"), this.inspector,
                     this.el("h3", "", "plots"), this.plotBox, this.recordedBox);
    r.append(this.viewBox, this.side);
  }
  send(obj) { this.transport.send(obj); }
  key(e) {
    // the pygame viewer's keys (viewer.md); true when the key was one of them
    const fields = (this.scene && this.scene.fields) || [];
    const vectors = (this.scene && this.scene.vectors) || [];
    const showField = name => {
      if (this.opts.field) this.lastField = this.opts.field;
      this.opts.field = name;
      this.fieldSelect.value = name || "";
      this.sendLayers();
    };
    const showVectors = name => {
      if (this.opts.vectors) this.lastVectors = this.opts.vectors;
      this.opts.vectors = name;
      this.vectorSelect.value = name || "";
      this.sendLayers();
    };
    if (e.key === " ") this.playButton.click();
    else if (e.key === "." || e.key === "ArrowRight") this.send({op: "step", n: 1});
    else if (e.key === "+" || e.key === "=") this.speedBy(2);
    else if (e.key === "-") this.speedBy(0.5);
    else if (e.key === "f" && fields.length) {
      showField(this.opts.field ? null : this.lastField || fields[0]);
    } else if (e.key === "Tab" && fields.length) {
      showField(fields[(fields.indexOf(this.opts.field) + 1) % fields.length]);
    } else if (e.key === "v" && vectors.length) {
      showVectors(this.opts.vectors ? null : this.lastVectors || vectors[0]);
    } else if (e.key === "g" && this.scene && this.scene.grid) this.toggles.grid.click();
    else if (e.key === "l") this.toggles.links.click();
    else if (e.key === "b") this.toggles.believed.click();
    else if (e.key === "t") this.toggles.leaf.click();
    else if (e.key === "k") this.toggles.kind.click();
    else return false;
    return true;
  }
  sendLayers() {
    this.send({op: "layers", field: this.opts.field, vectors: this.opts.vectors,
               grid: this.opts.grid, links: this.opts.links,
               believed: this.opts.believed, leaf: this.opts.leaf});
  }
  speedBy(f) {
    if (this.scene) this.send({op: "speed", value: this.scene.speed * f});
  }
  hello() {
    // a new connection: say what to draw, then ask for everything
    this.drawing = false;
    this.received = 0;
    this.sendLayers();
    this.send({op: "hello"});
  }
  click(e) {
    if (!this.scene || !this.scene.world) return;
    const rect = this.canvas.getBoundingClientRect();
    const px = (e.clientX - rect.left) * this.canvas.width / rect.width;
    const py = (e.clientY - rect.top) * this.canvas.height / rect.height;
    const [x, y, reach] = this.renderer.worldAt(px, py);
    this.send({op: "inspect", x, y, reach});
  }
  onText(msg) {
    if (msg.type === "scene") this.setScene(msg);
    else if (msg.type === "result") this.result(msg);
  }
  result(msg) {
    this.lastResult = msg;
    if (msg.op === "param") {
      const box = this.params.querySelector(`[data-param="${msg.name}"] .param-error`);
      if (box) box.textContent = (msg.errors || []).map(d => d.message).join("; ");
    } else if (msg.errors && msg.errors.length && msg.op !== "run") {
      this.status.textContent = msg.errors.map(d => d.text).join("\n");
    }
    if (this.onResult) this.onResult(msg);
  }
  setScene(scene) {
    this.scene = scene;
    this.renderer.setScene(scene);
    this.playButton.textContent = scene.playing ? "❚❚ pause" : "▶ play";
    this.speedLabel.textContent = this.speedText(scene.speed);
    this.seedInput.value = scene.seed;
    this.setLine.textContent = (scene.set_line || "") + (scene.changed_at ?
      `   (values changed at tick ${scene.changed_at})` : "");
    // no command makes the run (the text running is not the file's): say so, in yellow
    this.setLine.classList.toggle("save-first", scene.set_line_exact === false);
    const fields = scene.fields || [], vectors = scene.vectors || [];
    this.fillChoices(this.fieldSelect, fields, fields.length ? "no field" : "no fields");
    this.fillChoices(this.vectorSelect, vectors, "no arrows");
    this.vectorSelect.hidden = !vectors.length;
    let changed = false;
    if (this.firstScene === undefined) {    // the viewer shows the first of each at start
      if (this.opts.field === null && fields.length) this.opts.field = fields[0];
      if (this.opts.vectors === null && vectors.length) this.opts.vectors = vectors[0];
      changed = !!(this.opts.field || this.opts.vectors);
    }
    this.firstScene = false;
    if (this.opts.field && !fields.includes(this.opts.field)) {
      this.opts.field = null; changed = true;
    }
    if (this.opts.vectors && !vectors.includes(this.opts.vectors)) {
      this.opts.vectors = null; changed = true;
    }
    this.toggles.grid.disabled = !scene.grid;
    this.toggles.grid.parentElement.hidden = !scene.grid;
    if (changed) this.sendLayers();
    this.fieldSelect.value = this.opts.field || "";
    this.vectorSelect.value = this.opts.vectors || "";
    this.buildParams(scene.params || []);
    this.buildPlots(scene);
    this.showFault(scene.fault);
    if (this.onScene) this.onScene(scene);
  }
  fillChoices(select, names, noneLabel) {
    // a menu of the program's fields (or vector fields), the choice of none first
    select.innerHTML = "";
    const none = this.el("option", "", noneLabel);
    none.value = "";
    select.append(none);
    for (const f of names) {
      const o = this.el("option", "", f);
      o.value = f;
      select.append(o);
    }
  }
  speedText(s) {
    return s >= 1 ? `${s} tick${s === 1 ? "" : "s"}/frame` : `1 tick/${Math.round(1 / s)} frames`;
  }
  showFault(fault) {
    this.status.textContent = fault || "";
    this.status.classList.toggle("fault", !!fault);
  }
  buildParams(params) {
    const focused = document.activeElement;
    if (focused && this.params.contains(focused) && focused.dataset.dragging) return;
    this.params.innerHTML = "";
    for (const p of params) {
      const row = this.el("div", "param");
      row.dataset.param = p.name;
      const name = this.el("span", "param-name", p.name);
      row.append(name);
      if (p.type === "bool") {
        const sw = this.el("input", "switch");
        sw.type = "checkbox";
        sw.checked = !!p.value;
        sw.dataset.role = "param-" + p.name;
        sw.addEventListener("change", () => this.send({op: "param", name: p.name, value: sw.checked}));
        row.append(sw);
      } else {
        const slider = this.el("input", "slider");
        slider.type = "range";
        slider.min = p.lo; slider.max = p.hi; slider.step = p.step;
        slider.value = p.value;
        slider.dataset.role = "param-" + p.name;
        const box = this.el("input", "number");
        box.type = "number";
        box.step = "any";
        box.value = p.value;
        box.dataset.role = "value-" + p.name;
        slider.addEventListener("input", () => { box.value = slider.value; });
        slider.addEventListener("change", () =>
          this.send({op: "param", name: p.name, value: Number(slider.value)}));
        box.addEventListener("change", () =>
          this.send({op: "param", name: p.name, value: Number(box.value)}));
        row.append(slider, box);
        if (!p.declared_range) row.title = "no declared range: the slider spans 0 to twice " +
                                           "the value; type any value in the box";
      }
      if (p.overridden) row.classList.add("overridden");
      row.append(this.el("div", "param-error"));
      this.params.append(row);
    }
  }
  buildPlots(scene) {
    this.plotBox.innerHTML = "";
    this.plots = [];
    const metrics = scene.metrics || [];
    metrics.forEach((m, i) => this.plots.push(new Plot(this.plotBox, m, [m], [[250, 200, 60]])));
    this.countPlot = new Plot(this.plotBox, "agents by status", scene.status_names || [],
                              scene.palette || [[200, 200, 200]]);
    this.addSamples(scene.history || []);
    this.plots.forEach(p => p.draw());
    this.countPlot.draw();
  }
  showRecorded(recorded) {
    // a finished run's metrics.parquet, {name: [[tick, value], ...]} (the widget's)
    this.recordedBox.innerHTML = "";
    const names = Object.keys(recorded || {});
    if (!names.length) return;
    this.recordedBox.append(this.el("h3", "", "recorded run (metrics.parquet)"));
    for (const name of names) {
      const plot = new Plot(this.recordedBox, name, [name], [[120, 200, 250]]);
      for (const [tick, value] of recorded[name]) plot.add(tick, [value]);
      plot.draw();
    }
  }
  addSamples(samples) {
    if (!this.scene || !this.countPlot) return;
    const k = (this.scene.metrics || []).length;
    for (const row of samples) {
      const tick = row[0];
      for (let i = 0; i < k; i++) this.plots[i].add(tick, [row[1 + i]]);
      this.countPlot.add(tick, row.slice(1 + k));
    }
  }
  onFrame(buffer) {
    const frame = decodeFrame(buffer);
    this.pending = frame;
    this.received++;
    if (!this.drawing) {
      this.drawing = true;
      requestAnimationFrame(() => this.drawPending());
    }
  }
  drawPending() {
    const frame = this.pending;
    this.pending = null;
    this.drawing = false;
    if (!frame) return;
    this.send({op: "ready", n: this.received});  // the next frame is made while this draws
    this.received = 0;
    this.frame = frame;
    const h = frame.header;
    if (this.scene) {
      this.scene.playing = h.playing;
      this.scene.speed = h.speed;
      this.playButton.textContent = h.playing ? "❚❚ pause" : "▶ play";
      this.speedLabel.textContent = this.speedText(h.speed);
      if (this.scene.world) this.renderer.draw(frame, this.opts);
      this.addSamples(h.samples || []);
      if ((h.samples || []).length) { this.plots.forEach(p => p.draw()); this.countPlot.draw(); }
      this.showFault(h.fault);
      this.showAgent(h.selected);
    }
    this.frames++;
    this.canvas.dataset.tick = h.tick;
    this.canvas.dataset.frames = this.frames;
  }
  showAgent(a) {
    if (!a) { this.inspector.textContent = "click an agent to inspect it"; return; }
    if (a.gone) { this.inspector.textContent = `agent ${a.id} is gone`; return; }
    const fmt = v => Array.isArray(v) ? "(" + v.map(fmt).join(", ") + ")" :
      typeof v === "number" ? Number(v.toPrecision(5)).toString() : String(v);
    const lines = [`id ${a.id}  ${a.kind}  status ${a.status}`];
    if (a.path) lines.push(`tree: ${a.path}`);
    lines.push(`pos ${fmt(a.pos)}  heading ${fmt(a.heading)}`);
    for (const [k, v] of Object.entries(a.vars)) lines.push(`${k} = ${fmt(v)}`);
    this.inspector.textContent = lines.join("\n");
  }
}
