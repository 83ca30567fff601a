// viewer.js: the bokehfit viewer. Path-traces the Cornell box progressively through
// WebGPU with the package's own WGSL, and sketches the box from above.
//
// The page's modules, one job each: viewer.js (this one: the page, its settings sent to the
// server, the progressive loop), viewer_renderer.js (the WebGPU renderer and its buffers),
// viewer_points.js (the point-light view's WGSL), viewer_topdown.js (the top-down sketch),
// viewer_controls.js (the URL's settings and the controls), viewer_files.js (the matched aperture,
// the mask upload, Save PNG, the requests to the server), png_text.js (a PNG's tEXt chunks) and
// common.js (what the photo page shares).
//
// Nothing about the renderer is written twice here. From the server (bokehfit/view/server.py):
//   /pathtrace.wgsl  the path tracer, built by the same Python code as `bokehfit render` uses;
//   /config.json     the RenderParams layout (each field's name, WGSL type, scalar type,
//                    components and byte offset, from bokehfit.gpu.layout; padded size, WGSL
//                    declaration), entry point, workgroup size, bindings, the scene for the
//                    sketch, the shapes and the slider ranges;
//   /params.json     every RenderParams value for the current settings (a vector field as a
//                    list), filled by the Python renderer's own code; the page only sets
//                    sample_index;
//   /display.wgsl    the display pass (shaders/display.wgsl): the accumulation buffer (sum of
//                    samples in rgb, count in a) through tone_map_srgb8 of shaders/tonemap.wgsl,
//                    the WGSL twin of the tone map `bokehfit render --out x.png` writes with
//                    (scale by 2^EV, clip to [0, 1], sRGB), into 8-bit RGBA, which is read back
//                    and put on the #render canvas;
//   /mask            (POST) an uploaded PNG becomes the custom mask aperture's table, built by
//                    the same Python code as `bokehfit render --mask`; /mask_table?mask=DIGEST
//                    is that table as float32, uploaded as it is into the mask_table binding.
// The one shader written in the page is POINTS_WGSL (viewer_points.js), the point-light view's
// two entry points.
//
// URL options (read in viewer_controls.js): ?size=WxH, max_spp=N (stop there; default 4096),
// mode=edit, scene=points, and the settings shape, angle, fstop, focus, blades, aspect, and the
// real-lens features roundness, squeeze, rim, vignetting_radius with vignetting_shift,
// chromatic_red with chromatic_blue.

import { $ } from "./common.js";
import { controls, parseSize, query } from "./viewer_controls.js";
import { fetchJSON, files } from "./viewer_files.js";
import { NoWebGPU, Renderer } from "./viewer_renderer.js";
import { TopDown } from "./viewer_topdown.js";

const DEFAULT_MAX_SPP = 4096;
// Samples per submission batch adapt so that one batch takes about this long (ms).
const BATCH_TARGET_MS = 60;
const MAX_BATCH = 32;
// Window of the samples-per-second estimate (ms).
const RATE_WINDOW_MS = 3000;

// --- the page -----------------------------------------------------------------------------

class Viewer {
  constructor(config) {
    this.config = config;
    const [lo, hi] = config.ranges.image_side;
    const size = parseSize(query.get("size"));
    const fits = size && size.every((v) => v >= lo && v <= hi);
    [this.width, this.height] = fits ? size : [config.defaults.width, config.defaults.height];
    this.sizeNote = query.has("size") && !fits ? `size must be WxH, each ${lo} to ${hi} px (got ${query.get("size")}): using the default` : "";
    const maxSpp = parseInt(query.get("max_spp"), 10);
    this.maxSpp = maxSpp >= 1 ? maxSpp : DEFAULT_MAX_SPP;
    this.maskName = null; // the uploaded mask's file name, for the render command
    this.shapes = Object.fromEntries(config.shapes.map((s) => [s.name, s]));
    this.state = this.initialState();
    this.info = null; // the last /params.json answer
    this.renderer = null;
    this.spp = 0; // samples finished since the last restart
    this.queued = 0; // samples queued since the last restart
    this.generation = 0;
    this.restarts = 0;
    this.batch = 1;
    this.history = [];
    this.request = 0;
    this.wake = null;
    this.sketch = new TopDown($("topdown"), config);
    this.scene = query.get("scene") === "points" ? "points" : "cornell";
  }

  async start() {
    this.setupControls();
    this.setMode(query.get("mode") === "edit" ? "edit" : "view");
    this.setScene(this.scene);
    $("fallback-command").textContent = this.config.fallback_command;
    try {
      this.renderer = await Renderer.create($("render"), this.config, this.width, this.height);
      $("adapter").textContent = `· ${this.renderer.adapterName}`;
      this.renderer.scene = this.scene;
      document.body.dataset.webgpu = "ok";
    } catch (error) {
      this.renderer = null;
      if (error instanceof NoWebGPU) {
        document.body.dataset.webgpu = "none";
        $("no-webgpu-reason").textContent = error.message;
        $("no-webgpu").hidden = false;
      } else {
        document.body.dataset.webgpu = "error";
        this.showMessage(`The render cannot start: ${error.message}`, true);
      }
    }
    await this.apply();
    if (this.sizeNote) this.showMessage(this.sizeNote, true);
    document.body.dataset.ready = "true";
    if (this.renderer) {
      this.loop().catch((error) => {
        const lost = this.renderer.lost ? ` (device lost: ${this.renderer.lost})` : "";
        this.showMessage(`The render stopped: ${error.message}${lost}`, true);
      });
    }
  }

