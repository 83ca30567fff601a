// photo.js: `bokehfit view PHOTO`. The photo with every candidate outlined, the verdict, the fitted
// aperture and the candidates' table, all read from the server's `compare --json` document of the
// fit shown (never recomputed here); the person's picks, sent to POST /photo/refit, which fits
// exactly those discs (compare --discs semantics) in a worker the page polls and may cancel. The
// selected disc's kernel is drawn in the browser by the project's WGSL kernel renderer (WebGPU).

const TOKEN = document.querySelector('meta[name="bokehfit-token"]').content;
const COLOURS = { used: "#009e73", usable: "#56b4e9", rejected: "#d55e00", dropped: "#999999", added: "#ffffff" };
// A pick and a disc are the same place when the centres lie within this share of the diameter (labels.py's rule).
const SAME_PLACE = 0.25;
const POLL_MS = 200;

const $ = (id) => document.getElementById(id);
const canvas = $("photo");
const ctx = canvas.getContext("2d");
const image = new Image();

const state = {
  info: null,
  auto: null,      // {job, doc, tiles}: the automatic compare
  shown: null,     // {job, doc, tiles}: the compare on the page
  picks: [],       // [{center_xy: [x, y], diameter_px: D}]: what Refit sends
  shapes: null,    // null: all
  undo: [],
  view: { scale: 1, x: 0, y: 0 },
  moved: false,    // zoomed or panned by the person: a resize keeps the view
  selected: null,  // a disc of shown.doc (its index)
  hover: null,
  running: null,
  drawing: null,   // {x, y, r} while a circle is drawn
};

async function getJson(path) {
  const response = await fetch(path, { cache: "no-store" });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
}

async function postJson(path, body) {
  const response = await fetch(path, {
    method: "POST",
    headers: { "Content-Type": "application/json", "X-Bokehfit-Token": TOKEN },
    body: JSON.stringify(body),
  });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
}

function showError(message) {
  $("error").textContent = message || "";
}

// --- places -----------------------------------------------------------------------------------

function samePlace(a, b) {
  const d = Math.max(a.diameter_px, b.diameter_px);
  return Math.hypot(a.center_xy[0] - b.center_xy[0], a.center_xy[1] - b.center_xy[1]) <= SAME_PLACE * d;
}

function pickOf(disc) {
  return state.picks.findIndex((p) => samePlace(p, disc));
}

function placeOf(disc) {
  return { center_xy: [disc.center_xy[0], disc.center_xy[1]], diameter_px: disc.diameter_px };
}

function role(disc) {
  return disc.used ? "used" : disc.usable ? "usable" : "rejected";
}

// Everything drawn: the shown fit's discs, the automatic candidates it lacks, the picks neither has.
function marks() {
  const out = [];
  const doc = state.shown ? state.shown.doc : null;
  const discs = doc ? doc.discs : [];
  for (const disc of discs) out.push({ disc, role: role(disc), picked: pickOf(disc) >= 0, source: "shown" });
  if (state.auto && state.shown && state.shown.job !== state.auto.job) {
    for (const disc of state.auto.doc.discs) {
      if (discs.some((d) => samePlace(d, disc))) continue;
      out.push({ disc, role: "dropped", picked: pickOf(disc) >= 0, source: "auto" });
    }
  }
  for (const pick of state.picks) {
    if (out.some((m) => samePlace(m.disc, pick))) continue;
    out.push({ disc: { ...pick, index: null }, role: "added", picked: true, source: "pick" });
  }
  return out;
}

// --- drawing ----------------------------------------------------------------------------------

function fitView() {
  const { width, height } = state.info;
  const scale = Math.min(canvas.width / width, canvas.height / height);
  state.view = { scale, x: (canvas.width - width * scale) / 2, y: (canvas.height - height * scale) / 2 };
}

function resize() {
  const box = canvas.getBoundingClientRect();
  const ratio = window.devicePixelRatio || 1;
  const first = canvas.width === 300 && canvas.height === 150;
  canvas.width = Math.max(1, Math.round(box.width * ratio));
  canvas.height = Math.max(1, Math.round(box.height * ratio));
  if (state.info && (first || !state.moved)) fitView();
  draw();
}

function outlinePath(disc) {
  ctx.beginPath();
  const dashedCircle = !disc.outline_xy || !disc.outline_xy.length;
  if (dashedCircle) {
    ctx.arc(disc.center_xy[0], disc.center_xy[1], disc.diameter_px / 2, 0, 2 * Math.PI);
  } else {
    disc.outline_xy.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.closePath();
  }
}

function draw() {
  if (!state.info) return;
  const { scale, x, y } = state.view;
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = "#000";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.setTransform(scale, 0, 0, scale, x, y);
  ctx.imageSmoothingEnabled = scale < 2;
  if (image.complete && image.naturalWidth) ctx.drawImage(image, 0, 0, state.info.width, state.info.height);
  const line = Math.max(1.5, 2 * (window.devicePixelRatio || 1)) / scale;
  for (const mark of marks()) {
    // Dashed: not among the picks (dropped), or picked but not yet fitted (added).
    const dashed = mark.role === "added" || !mark.picked;
    ctx.setLineDash(dashed ? [6 / scale, 4 / scale] : []);
    ctx.strokeStyle = COLOURS[mark.role];
    ctx.lineWidth = line * (mark.disc === state.hover || (mark.source === "shown" && mark.disc.index === state.selected) ? 2.2 : 1);
    outlinePath(mark.disc);
    ctx.stroke();
  }
  ctx.setLineDash([]);
  if (state.drawing && state.drawing.r > 0) {
    ctx.strokeStyle = COLOURS.added;
    ctx.lineWidth = line;
    ctx.beginPath();
    ctx.arc(state.drawing.x, state.drawing.y, state.drawing.r, 0, 2 * Math.PI);
    ctx.stroke();
  }
}

// --- the page's pointer: zoom, pan, click, Shift+drag ------------------------------------------

function photoXY(event) {
  const box = canvas.getBoundingClientRect();
  const ratio = canvas.width / box.width;
  const cx = (event.clientX - box.left) * ratio, cy = (event.clientY - box.top) * ratio;
  return [(cx - state.view.x) / state.view.scale, (cy - state.view.y) / state.view.scale];
}

// Client coordinates of a photo pixel (the tests click through this).
function clientXY(x, y) {
  const box = canvas.getBoundingClientRect();
  const ratio = canvas.width / box.width;
  return [box.left + (x * state.view.scale + state.view.x) / ratio, box.top + (y * state.view.scale + state.view.y) / ratio];
}

function markAt(x, y) {
  let best = null, bestDistance = Infinity;
  for (const mark of marks()) {
    const d = Math.hypot(mark.disc.center_xy[0] - x, mark.disc.center_xy[1] - y);
    if (d <= Math.max(mark.disc.diameter_px / 2, 4 / state.view.scale) && d < bestDistance) {
      best = mark;
      bestDistance = d;
    }
  }
  return best;
}

function remember() {
  state.undo.push({ picks: state.picks.map(placeOf), shown: state.shown, selected: state.selected });
  $("undo").disabled = false;
}

function toggle(mark) {
  remember();
  const at = pickOf(mark.disc);
  if (at >= 0) state.picks.splice(at, 1);
  else state.picks.push(placeOf(mark.disc));
  if (mark.source === "shown") select(mark.disc.index);
  changed();
}

function addDisc(x, y, r) {
  const { width, height } = state.info;
  if (r < 1 || x < 0 || y < 0 || x > width - 1 || y > height - 1) return;
  remember();
  state.picks.push({ center_xy: [x, y], diameter_px: 2 * r });
  changed();
}

let press = null;
canvas.addEventListener("pointerdown", (event) => {
  if (!state.info) return;
  canvas.setPointerCapture(event.pointerId);
  const [x, y] = photoXY(event);
  const adding = event.shiftKey || $("add").getAttribute("aria-pressed") === "true";
  press = { clientX: event.clientX, clientY: event.clientY, view: { ...state.view }, x, y, adding, moved: false };
  if (adding) state.drawing = { x, y, r: 0 };
});

canvas.addEventListener("pointermove", (event) => {
  if (!state.info) return;
  const [x, y] = photoXY(event);
  if (press) {
    const dx = event.clientX - press.clientX, dy = event.clientY - press.clientY;
    if (Math.hypot(dx, dy) > 3) press.moved = true;
    if (press.adding) {
      state.drawing.r = Math.hypot(x - press.x, y - press.y);
    } else if (press.moved) {
      const ratio = canvas.width / canvas.getBoundingClientRect().width;
      state.moved = true;
      state.view.x = press.view.x + dx * ratio;
      state.view.y = press.view.y + dy * ratio;
    }
    draw();
    return;
  }
  const mark = markAt(x, y);
  const hover = mark ? mark.disc : null;
  if (hover !== state.hover) {
    state.hover = hover;
    draw();
  }
  showTip(event, mark);
});

canvas.addEventListener("pointerup", (event) => {
  if (!press) return;
  const done = press;
  press = null;
  if (done.adding) {
    const circle = state.drawing;
    state.drawing = null;
    if (done.moved) addDisc(circle.x, circle.y, circle.r);
    draw();
    return;
  }
  if (!done.moved) {
    const mark = markAt(done.x, done.y);
    if (mark) toggle(mark);
  }
});

canvas.addEventListener("pointerleave", () => { $("tip").hidden = true; });