  // --- settings → server → restart

  paramsQuery() {
    const s = this.state;
    const spec = this.shapes[s.shape];
    const q = new URLSearchParams({
      shape: s.shape,
      angle: String(s.angle_deg),
      fstop: String(s.fstop),
      focus: String(s.focus_distance_m),
      width: String(this.width),
      height: String(this.height),
    });
    if (spec.takes_blades) q.set("blades", String(s.blades));
    if (spec.takes_aspect) q.set("aspect", String(s.aspect));
    if (spec.rounds) q.set("roundness", String(s.roundness));
    if (spec.tabulated) q.set("mask", s.mask);
    q.set("squeeze", String(s.squeeze));
    q.set("rim", String(s.rim));
    if (s.vignetting) {
      q.set("vignetting_radius", String(s.vignetting_radius));
      q.set("vignetting_shift", String(s.vignetting_shift));
    }
    if (s.chromatic_red !== 0 || s.chromatic_blue !== 0) {
      q.set("chromatic_red", String(s.chromatic_red));
      q.set("chromatic_blue", String(s.chromatic_blue));
    }
    return q;
  }

  // Ask the server for the uniform values of the current settings; the latest answer wins.
  async apply() {
    const id = ++this.request;
    this.syncControls();
    this.sketch.draw(this.state, this.info);
    let info;
    try {
      info = await fetchJSON(`/params.json?${this.paramsQuery()}`);
    } catch (error) {
      if (id === this.request) this.showMessage(error.message, true);
      return;
    }
    if (id !== this.request) return;
    this.info = info;
    this.showMessage("");
    this.restart();
    this.syncControls();
    this.sketch.draw(this.state, info);
  }

  restart() {
    this.generation++;
    this.restarts++;
    document.body.dataset.restarts = String(this.restarts);
    this.spp = 0;
    this.queued = 0;
    this.history = [];
    this.showSpp();
    if (this.renderer) {
      this.renderer.setValues(this.info.values);
      this.renderer.clear();
    }
    if (this.wake) this.wake();
  }

  // --- the progressive loop: batches of samples, one present per batch

  async loop() {
    const r = this.renderer;
    for (;;) {
      if (r.lost) {
        this.showMessage(`The WebGPU device was lost (${r.lost}); reload the page.`, true);
        return;
      }
      if (this.spp >= this.maxSpp) {
        $("rate").textContent = "· done";
        await new Promise((resolve) => (this.wake = resolve));
        this.wake = null;
        continue;
      }
      const generation = this.generation;
      const count = Math.min(this.batch, this.maxSpp - this.queued);
      const t0 = performance.now();
      r.addSamples(this.queued, count);
      this.queued += count;
      await r.present();
      const ms = performance.now() - t0;
      if (generation === this.generation) {
        this.spp += count;
        this.history.push([performance.now(), this.spp]);
        this.showSpp();
      }
      this.batch = ms < BATCH_TARGET_MS / 2 ? Math.min(MAX_BATCH, this.batch * 2) : ms > 2 * BATCH_TARGET_MS ? Math.max(1, this.batch >> 1) : this.batch;
      await new Promise((resolve) => requestAnimationFrame(resolve));
    }
  }

  samplesPerSecond() {
    const h = this.history;
    if (h.length < 2) return null;
    const now = h[h.length - 1];
    let i = 0;
    while (i < h.length - 2 && now[0] - h[i][0] > RATE_WINDOW_MS) i++;
    const [t, n] = h[i];
    return now[0] > t ? (1000 * (now[1] - n)) / (now[0] - t) : null;
  }

  showSpp() {
    if (this.spp > 0) document.body.dataset.firstFrame = "done"; // the loading message goes
    $("spp").textContent = String(this.spp);
    const rate = this.samplesPerSecond();
    $("rate").textContent = rate === null ? "" : `· ${rate.toFixed(rate < 10 ? 2 : 1)} spp/s`;
  }

  showMessage(text, error = false) {
    const m = $("message");
    m.textContent = text;
    m.classList.toggle("error", error);
  }
}

// The controls and the files are methods of the page too.
Object.assign(Viewer.prototype, controls, files);

async function main() {
  let config;
  try {
    config = await fetchJSON("/config.json");
  } catch (error) {
    $("message").textContent = `Cannot reach the bokehfit server: ${error.message}`;
    return;
  }
  const viewer = new Viewer(config);
  // For tests and tools: the state, the counters and the linear image.
  window.bokehfitViewer = {
    get spp() { return viewer.spp; },
    get restarts() { return viewer.restarts; },
    get state() { return { ...viewer.state }; },
    get scene() { return viewer.scene; },
    get info() { return viewer.info; },
    samplesPerSecond: () => viewer.samplesPerSecond(),
    readImage: async () => {
      const image = await viewer.renderer.readImage();
      return { ...image, rgb: Array.from(image.rgb) };
    },
    pngBase64: async () => {
      const bytes = await viewer.pngBytes();
      let s = "";
      for (const b of bytes) s += String.fromCharCode(b);
      return btoa(s);
    },
    fileName: () => viewer.fileName(),
  };
  await viewer.start();
}

main();