canvas.addEventListener("wheel", (event) => {
  event.preventDefault();
  const box = canvas.getBoundingClientRect();
  const ratio = canvas.width / box.width;
  const cx = (event.clientX - box.left) * ratio, cy = (event.clientY - box.top) * ratio;
  const factor = Math.exp(-event.deltaY * 0.0015);
  const scale = Math.min(64, Math.max(0.02, state.view.scale * factor));
  const k = scale / state.view.scale;
  state.view = { scale, x: cx - (cx - state.view.x) * k, y: cy - (cy - state.view.y) * k };
  state.moved = true;
  draw();
}, { passive: false });

function describe(mark) {
  const disc = mark.disc;
  const where = `(${disc.center_xy[0].toFixed(0)}, ${disc.center_xy[1].toFixed(0)}), ${disc.diameter_px.toFixed(1)} px`;
  const action = mark.picked ? "click to drop" : "click to use";
  if (mark.role === "added") return `added at ${where}: not yet fitted; ${action}`;
  if (mark.role === "dropped") return `#${disc.index} ${where}: dropped; ${action}`;
  const why = disc.rejected_because && disc.rejected_because.length ? `: ${disc.rejected_because.join("; ")}` : "";
  const words = { used: "used in the fit", usable: "usable, not needed", rejected: "rejected" }[mark.role];
  return `#${disc.index} ${where}: ${words}${why}; ${mark.picked ? "picked" : "not picked"}, ${action}`;
}

function showTip(event, mark) {
  const tip = $("tip");
  if (!mark) {
    tip.hidden = true;
    return;
  }
  const box = $("stage").getBoundingClientRect();
  tip.textContent = describe(mark);
  tip.style.left = `${event.clientX - box.left + 14}px`;
  tip.style.top = `${event.clientY - box.top + 14}px`;
  tip.hidden = false;
}

// --- the matched kernel, drawn on the GPU by the project's kernel renderer ------------------------
// The selected disc's kernel is drawn by kernel_mc.wgsl (served as /photo/kernel_mc.wgsl, the WGSL that
// bokehfit.kernels.mc compiles; its aperture samplers are shaders/apertures.wgsl): stratified samples
// of the fitted aperture (shape, angle, roundness, squeeze, rim, the vignetting's cut at the disc's
// field position) counted in the pixels they land in. Its KernelParams and ApertureParams are packed
// by the layouts in /photo/info.json, with the values of the disc's tile (the fit's own aperture, from
// Aperture.shader_params on the server). Here the counts become the disc's coverage, are moved to the
// fitted centre, blurred by the fitted edge blur and given the fitted levels: the model, and the residual.

const SETTERS = { f32: "setFloat32", u32: "setUint32", i32: "setInt32" };
// cv2.GaussianBlur's reach for float images (4 sigma) and the fit's smallest blur (fit/pixels.py BLUR_RANGE).
const BLUR_REACH = 4;
const MIN_BLUR_PX = 0.05;
// kernel_mc.py: samples each thread draws at most, to size the dispatch.
const SAMPLES_PER_THREAD = 16;

function pack(layout, values, what) {
  const bytes = new ArrayBuffer(layout.size_bytes);
  const view = new DataView(bytes);
  for (const f of layout.fields) {
    const v = values[f.name];
    if (v === undefined || v === null) throw new Error(`${what} lacks ${layout.name}.${f.name}`);
    const components = f.components === 1 ? [v] : v;
    if (!Array.isArray(components) || components.length !== f.components) throw new Error(`${layout.name}.${f.name} is a ${f.type}`);
    const setter = SETTERS[f.scalar];
    if (!setter) throw new Error(`${layout.name}.${f.name}: unknown type ${f.type}`);
    components.forEach((c, i) => view[setter](f.offset + 4 * i, c, true));
  }
  return bytes;
}

class KernelRenderer {
  static async create(config) {
    if (!navigator.gpu) throw new Error("navigator.gpu is missing: WebGPU is off or unsupported here");
    const adapter = await navigator.gpu.requestAdapter();
    if (!adapter) throw new Error("navigator.gpu.requestAdapter() found no adapter");
    const device = await adapter.requestDevice();
    const response = await fetch(config.url, { cache: "no-store" });
    if (!response.ok) throw new Error(`${config.url}: ${response.status}`);
    const module = device.createShaderModule({ label: "kernel_mc", code: await response.text() });
    const info = await module.getCompilationInfo();
    const errors = info.messages.filter((m) => m.type === "error");
    if (errors.length) throw new Error("kernel_mc.wgsl does not compile here: " + errors.map((m) => `${m.lineNum}:${m.linePos} ${m.message}`).join("; "));
    device.pushErrorScope("validation");
    const pipeline = await device.createComputePipelineAsync({ label: "kernel_mc", layout: "auto", compute: { module, entryPoint: config.entry_point } });
    const error = await device.popErrorScope();
    if (error) throw new Error(`kernel_mc.wgsl: ${error.message}`);
    const info2 = adapter.info || {};
    return new KernelRenderer(config, device, pipeline, [info2.vendor, info2.architecture, info2.description].filter(Boolean).join(" ") || "WebGPU");
  }

  constructor(config, device, pipeline, adapterName) {
    Object.assign(this, { config, device, pipeline, adapterName, lost: null });
    device.lost.then((info) => { this.lost = info.message || info.reason || "device lost"; });
    // A mask aperture's CDF tables go here; the fitted families are shapes, so one float (as kernel_mc.py binds).
    this.maskTable = device.createBuffer({ label: "mask_table", size: 4, usage: GPUBufferUsage.STORAGE });
  }

  // The histogram of `samples` stratified aperture samples scaled by `scale` on a size × size frame (kernel_mc.wgsl).
  async counts(tile, scale) {
    if (this.lost) throw new Error(`the GPU was lost: ${this.lost}`);
    const { device, config } = this;
    const size = tile.size;
    const params = pack(config.params, { size, samples: tile.samples, strata: tile.strata, stratified: 1, seed: 0, scale,
      row_first: 0, rows: size }, "the kernel's parameters");
    const aperture = pack(config.aperture, tile.aperture, "the disc's tile");
    const uniform = (bytes, label) => {
      const buffer = device.createBuffer({ label, size: bytes.byteLength, usage: GPUBufferUsage.UNIFORM | GPUBufferUsage.COPY_DST });
      device.queue.writeBuffer(buffer, 0, bytes);
      return buffer;
    };
    const buffers = { params: uniform(params, "params"), aperture: uniform(aperture, "aperture"), mask_table: this.maskTable };
    buffers.counts = device.createBuffer({ label: "counts", size: 4 * size * size, usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_SRC });
    const readback = device.createBuffer({ label: "readback", size: 4 * size * size, usage: GPUBufferUsage.MAP_READ | GPUBufferUsage.COPY_DST });
    const entries = Object.entries(config.bindings).map(([name, b]) => ({ binding: b.binding, resource: { buffer: buffers[name] } }));
    device.pushErrorScope("validation");
    const group = device.createBindGroup({ layout: this.pipeline.getBindGroupLayout(0), entries });
    const threads = config.workgroup_size.reduce((a, b) => a * b, 1);
    const groups = Math.max(1, Math.min(Math.ceil(tile.samples / (threads * SAMPLES_PER_THREAD)), device.limits.maxComputeWorkgroupsPerDimension));
    const encoder = device.createCommandEncoder();
    const pass = encoder.beginComputePass();
    pass.setPipeline(this.pipeline);
    pass.setBindGroup(0, group);
    pass.dispatchWorkgroups(groups);
    pass.end();
    encoder.copyBufferToBuffer(buffers.counts, 0, readback, 0, 4 * size * size);
    device.queue.submit([encoder.finish()]);
    const error = await device.popErrorScope();
    if (error) throw new Error(`kernel_mc.wgsl: ${error.message}`);
    await readback.mapAsync(GPUMapMode.READ);
    const counts = new Uint32Array(readback.getMappedRange().slice(0));
    readback.unmap();
    for (const b of [readback, buffers.counts, buffers.params, buffers.aperture]) b.destroy();
    return counts;
  }

  // The disc's model on its crop: per channel (green, or red, green, blue with colour) the coverage,
  // at the fitted centre, blurred; and each channel's unit-area kernel as drawn (centred, for the tests).
  async draw(tile) {
    const start = performance.now();
    const scales = tile.chromatic ? [1 + tile.chromatic[0], 1, 1 + tile.chromatic[1]] : [1];
    const channels = [];
    const kernels = [];
    for (const s of scales) {
      const counts = await this.counts(tile, tile.scale * s);
      // Each sample stands for scale² / samples of the unit-area aperture's area, in pixels.
      const area = (tile.scale * s) ** 2 / tile.samples;
      const cover = Float32Array.from(counts, (c) => c * area);
      let total = 0;
      for (const c of counts) total += c;
      kernels.push(Float32Array.from(counts, (c) => c / Math.max(total, 1)));
      // To the fitted centre: a bilinear move by (dx, dy) spreads each axis by the variance f (1 − f) of its
      // fraction f, which the blur then leaves out (where it can): the two give the fitted blur's spread.
      const centre = (tile.size - 1) / 2;
      const [dx, dy] = [tile.center[0] - centre, tile.center[1] - centre];
      const sigma = Math.max(tile.blur_px, MIN_BLUR_PX);
      const rest = (d) => { const f = d - Math.floor(d); return Math.sqrt(Math.max(sigma * sigma - f * (1 - f), MIN_BLUR_PX * MIN_BLUR_PX)); };
      channels.push(blur(shift(cover, tile.size, dx, dy), tile.size, rest(dx), rest(dy)));
    }
    return { kernel: kernels[kernels.length === 3 ? 1 : 0], kernels, channels, ms: performance.now() - start };
  }
}

// Bilinear move of a size × size image by (dx, dy) pixels (x right, y down), zero outside.
function shift(image, size, dx, dy) {
  const out = new Float32Array(size * size);
  const ix = Math.floor(dx), iy = Math.floor(dy), fx = dx - ix, fy = dy - iy;
  const at = (r, c) => (r >= 0 && r < size && c >= 0 && c < size ? image[r * size + c] : 0);
  for (let r = 0; r < size; r++) {
    for (let c = 0; c < size; c++) {
      const r0 = r - iy, c0 = c - ix;
      out[r * size + c] = (1 - fy) * ((1 - fx) * at(r0, c0) + fx * at(r0, c0 - 1)) + fy * ((1 - fx) * at(r0 - 1, c0) + fx * at(r0 - 1, c0 - 1));
    }
  }
  return out;
}

// Separable Gaussian blur of sigma px across (sx) and down (sy), edges replicated (as the fit's cv2.GaussianBlur).
function blur(image, size, sx, sy) {
  const weights = (sigma) => {
    const reach = Math.max(1, Math.round(BLUR_REACH * sigma));
    const w = [];
    for (let i = -reach; i <= reach; i++) w.push(Math.exp(-0.5 * (i / sigma) ** 2));
    const sum = w.reduce((a, b) => a + b, 0);
    return { reach, w: w.map((v) => v / sum) };
  };
  const clamp = (i) => Math.min(size - 1, Math.max(0, i));
  const pass = (source, horizontal, { reach, w }) => {
    const out = new Float32Array(size * size);
    for (let r = 0; r < size; r++) {
      for (let c = 0; c < size; c++) {
        let v = 0;
        for (let k = -reach; k <= reach; k++) {
          v += w[k + reach] * (horizontal ? source[r * size + clamp(c + k)] : source[clamp(r + k) * size + c]);
        }
        out[r * size + c] = v;
      }
    }
    return out;
  };
  return pass(pass(image, true, weights(sx)), false, weights(sy));
}

// The tile's crop (uint16 between crop_range, base64) as linear values.
function cropValues(tile) {
  const bytes = Uint8Array.from(atob(tile.crop), (ch) => ch.charCodeAt(0));
  const view = new DataView(bytes.buffer);
  const [low, high] = tile.crop_range;
  const out = new Float32Array(tile.size * tile.size);
  for (let i = 0; i < out.length; i++) out[i] = low + (view.getUint16(2 * i, true) / 65535) * (high - low);
  return out;
}

// Residual colours of the HTML report (report/html.py _RESIDUAL_STOPS): blue darker, white equal, red brighter.
const RESIDUAL_STOPS = [[0, [33, 102, 172]], [0.5, [247, 247, 247]], [1, [178, 24, 43]]];

function residualColour(value, span) {
  const t = 0.5 + 0.5 * Math.max(-1, Math.min(1, value / Math.max(span, 1e-9)));
  const [[p0, c0], [p1, c1]] = t <= 0.5 ? [RESIDUAL_STOPS[0], RESIDUAL_STOPS[1]] : [RESIDUAL_STOPS[1], RESIDUAL_STOPS[2]];
  const f = (t - p0) / (p1 - p0);
  return c0.map((c, i) => Math.round(c + f * (c1[i] - c)));
}

// As the report's tiles (grey8): (v − background) / (plateau − background), clipped, through a gamma of 2.
function grey(value, low, high) {
  return Math.round(Math.sqrt(Math.max(0, Math.min(1, (value - low) / Math.max(high - low, 1e-9)))) * 255);
}

function paint(canvas, size, rgbAt) {
  canvas.width = size;
  canvas.height = size;
  const context = canvas.getContext("2d");
  const image = context.createImageData(size, size);
  for (let i = 0; i < size * size; i++) {
    const [r, g, b] = rgbAt(i);
    image.data.set([r, g, b, 255], 4 * i);
  }
  context.putImageData(image, 0, 0);
}

const kernels = { renderer: null, failed: null, cache: new Map(), shown: null };

async function kernelRenderer() {
  if (kernels.renderer || kernels.failed) return kernels.renderer;
  if (!kernels.starting) {
    kernels.starting = KernelRenderer.create(state.info.kernel).then(
      (renderer) => { kernels.renderer = renderer; return renderer; },
      (error) => { kernels.failed = error.message; return null; });
  }
  return kernels.starting;
}

// --- what the page shows of a compare ------------------------------------------------------------

const fmt = (value, digits) => (value === null || value === undefined ? "–" : Number(value).toFixed(digits));

function showResult() {
  const { doc } = state.shown;
  document.body.dataset.job = String(state.shown.job);
  document.body.dataset.status = doc.status;
  const verdict = $("verdict");
  verdict.textContent = doc.verdict;
  verdict.className = doc.status;
  $("details").textContent = doc.verdict_details || "";
  const a = doc.aperture;
  $("aperture-svg").innerHTML = state.shown.tiles.aperture_svg || "";
  const parts = [];
  if (a.shape) {
    parts.push(`${a.shape}${a.blades ? ` (${a.blades} blades)` : ""}`);
    if (a.angle_deg !== null) parts.push(`angle ${fmt(a.angle_deg, 2)}° ± ${fmt(a.angle_uncertainty_deg, 2)}°`);
    parts.push(`diameter ${fmt(a.diameter_px, 2)} px`);
    if (a.fstop !== null) parts.push(`f/${fmt(a.fstop, 2)}${a.fstop_bound === "upper" ? " (at most)" : ""}`);
    parts.push(`${a.discs_fitted} discs fitted`);
  } else {
    parts.push("no aperture fitted");
  }
  $("aperture-text").textContent = parts.join(" · ");
  $("save-json").href = `/photo/result.json?job=${state.shown.job}`;
  $("save-html").href = `/photo/report.html?job=${state.shown.job}`;
  const base = state.info.file.replace(/\.[^.]*$/, "");
  $("save-json").download = `${base}_bokehfit.json`;
  $("save-html").download = `${base}_bokehfit.html`;
  showTable();
  showMatch();
  draw();
}

function showTable() {
  const { doc } = state.shown;
  const rows = [];
  const counts = { used: 0, usable: 0, rejected: 0 };
  for (const disc of doc.discs) {
    const r = role(disc);
    counts[r] += 1;
    const tr = document.createElement("tr");
    tr.dataset.index = String(disc.index);
    tr.dataset.role = r;
    tr.dataset.picked = String(pickOf(disc) >= 0);
    if (disc.index === state.selected) tr.className = "selected";
    const why = (disc.rejected_because || []).join("; ") + (pickOf(disc) >= 0 ? "" : (disc.rejected_because.length ? "; " : "") + "dropped");
    const cells = [disc.index, r, fmt(disc.center_xy[0], 1), fmt(disc.center_xy[1], 1), fmt(disc.diameter_px, 2),
      fmt(disc.fit_diameter_px, 2), fmt(disc.iou, 3), fmt(disc.angle_deg, 2), why];
    cells.forEach((value, i) => {
      const td = document.createElement("td");
      td.textContent = String(value);
      if (i === 1) td.className = `role-${r}`;
      tr.appendChild(td);
    });
    tr.addEventListener("click", () => select(disc.index));
    rows.push(tr);
  }
  $("candidates").tBodies[0].replaceChildren(...rows);
  document.body.dataset.used = String(counts.used);
  $("counts").textContent = `${doc.discs.length}: ${counts.used} used, ${counts.usable} usable, ${counts.rejected} rejected; ${state.picks.length} picked`;
}

function select(index) {
  state.selected = index;
  showTable();
  showMatch();
  draw();
}

function showMatch() {
  const box = $("match").querySelector(".tiles");
  box.replaceChildren();
  kernels.shown = null;
  const disc = state.shown && state.shown.doc.discs.find((d) => d.index === state.selected);
  if (!disc) {
    $("match-text").textContent = "Click a disc in the table to see it beside the fitted model.";
    document.body.dataset.kernel = "none";
    return;
  }
  const metrics = [`#${disc.index}`, `${role(disc)}`, `D ${fmt(disc.diameter_px, 2)} px`];
  if (disc.used) {
    metrics.push(`fitted D ${fmt(disc.fit_diameter_px, 2)} px`, `IoU ${fmt(disc.iou, 3)}`,
      `Hausdorff ${fmt(disc.hausdorff_rel, 3)} of D`);
    if (disc.angle_deg !== undefined) metrics.push(`its angle ${fmt(disc.angle_deg, 2)}°`);
    if (disc.depth_m !== null) metrics.push(`light at ${fmt(disc.depth_m, 2)} m`);
  } else if (disc.rejected_because.length) {
    metrics.push(disc.rejected_because.join("; "));
  } else {
    metrics.push("not used in the fit");
  }
  $("match-text").textContent = metrics.join(" · ");
  const tiles = state.shown.tiles.tiles[String(disc.index)];
  $("match-note").textContent = "";
  if (!tiles) {
    document.body.dataset.kernel = "none";
    return;
  }
  if (!tiles.kernel) {
    pythonTiles(box, tiles, "this result has no kernel data");
    return;
  }
  drawMatch(box, disc, tiles).catch((error) => pythonTiles(box, tiles, error.message));
}

function figure(element, label) {
  const item = document.createElement("figure");
  const caption = document.createElement("figcaption");
  caption.textContent = label;
  item.append(element, caption);
  return item;
}

// Without WebGPU: the crop, the model and the residual as the HTML report draws them (in Python).
function pythonTiles(box, tiles, why) {
  box.replaceChildren();
  for (const [key, label] of [["photo", "photo"], ["model", "fitted model (Python)"], ["residual", "residual"]]) {
    const img = document.createElement("img");
    img.src = tiles[key];
    img.alt = label;
    box.appendChild(figure(img, label));
  }
  $("match-note").textContent = `The kernel could not be drawn in this browser (${why}): the model is the one drawn in Python, `
    + "as the HTML report draws it (photo − model: blue darker, red brighter).";
  document.body.dataset.kernel = "fallback";
}

async function drawMatch(box, disc, tiles) {
  const key = `${state.shown.job}:${disc.index}`;
  kernels.shown = key;
  document.body.dataset.kernel = "drawing";
  const renderer = await kernelRenderer();
  if (kernels.shown !== key) return;
  if (!renderer) {
    pythonTiles(box, tiles, kernels.failed);
    return;
  }
  let drawn = kernels.cache.get(key);
  if (!drawn) {
    drawn = await renderer.draw(tiles.kernel);
    kernels.cache.set(key, drawn);
  }
  if (kernels.shown !== key) return;
  const tile = tiles.kernel;
  const { size, background: low, plateau: high } = tile;
  const crop = cropValues(tile);
  const levels = (profile) => Float32Array.from(profile, (p) => low + (high - low) * p);
  const models = drawn.channels.map(levels);
  const model = models[models.length === 3 ? 1 : 0];  // the luminance model is green's (the reference size)
  const residual = Float32Array.from(crop, (v, i) => v - model[i]);
  const canvases = ["photo", "kernel", "residual"].map((name) => {
    const canvas = document.createElement("canvas");
    canvas.id = `match-${name}`;
    return canvas;
  });
  paint(canvases[0], size, (i) => { const g = grey(crop[i], low, high); return [g, g, g]; });
  paint(canvases[1], size, (i) => (models.length === 3 ? models.map((m) => grey(m[i], low, high)) : Array(3).fill(grey(model[i], low, high))));
  paint(canvases[2], size, (i) => residualColour(residual[i], tile.residual_span));
  box.replaceChildren(figure(canvases[0], "photo"), figure(canvases[1], "kernel (WebGPU)"), figure(canvases[2], "residual"));
  let squares = 0;
  for (const r of residual) squares += r * r;
  const rms = Math.sqrt(squares / residual.length) / Math.max(high - low, 1e-9);
  const reduced = tile.factor > 1 ? `, the crop reduced ${tile.factor}×` : "";
  $("match-note").textContent = `The kernel of the fitted aperture at this disc (its size, angle and place in the frame, the `
    + `fitted edge blur and levels${reduced}) drawn here by the project's kernel renderer (kernel_mc.wgsl, ${tile.samples} `
    + `samples, ${drawn.ms.toFixed(0)} ms on ${renderer.adapterName}); residual photo − model (blue darker, red brighter), `
    + `RMS ${(100 * rms).toFixed(1)} % of the disc's brightness.`;
  window.photoView.kernel = { key, index: disc.index, size, kernel: Array.from(drawn.kernel), model: Array.from(model),
    residual_rms: rms, samples: tile.samples, ms: drawn.ms };
  document.body.dataset.kernel = "ready";
}

function changed() {
  if (state.shown) showTable();
  $("refit").disabled = state.running !== null || state.picks.length === 0;
  draw();
}

// --- refit, undo, reset, saves -----------------------------------------------------------------

async function loadJob(job) {
  const [doc, tiles] = await Promise.all([getJson(`/photo/result.json?job=${job}`), getJson(`/photo/tiles.json?job=${job}`)]);
  return { job, doc, tiles };
}

function setRunning(job) {
  state.running = job;
  document.body.dataset.state = job === null ? "idle" : "running";
  $("cancel").hidden = job === null;
  $("refit").disabled = job !== null || state.picks.length === 0;
  if (job === null) $("progress").textContent = "";
}

async function waitFor(job) {
  for (;;) {
    const status = await getJson(`/photo/job?job=${job}`);
    if (status.state !== "running") return status;
    const steps = status.total ? ` ${status.done}/${status.total}` : "";
    $("progress").textContent = `${status.stage}${steps} · ${status.elapsed_s.toFixed(1)} s`;
    await new Promise((resolve) => setTimeout(resolve, POLL_MS));
  }
}

async function refit() {
  showError("");
  const body = { discs: state.picks.map(placeOf) };
  if (state.shapes) body.shapes = state.shapes;
  let job;
  try {
    ({ job } = await postJson("/photo/refit", body));
  } catch (error) {
    showError(error.message);
    return;
  }
  setRunning(job);
  try {
    const status = await waitFor(job);
    if (status.state === "done") {
      const result = await loadJob(job);
      state.undo.push({ picks: state.picks.map(placeOf), shown: state.shown, selected: state.selected });
      $("undo").disabled = false;
      state.shown = result;
      if (!result.doc.discs.some((d) => d.index === state.selected)) state.selected = null;
      $("progress").textContent = "";
      showResult();
      $("progress").textContent = `refit in ${status.elapsed_s.toFixed(1)} s`;
    } else if (status.state === "failed") {
      showError(status.error);
    } else {
      showError("refit cancelled");
    }
  } catch (error) {
    showError(error.message);
  } finally {
    const text = $("progress").textContent;
    setRunning(null);
    $("progress").textContent = text.startsWith("refit in") ? text : "";
    changed();
  }
}

function undo() {
  const last = state.undo.pop();
  if (!last) return;
  state.picks = last.picks;
  state.shown = last.shown;
  state.selected = last.selected;
  $("undo").disabled = state.undo.length === 0;
  showResult();
  changed();
}

function reset() {
  remember();
  state.shown = state.auto;
  state.picks = autoPicks();
  state.selected = null;
  showResult();
  changed();
}

function autoPicks() {
  return state.auto.doc.discs.filter((d) => d.usable).map(placeOf);
}

async function saveDiscs() {
  showError("");
  try {
    const file = await postJson("/photo/discs-file", { discs: state.picks.map(placeOf) });
    const blob = new Blob([JSON.stringify(file, null, 1) + "\n"], { type: "application/json" });
    const link = document.createElement("a");
    link.href = URL.createObjectURL(blob);
    link.download = `${state.info.file.replace(/\.[^.]*$/, "")}_discs.json`;
    document.body.appendChild(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(link.href), 10_000);
  } catch (error) {
    showError(error.message);
  }
}

function shapesUi() {
  const list = $("shapes").querySelector(".list");
  for (const name of state.info.shapes) {
    const label = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox";
    box.value = name;
    box.checked = true;
    box.addEventListener("change", () => {
      const chosen = [...list.querySelectorAll("input:checked")].map((b) => b.value);
      state.shapes = chosen.length === state.info.shapes.length ? null : chosen;
      const left = state.info.shapes.filter((name) => !chosen.includes(name));
      $("shape-summary").textContent = !state.shapes ? "all" : !chosen.length ? "none"
        : left.length < chosen.length ? `all but ${left.join(", ")}` : chosen.join(", ");
    });
    label.append(box, ` ${name}`);
    list.appendChild(label);
  }
}

// --- start ---------------------------------------------------------------------------------------

async function start() {
  state.info = await getJson("/photo/info.json");
  $("name").textContent = state.info.file;
  $("size").textContent = `${state.info.width}×${state.info.height}`;
  document.title = `bokehfit view: ${state.info.file}`;
  shapesUi();
  image.src = "/photo/image.jpg";
  image.onload = draw;
  resize();
  fitView();
  setRunning(state.info.auto_job);
  const status = await waitFor(state.info.auto_job);
  setRunning(null);
  if (status.state !== "done") throw new Error(status.error || "the automatic compare did not finish");
  state.auto = await loadJob(state.info.auto_job);
  state.shown = state.auto;
  state.picks = autoPicks();
  showResult();
  changed();
  document.body.dataset.ready = "true";
}

$("refit").addEventListener("click", refit);
$("cancel").addEventListener("click", () => postJson("/photo/cancel", {}).catch((error) => showError(error.message)));
$("undo").addEventListener("click", undo);
$("reset").addEventListener("click", reset);
$("save-discs").addEventListener("click", saveDiscs);
$("add").addEventListener("click", () => {
  const on = $("add").getAttribute("aria-pressed") !== "true";
  $("add").setAttribute("aria-pressed", String(on));
});
window.addEventListener("keydown", (event) => {
  if ((event.ctrlKey || event.metaKey) && event.key === "z") {
    event.preventDefault();
    undo();
  }
});
new ResizeObserver(resize).observe(canvas);

// drawTile: the kernel renderer on a tile of one's own (the tests draw apertures the photo has not).
async function drawTile(tile) {
  const renderer = await kernelRenderer();
  if (!renderer) return { error: kernels.failed };
  const drawn = await renderer.draw(tile);
  return { kernels: drawn.kernels.map((k) => Array.from(k)), profiles: drawn.channels.map((c) => Array.from(c)) };
}

window.photoView = { state, clientXY, refit, reset, undo, drawTile };

start().catch((error) => {
  document.body.dataset.state = "failed";
  $("verdict").textContent = `The compare failed: ${error.message}`;
  showError(error.message);
});
