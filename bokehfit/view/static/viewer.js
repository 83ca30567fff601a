// viewer.js: the bokehfit viewer. Path-traces the Cornell box progressively through
// WebGPU with the package's own WGSL, and sketches the box from above.
//
// Nothing about the renderer is written twice here. From the server (bokehfit/view/server.py):
//   /pathtrace.wgsl  the path tracer, built by the same Python code as `bokehfit render` uses;
//   /config.json     the RenderParams layout (each field's name, WGSL type, scalar type,
//                    components and byte offset, from bokehfit.gpu.layout; padded size, WGSL
//                    declaration), entry point, workgroup size, bindings, the scene for the
//                    sketch, the shapes and the slider ranges;
//   /params.json     every RenderParams value for the current settings (a vector field as a
//                    list), filled by the Python renderer's own code; this file only sets
//                    sample_index;
//   /display.wgsl    the display pass (shaders/display.wgsl): the accumulation buffer (sum of
//                    samples in rgb, count in a) through tone_map_srgb8 of shaders/tonemap.wgsl,
//                    the WGSL twin of the tone map `bokehfit render --out x.png` writes with
//                    (scale by 2^EV, clip to [0, 1], sRGB), into 8-bit RGBA, which is read back
//                    and put on the #render canvas;
//   /mask            (POST) an uploaded PNG becomes the custom mask aperture's table, built by
//                    the same Python code as `bokehfit render --mask`; /mask_table?mask=DIGEST
//                    is that table as float32, uploaded as it is into the mask_table binding.
// The one shader written here is POINTS_WGSL below, the point-light view's two entry points.
// The display goes to a 2-D canvas, not a WebGPU one: headless Chromium on SwiftShader with
// the usual flags has no shared-image backing for a WebGPU canvas and loses the device at its
// first present, which would stop the render; one read-back a batch (1 MiB at 512×512) works
// everywhere.
//
// URL options: ?size=WxH, max_spp=N (stop there; default 4096), mode=edit, scene=points, and the
// settings shape, angle, fstop, focus, blades, aspect, and the real-lens features roundness,
// squeeze, rim, vignetting_radius with vignetting_shift, chromatic_red with chromatic_blue.

const $ = (id) => document.getElementById(id);
const query = new URLSearchParams(location.search);

const DEFAULT_MAX_SPP = 4096;
// The real-lens features' sliders (design.md §3b): state key = range and default key of
// /config.json; the element id is the key with dashes.
const FEATURE_SLIDERS = ["roundness", "squeeze", "rim", "vignetting_radius", "vignetting_shift", "chromatic_red", "chromatic_blue"];
// Samples per submission batch adapt so that one batch takes about this long (ms).
const BATCH_TARGET_MS = 60;
const MAX_BATCH = 32;
// Window of the samples-per-second estimate (ms).
const RATE_WINDOW_MS = 3000;

// Aperture samples per point light and batch, and the most workgroups of one point-light dispatch.
const POINT_SAMPLES = 65536;
const POINT_MAX_GROUPS = 4096;

// The point-light view: six point lights on black, each drawn by splatting aperture samples
// through it as `bokehfit render --scene points` does (points.wgsl), so that the aperture's
// shape is what one sees: upright in the top row (lights behind the focus plane), turned by
// 180° in the bottom row (in front of it). Appended to the served path tracer's WGSL, whose
// aperture and camera functions it calls; counts in u32 atomics (WGSL has no float atomics),
// then added to the accumulation buffer, which the tone map shows as it shows the path tracer's.
const POINTS_WGSL = (binding, gain) => `
@group(0) @binding(${binding}) var<storage, read_write> point_counts: array<atomic<u32>>;
// Aperture samples per light and batch, the lights, the plateau after the exposure.
const POINT_SAMPLES: u32 = ${POINT_SAMPLES}u;
const POINT_LIGHTS: u32 = 6u;
const POINT_GAIN: f32 = ${gain};

// The near row's 1/depth offset from the focus plane: its discs a fifth of the image wide.
fn point_offset() -> f32 {
    let lens_diameter = 2.0 * params.aperture_scale / sqrt(PI);  // equal-area aperture, metres
    return 0.4 * params.tan_half.x / lens_diameter;
}

// Light i: its pinhole slopes (x/z, y/z), 1/depth, and its disc's size over the near row's.
// The far row is as far as the near one is near, or at infinity where that is nearer: its
// discs are then smaller (a lens focused close blurs lights at infinity only so much).
fn point_light(i: u32) -> vec4f {
    let far = i < 3u;
    let x = 0.55 * (f32(i % 3u) - 1.0) * params.tan_half.x;
    let y = select(-0.45, 0.45, far) * params.tan_half.y;
    let offset = select(point_offset(), min(point_offset(), 1.0 / params.focus_distance), far);
    return vec4f(x, y, 1.0 / params.focus_distance + select(1.0, -1.0, far) * offset, offset / point_offset());
}

@compute @workgroup_size(64)
fn point_splat(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    for (var n = gid.x; n < POINT_SAMPLES * POINT_LIGHTS; n += groups.x * 64u) {
        let light = point_light(n / POINT_SAMPLES);
        // samples in proportion to the disc's area: every disc as bright
        if (f32(n % POINT_SAMPLES) >= f32(POINT_SAMPLES) * light.w * light.w) {
            continue;
        }
        let stream = (n / POINT_SAMPLES + 1u) ^ pcg_hash(params.seed);
        let index = params.sample_index * POINT_SAMPLES + n % POINT_SAMPLES;
        let u = vec2f(rand_unit_float(stream, index, 0u), rand_unit_float(stream, index, 1u));
        let near = light.z > 1.0 / params.focus_distance;
        let seen = aperture_seen(field_position(pinhole_image_xy(light.xy)), near);
        let drawn = aperture_point(u, seen, CHANNEL_GREEN);
        if (drawn.z > 0.0) {
            // the lens ray from the aperture point through the light, on the focus plane, seen from the pinhole
            let xy = pinhole_image_xy(drawn.xy * (1.0 / params.focus_distance - light.z) + light.xy);
            if (all(xy >= vec2f(0.0)) && all(xy < vec2f(params.image_size))) {
                atomicAdd(&point_counts[u32(xy.y) * params.image_size.x + u32(xy.x)], 1u);
            }
        }
    }
}

@compute @workgroup_size(64)
fn point_resolve(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    // A near disc's area in pixels (the aperture's area, scaled by the offset into slopes, then
    // pixels): counts × area / samples is 1 inside any disc.
    let offset = point_offset();
    let per_slope = vec2f(params.image_size) / (2.0 * params.tan_half);
    let area_px = params.aperture_scale * params.aperture_scale * offset * offset * per_slope.x * per_slope.y;
    let scale = POINT_GAIN * area_px / f32(POINT_SAMPLES);
    for (var i = gid.x; i < params.image_size.x * params.image_size.y; i += groups.x * 64u) {
        let count = atomicLoad(&point_counts[i]);
        atomicStore(&point_counts[i], 0u);
        accum[i] += vec4f(vec3f(scale * f32(count)), 1.0);
    }
}
`;

class NoWebGPU extends Error {}

// A write (POST) names its content type and carries this run's token from the served page
// (the server refuses writes without both, so that no other web site can make them).
function writeHeaders(config, contentType) {
  const token = document.querySelector('meta[name="bokehfit-token"]').content;
  return { "Content-Type": contentType, [config.write_token_header]: token };
}

async function fetchJSON(url, options) {
  const response = await fetch(url, options);
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || `${url}: HTTP ${response.status}`);
  return data;
}

function parseSize(text) {
  const m = /^\s*(\d+)\s*[xX×]\s*(\d+)\s*$/.exec(text || "");
  return m ? [parseInt(m[1], 10), parseInt(m[2], 10)] : null;
}

// --- the WebGPU renderer ------------------------------------------------------------------

class Renderer {
  static async create(canvas, config, width, height) {
    if (!("gpu" in navigator)) throw new NoWebGPU("navigator.gpu is missing: WebGPU is off or unsupported here.");
    const adapter = await navigator.gpu.requestAdapter();
    if (!adapter) throw new NoWebGPU("navigator.gpu.requestAdapter() found no adapter.");
    const device = await adapter.requestDevice();
    const r = new Renderer(canvas, config, adapter, device, width, height);
    await r.build();
    return r;
  }

  constructor(canvas, config, adapter, device, width, height) {
    this.canvas = canvas;
    this.config = config;
    this.adapter = adapter;
    this.device = device;
    this.width = width;
    this.height = height;
    const info = adapter.info || {};
    this.adapterName = [info.vendor, info.architecture, info.description].filter(Boolean).join(" ") || "WebGPU";
    this.layout = config.uniform;
    this.recordBytes = new ArrayBuffer(this.layout.size_bytes);
    this.record = new DataView(this.recordBytes);
    this.field = Object.fromEntries(this.layout.fields.map((f) => [f.name, f]));
    if (!this.field.sample_index) throw new Error("RenderParams has no sample_index field");
    this.lost = null;
    device.lost.then((info) => {
      this.lost = info.message || info.reason || "device lost";
    });
  }

  async build() {
    const { device, config, width, height } = this;
    const limits = device.limits;
    const bytes = 16 * width * height;
    if (bytes > Math.min(limits.maxStorageBufferBindingSize, limits.maxBufferSize)) {
      throw new Error(`${width}×${height} needs a ${bytes} byte buffer: this adapter allows ${limits.maxStorageBufferBindingSize}`);
    }
    const [gx, gy] = config.shader.workgroup_size;
    this.groups = [Math.ceil(width / gx), Math.ceil(height / gy)];
    if (Math.max(...this.groups) > limits.maxComputeWorkgroupsPerDimension) {
      throw new Error(`${width}×${height} needs more workgroups than this adapter allows`);
    }

    const code = await (await fetch(config.shader.url)).text();
    const module = device.createShaderModule({ label: "pathtrace", code });
    await this.checkCompilation(module, "pathtrace.wgsl");
    this.compute = await device.createComputePipelineAsync({
      label: "pathtrace",
      layout: "auto",
      compute: { module, entryPoint: config.shader.entry_point },
    });

    // The point-light view's pipelines: the same WGSL with its two entry points appended.
    const b = config.shader.bindings;
    const countsBinding = 1 + Math.max(...Object.values(b).map((e) => e.binding));
    const gain = 0.9 / Math.pow(2, config.exposure_ev);
    const pointsModule = device.createShaderModule({ label: "points", code: code + POINTS_WGSL(countsBinding, gain.toFixed(6)) });
    await this.checkCompilation(pointsModule, "point lights");
    const storage = (binding, type) => ({ binding, visibility: GPUShaderStage.COMPUTE, buffer: { type } });
    this.pointsLayout = device.createBindGroupLayout({
      label: "points",
      entries: [storage(b.params.binding, "uniform"), storage(b.accum.binding, "storage"), storage(countsBinding, "storage")]
        .concat(b.mask_table ? [storage(b.mask_table.binding, "read-only-storage")] : []),
    });
    this.countsBinding = countsBinding;
    const pointsPipeline = (entryPoint) => device.createComputePipelineAsync({
      label: entryPoint,
      layout: device.createPipelineLayout({ bindGroupLayouts: [this.pointsLayout] }),
      compute: { module: pointsModule, entryPoint },
    });
    [this.pointSplat, this.pointResolve] = await Promise.all([pointsPipeline("point_splat"), pointsPipeline("point_resolve")]);
    this.scene = "cornell";

    const display = config.display;
    const [dx, dy] = display.workgroup_size;
    this.displayGroups = [Math.ceil(width / dx), Math.ceil(height / dy)];
    const displayModule = device.createShaderModule({ label: "display", code: await (await fetch(display.url)).text() });
    await this.checkCompilation(displayModule, "display.wgsl");
    this.display = await device.createComputePipelineAsync({
      label: "display",
      layout: "auto",
      compute: { module: displayModule, entryPoint: display.entry_point, constants: { exposure_ev: config.exposure_ev } },
    });
    this.canvas.width = width;
    this.canvas.height = height;
    this.context = this.canvas.getContext("2d");
    this.imageData = this.context.createImageData(width, height);

    this.uniform = device.createBuffer({ label: "params", size: this.layout.size_bytes, usage: GPUBufferUsage.UNIFORM | GPUBufferUsage.COPY_DST });
    this.accum = device.createBuffer({
      label: "accum",
      size: bytes,
      usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_SRC | GPUBufferUsage.COPY_DST,
    });
    this.counts = device.createBuffer({ label: "point_counts", size: 4 * width * height, usage: GPUBufferUsage.STORAGE });
    // The mask's CDF tables: a single 0 until a mask is uploaded (the binding must exist).
    this.setMaskTable(new Float32Array(1));
    this.rgba = device.createBuffer({ label: "rgba", size: 4 * width * height, usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_SRC });
    this.staging = device.createBuffer({ label: "staging", size: 4 * width * height, usage: GPUBufferUsage.MAP_READ | GPUBufferUsage.COPY_DST });
    const d = display.bindings;
    this.displayGroup = device.createBindGroup({
      layout: this.display.getBindGroupLayout(d.params.group),
      entries: [
        { binding: d.params.binding, resource: { buffer: this.uniform } },
        { binding: d.accum.binding, resource: { buffer: this.accum } },
        { binding: d.rgba.binding, resource: { buffer: this.rgba } },
      ],
    });
  }

  // Upload a mask's tables (float32, as /mask_table serves them) and bind them with the rest.
  setMaskTable(table) {
    const { device } = this;
    const b = this.config.shader.bindings;
    if (table.byteLength > device.limits.maxStorageBufferBindingSize) {
      throw new Error(`the mask's tables (${table.byteLength} bytes) exceed this adapter's storage binding`);
    }
    const buffer = device.createBuffer({ label: "mask_table", size: table.byteLength, usage: GPUBufferUsage.STORAGE | GPUBufferUsage.COPY_DST });
    device.queue.writeBuffer(buffer, 0, table);
    const entries = [
      { binding: b.params.binding, resource: { buffer: this.uniform } },
      { binding: b.accum.binding, resource: { buffer: this.accum } },
    ];
    if (b.mask_table) entries.push({ binding: b.mask_table.binding, resource: { buffer } });
    this.computeGroup = device.createBindGroup({ layout: this.compute.getBindGroupLayout(b.params.group), entries });
    this.pointsGroup = device.createBindGroup({
      layout: this.pointsLayout,
      entries: [...entries, { binding: this.countsBinding, resource: { buffer: this.counts } }],
    });
    if (this.maskTable) this.maskTable.destroy();
    this.maskTable = buffer;
  }

  async checkCompilation(module, name) {
    const info = await module.getCompilationInfo();
    const errors = info.messages.filter((m) => m.type === "error");
    if (errors.length) {
      throw new Error(`${name} does not compile here: ` + errors.map((m) => `${m.lineNum}:${m.linePos} ${m.message}`).join("; "));
    }
  }

  // Fill the record from the server's values, by field name, at the served layout's offsets:
  // a vector field's components (a list in params.json) 4 bytes apart from its offset.
  setValues(values) {
    const setters = { f32: "setFloat32", u32: "setUint32", i32: "setInt32" };
    for (const f of this.layout.fields) {
      const v = values[f.name];
      if (v === undefined || v === null) throw new Error(`params.json lacks RenderParams.${f.name}`);
      const components = f.components === 1 ? [v] : v;
      if (!Array.isArray(components) || components.length !== f.components) {
        throw new Error(`params.json: RenderParams.${f.name} is a ${f.type}, ${f.components} values`);
      }
      const setter = setters[f.scalar];
      if (!setter) throw new Error(`RenderParams.${f.name}: unknown type ${f.type}`);
      components.forEach((c, i) => this.record[setter](f.offset + 4 * i, c, true));
    }
    const [width, height] = values.image_size;
    if (width !== this.width || height !== this.height) {
      throw new Error("params.json is for another image size");
    }
  }

  // Clear the accumulation buffer: the next sample is sample 0 again.
  clear() {
    const encoder = this.device.createCommandEncoder();
    encoder.clearBuffer(this.accum);
    this.device.queue.submit([encoder.finish()]);
  }

  // Queue samples first .. first + count - 1, each its own dispatch with its own sample_index.
  addSamples(first, count) {
    const { device } = this;
    for (let i = 0; i < count; i++) {
      this.record.setUint32(this.field.sample_index.offset, first + i, true);
      device.queue.writeBuffer(this.uniform, 0, this.recordBytes);
      const encoder = device.createCommandEncoder();
      const pass = encoder.beginComputePass();
      if (this.scene === "points") {
        pass.setBindGroup(0, this.pointsGroup);
        pass.setPipeline(this.pointSplat);
        pass.dispatchWorkgroups(Math.min(POINT_MAX_GROUPS, Math.ceil((6 * POINT_SAMPLES) / 64)));
        pass.setPipeline(this.pointResolve);
        pass.dispatchWorkgroups(Math.min(POINT_MAX_GROUPS, Math.ceil((this.width * this.height) / 64)));
      } else {
        pass.setPipeline(this.compute);
        pass.setBindGroup(this.config.shader.bindings.params.group, this.computeGroup);
        pass.dispatchWorkgroups(this.groups[0], this.groups[1]);
      }
      pass.end();
      device.queue.submit([encoder.finish()]);
    }
  }

  // Tone-map what is accumulated so far and show it; resolves once the queued samples are done.
  async present() {
    const { device, width, height } = this;
    const encoder = device.createCommandEncoder();
    const pass = encoder.beginComputePass();
    pass.setPipeline(this.display);
    pass.setBindGroup(this.config.display.bindings.params.group, this.displayGroup);
    pass.dispatchWorkgroups(this.displayGroups[0], this.displayGroups[1]);
    pass.end();
    encoder.copyBufferToBuffer(this.rgba, 0, this.staging, 0, 4 * width * height);
    device.queue.submit([encoder.finish()]);
    await this.staging.mapAsync(GPUMapMode.READ);
    this.imageData.data.set(new Uint8Array(this.staging.getMappedRange()));
    this.staging.unmap();
    this.context.putImageData(this.imageData, 0, 0);
  }

  // The linear image (average of the samples), row-major RGB float32: for tests and tools.
  async readImage() {
    const { device } = this;
    const bytes = 16 * this.width * this.height;
    const staging = device.createBuffer({ size: bytes, usage: GPUBufferUsage.MAP_READ | GPUBufferUsage.COPY_DST });
    const encoder = device.createCommandEncoder();
    encoder.copyBufferToBuffer(this.accum, 0, staging, 0, bytes);
    device.queue.submit([encoder.finish()]);
    await staging.mapAsync(GPUMapMode.READ);
    const data = new Float32Array(staging.getMappedRange().slice(0));
    staging.unmap();
    staging.destroy();
    const rgb = new Float32Array(3 * this.width * this.height);
    for (let p = 0; p < this.width * this.height; p++) {
      const n = Math.max(data[4 * p + 3], 1);
      for (let c = 0; c < 3; c++) rgb[3 * p + c] = data[4 * p + c] / n;
    }
    return { width: this.width, height: this.height, samples: data[3], rgb };
  }
}

// --- the top-down sketch ------------------------------------------------------------------

class TopDown {
  constructor(canvas, config) {
    this.canvas = canvas;
    this.config = config;
    const cam = config.scene.camera;
    this.cam = cam;
    this.tanHalf = null;
    // Depth range shown: just behind the camera to the far end of the focus slider.
    this.depthMin = -0.12;
    this.depthMax = config.ranges.focus_distance_m[1] + 0.05;
    this.hover = null;
    const ratio = window.devicePixelRatio || 1;
    this.cssWidth = canvas.clientWidth || canvas.width;
    this.cssHeight = canvas.clientHeight || canvas.height;
    canvas.width = Math.round(this.cssWidth * ratio);
    canvas.height = Math.round(this.cssHeight * ratio);
    this.ratio = ratio;
    const margin = 28;
    this.scale = (this.cssHeight - 2 * margin) / (this.depthMax - this.depthMin);
    this.originX = this.cssWidth / 2;
    this.originY = this.cssHeight - margin + this.depthMin * this.scale;
  }

  // World point → (across, depth) in the camera's frame: across along `right`, depth along `forward`.
  project(p) {
    const c = this.cam;
    const d = [p[0] - c.position[0], p[1] - c.position[1], p[2] - c.position[2]];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    return [dot(d, c.right), dot(d, c.forward)];
  }

  toScreen([across, depth]) {
    return [this.originX + across * this.scale, this.originY - depth * this.scale];
  }

  // Canvas position (CSS pixels) → depth along the view axis (metres).
  depthAt(y) {
    return (this.originY - y) / this.scale;
  }

  colour(name, alpha = 1) {
    const m = this.config.scene.materials[name];
    if (m.kind === "mirror") return `rgba(150, 190, 230, ${alpha})`;
    const [r, g, b] = m.colour.map((v) => Math.round(255 * Math.pow(Math.min(1, v), 1 / 2.2)));
    return `rgba(${r}, ${g}, ${b}, ${alpha})`;
  }

  // The scene's primitives, optionally reflected in the plane (o, n) (a mirror), drawn at `alpha`.
  drawScene(ctx, alpha, mirror) {
    const reflect = (p) => {
      if (!mirror) return p;
      const [o, n] = mirror;
      const t = 2 * ((p[0] - o[0]) * n[0] + (p[1] - o[1]) * n[1] + (p[2] - o[2]) * n[2]);
      return [p[0] - t * n[0], p[1] - t * n[1], p[2] - t * n[2]];
    };
    const pts = (corners) => corners.map((p) => this.toScreen(this.project(reflect(p))));
    const polygon = (ps) => {
      ctx.beginPath();
      ps.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
      ctx.closePath();
    };
    const scene = this.config.scene;
    // Floor first (a fill), then the light (dashed: it hangs above), then walls, block, balls.
    for (const q of scene.quads) {
      const kind = scene.materials[q.material].kind;
      if (Math.abs(q.normal[1]) > 0.9 && q.normal[1] > 0 && kind !== "emitter") {
        polygon(pts(q.corners));
        ctx.fillStyle = this.colour(q.material, 0.12 * alpha);
        ctx.fill();
      }
    }
    for (const q of scene.quads) {
      const kind = scene.materials[q.material].kind;
      if (Math.abs(q.normal[1]) > 0.9) {
        if (kind === "emitter") {
          polygon(pts(q.corners));
          ctx.setLineDash([3, 3]);
          ctx.strokeStyle = `rgba(255, 220, 120, ${alpha})`;
          ctx.lineWidth = 1;
          ctx.stroke();
          ctx.setLineDash([]);
        }
        continue;
      }
      // A vertical quad is a segment from above: its two projected corners farthest apart.
      const ps = pts(q.corners);
      let best = [ps[0], ps[1]];
      let far = -1;
      for (let i = 0; i < 4; i++) {
        for (let j = i + 1; j < 4; j++) {
          const d = Math.hypot(ps[i][0] - ps[j][0], ps[i][1] - ps[j][1]);
          if (d > far) [far, best] = [d, [ps[i], ps[j]]];
        }
      }
      ctx.beginPath();
      ctx.moveTo(...best[0]);
      ctx.lineTo(...best[1]);
      ctx.strokeStyle = this.colour(q.material, alpha);
      ctx.lineWidth = kind === "mirror" ? 4 : 3;
      ctx.stroke();
    }
    for (const b of scene.boxes) {
      polygon(pts(b.corners));
      ctx.fillStyle = this.colour(b.material, 0.35 * alpha);
      ctx.fill();
      ctx.strokeStyle = this.colour(b.material, alpha);
      ctx.lineWidth = 1.5;
      ctx.stroke();
    }
    for (const s of scene.spheres) {
      const [x, y] = this.toScreen(this.project(reflect(s.center)));
      ctx.beginPath();
      ctx.arc(x, y, s.radius * this.scale, 0, 2 * Math.PI);
      ctx.fillStyle = this.colour(s.material, 0.35 * alpha);
      ctx.fill();
      ctx.strokeStyle = this.colour(s.material, alpha);
      ctx.lineWidth = 1.5;
      ctx.stroke();
    }
  }

  // Planar mirrors standing upright: the sketch shows the room's reflection beyond them.
  mirrors() {
    const scene = this.config.scene;
    return scene.quads
      .filter((q) => scene.materials[q.material].kind === "mirror" && Math.abs(q.normal[1]) < 1e-6)
      .map((q) => [q.corners[0], q.normal]);
  }

  draw(state, info) {
    const ctx = this.canvas.getContext("2d");
    ctx.setTransform(this.ratio, 0, 0, this.ratio, 0, 0);
    ctx.clearRect(0, 0, this.cssWidth, this.cssHeight);
    ctx.font = "11px system-ui, sans-serif";
    const tan = info ? info.values.tan_half[0] : 0.5;
    const wedgeX = (depth) => depth * tan * this.scale;
    const [cx, cy] = this.toScreen([0, 0]);
    const yAt = (depth) => this.originY - depth * this.scale;

    // Depth-of-field band inside the field of view.
    if (info) {
      const dof = info.depth_of_field;
      const near = dof.near_m;
      const far = dof.far_m === null ? this.depthMax : Math.min(dof.far_m, this.depthMax);
      ctx.beginPath();
      ctx.moveTo(cx - wedgeX(near), yAt(near));
      ctx.lineTo(cx + wedgeX(near), yAt(near));
      ctx.lineTo(cx + wedgeX(far), yAt(far));
      ctx.lineTo(cx - wedgeX(far), yAt(far));
      ctx.closePath();
      ctx.fillStyle = "rgba(120, 200, 120, 0.22)";
      ctx.fill();
    }

    for (const m of this.mirrors()) this.drawScene(ctx, 0.3, m);
    this.drawScene(ctx, 1, null);

    // Field of view.
    ctx.beginPath();
    ctx.moveTo(cx - wedgeX(this.depthMax), yAt(this.depthMax));
    ctx.lineTo(cx, cy);
    ctx.lineTo(cx + wedgeX(this.depthMax), yAt(this.depthMax));
    ctx.strokeStyle = "rgba(230, 230, 230, 0.55)";
    ctx.lineWidth = 1;
    ctx.setLineDash([5, 4]);
    ctx.stroke();
    ctx.setLineDash([]);

    // Camera: a small body behind the lens.
    ctx.fillStyle = "#e6e6e6";
    ctx.fillRect(cx - 9, cy, 18, 10);
    ctx.fillRect(cx - 5, cy - 4, 10, 4);

    // Near and far limits, and the focus plane.
    const line = (depth, style, width, label, dx = 4) => {
      if (depth > this.depthMax) return;
      ctx.beginPath();
      ctx.moveTo(cx - wedgeX(depth), yAt(depth));
      ctx.lineTo(cx + wedgeX(depth), yAt(depth));
      ctx.strokeStyle = style;
      ctx.lineWidth = width;
      ctx.stroke();
      if (label) {
        ctx.fillStyle = style;
        ctx.fillText(label, Math.min(cx + wedgeX(depth) + dx, this.cssWidth - ctx.measureText(label).width - 4), yAt(depth) - 4);
      }
    };
    if (info) {
      const dof = info.depth_of_field;
      line(dof.near_m, "rgba(120, 200, 120, 0.9)", 1, "");
      if (dof.far_m !== null) line(dof.far_m, "rgba(120, 200, 120, 0.9)", 1, "");
    }
    line(state.focus_distance_m, "#f0a640", 2, `focus ${state.focus_distance_m.toFixed(3)} m`);

    if (this.hover !== null) {
      line(this.hover, "rgba(240, 166, 64, 0.6)", 1, `${this.hover.toFixed(3)} m`);
    }

    // Legend.
    ctx.fillStyle = "#9aa0a6";
    ctx.fillText("top view · camera at the bottom", 8, 14);
    ctx.fillStyle = "rgba(150, 190, 230, 0.9)";
    ctx.fillText("beyond the mirror: its reflection", 8, 28);
  }
}

// --- PNG with its settings in tEXt chunks ------------------------------------------------

const CRC_TABLE = (() => {
  const table = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    table[n] = c >>> 0;
  }
  return table;
})();

function crc32(bytes) {
  let c = 0xffffffff;
  for (const b of bytes) c = CRC_TABLE[(c ^ b) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

// A tEXt chunk: Latin-1 keyword, NUL, Latin-1 text (non-Latin-1 characters escaped as \uXXXX).
function textChunk(keyword, text) {
  const latin1 = text.replace(/[^\x20-\x7e\xa0-\xff\n]/g, (ch) => "\\u" + ch.charCodeAt(0).toString(16).padStart(4, "0"));
  const data = new Uint8Array(keyword.length + 1 + latin1.length);
  for (let i = 0; i < keyword.length; i++) data[i] = keyword.charCodeAt(i);
  for (let i = 0; i < latin1.length; i++) data[keyword.length + 1 + i] = latin1.charCodeAt(i);
  const chunk = new Uint8Array(12 + data.length);
  const view = new DataView(chunk.buffer);
  view.setUint32(0, data.length);
  chunk.set([0x74, 0x45, 0x58, 0x74], 4); // "tEXt"
  chunk.set(data, 8);
  view.setUint32(8 + data.length, crc32(chunk.subarray(4, 8 + data.length)));
  return chunk;
}

// Insert chunks right after IHDR (8-byte signature + 25-byte IHDR chunk).
function withTextChunks(png, entries) {
  const chunks = entries.map(([k, t]) => textChunk(k, t));
  const extra = chunks.reduce((n, c) => n + c.length, 0);
  const out = new Uint8Array(png.length + extra);
  out.set(png.subarray(0, 33), 0);
  let at = 33;
  for (const c of chunks) {
    out.set(c, at);
    at += c.length;
  }
  out.set(png.subarray(33), at);
  return out;
}

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

  initialState() {
    const d = this.config.defaults;
    const num = (key, fallback) => (query.has(key) && isFinite(parseFloat(query.get(key))) ? parseFloat(query.get(key)) : fallback);
    const shape = query.get("shape");
    return {
      // A mask shape needs an uploaded image first: it cannot come from the URL.
      shape: shape && shape in this.shapes && !this.shapes[shape].tabulated ? shape : d.shape,
      angle_deg: num("angle", d.angle_deg),
      fstop: num("fstop", d.fstop),
      focus_distance_m: num("focus", d.focus_distance_m),
      blades: Math.round(num("blades", d.blades)),
      aspect: num("aspect", d.aspect),
      roundness: num("roundness", d.roundness),
      squeeze: num("squeeze", d.squeeze),
      rim: num("rim", d.rim),
      vignetting: query.has("vignetting_radius") && query.has("vignetting_shift") ? true : d.vignetting,
      vignetting_radius: num("vignetting_radius", d.vignetting_radius),
      vignetting_shift: num("vignetting_shift", d.vignetting_shift),
      chromatic_red: num("chromatic_red", d.chromatic_red),
      chromatic_blue: num("chromatic_blue", d.chromatic_blue),
      mask: d.mask,
    };
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

  // --- controls

  // The Cornell box (path traced) or the point lights (the aperture's shape itself), one click apart.
  setScene(scene) {
    this.scene = scene;
    if (this.renderer) this.renderer.scene = scene;
    document.body.dataset.scene = scene;
    const t = $("scene-toggle");
    t.textContent = scene === "points" ? "Cornell box" : "Point lights";
    t.setAttribute("aria-pressed", String(scene === "points"));
    // the PNG's settings and render command are the Cornell box's
    $("save-png").disabled = scene === "points";
    if (this.info) this.restart();
  }

  setMode(mode) {
    document.body.dataset.mode = mode;
    const t = $("mode-toggle");
    t.textContent = mode === "edit" ? "View" : "Edit";
    t.setAttribute("aria-pressed", String(mode === "edit"));
    t.title = mode === "edit" ? "Back to view mode (key E)" : "Edit the settings (key E)";
    this.sketch.hover = null;
    this.sketch.draw(this.state, this.info);
  }

  setupControls() {
    const r = this.config.ranges;
    const select = $("shape");
    for (const s of this.config.shapes) select.add(new Option(s.name, s.name));
    const range = (id, [min, max]) => {
      $(id).min = String(min);
      $(id).max = String(max);
    };
    range("fstop", r.fstop);
    range("focus-distance", r.focus_distance_m);
    range("blades", r.blades);
    range("aspect", r.aspect);
    range("angle", r.angle_deg);
    for (const key of FEATURE_SLIDERS) range(key.replaceAll("_", "-"), r[key]);

    const bind = (id, key, parse) => {
      $(id).addEventListener("input", () => {
        this.state[key] = parse($(id).value);
        this.apply();
      });
    };
    bind("shape", "shape", (v) => v);
    bind("angle", "angle_deg", parseFloat);
    bind("blades", "blades", (v) => parseInt(v, 10));
    bind("aspect", "aspect", parseFloat);
    bind("fstop", "fstop", parseFloat);
    bind("focus-distance", "focus_distance_m", parseFloat);
    for (const key of FEATURE_SLIDERS) bind(key.replaceAll("_", "-"), key, parseFloat);
    $("vignetting").addEventListener("input", () => {
      this.state.vignetting = $("vignetting").checked;
      this.apply();
    });

    $("mode-toggle").addEventListener("click", () => this.setMode(document.body.dataset.mode === "edit" ? "view" : "edit"));
    $("scene-toggle").addEventListener("click", () => this.setScene(this.scene === "points" ? "cornell" : "points"));
    document.addEventListener("keydown", (event) => {
      const typing = event.target instanceof HTMLInputElement || event.target instanceof HTMLSelectElement;
      if (!typing && !event.ctrlKey && !event.metaKey && !event.altKey && event.key.toLowerCase() === "e") {
        this.setMode(document.body.dataset.mode === "edit" ? "view" : "edit");
      }
    });

    const canvas = $("topdown");
    const depthOf = (event) => {
      const rect = canvas.getBoundingClientRect();
      const y = ((event.clientY - rect.top) * this.sketch.cssHeight) / rect.height;
      const [lo, hi] = r.focus_distance_m;
      return Math.min(hi, Math.max(lo, this.sketch.depthAt(y)));
    };
    canvas.addEventListener("click", (event) => {
      if (document.body.dataset.mode !== "edit") return;
      this.state.focus_distance_m = Math.round(depthOf(event) * 1000) / 1000;
      this.apply();
    });
    canvas.addEventListener("mousemove", (event) => {
      if (document.body.dataset.mode !== "edit") return;
      this.sketch.hover = depthOf(event);
      this.sketch.draw(this.state, this.info);
    });
    canvas.addEventListener("mouseleave", () => {
      this.sketch.hover = null;
      this.sketch.draw(this.state, this.info);
    });

    $("matched-file").addEventListener("change", () => this.loadMatched());
    $("mask-file").addEventListener("change", () => this.loadMask());
    $("save-png").addEventListener("click", () => this.savePNG());
    $("reset").addEventListener("click", () => {
      for (const key of Object.keys(this.state)) this.state[key] = this.config.defaults[key];
      this.apply();
    });
  }

  // Show the state in the controls and as text.
  syncControls() {
    const s = this.state;
    const spec = this.shapes[s.shape];
    for (const option of $("shape").options) option.disabled = this.shapes[option.value].tabulated && !s.mask;
    $("shape").value = s.shape;
    $("angle").value = String(s.angle_deg);
    $("angle").disabled = !spec.has_angle;
    $("blades").value = String(s.blades);
    $("aspect").value = String(s.aspect);
    $("fstop").value = String(s.fstop);
    $("focus-distance").value = String(s.focus_distance_m);
    $("blades-row").hidden = !spec.takes_blades;
    $("aspect-row").hidden = !spec.takes_aspect;
    $("roundness-row").hidden = !spec.rounds;
    for (const key of FEATURE_SLIDERS) {
      $(key.replaceAll("_", "-")).value = String(s[key]);
      $(`${key.replaceAll("_", "-")}-out`).textContent = s[key].toFixed(key.startsWith("chromatic") ? 3 : 2);
    }
    $("vignetting").checked = s.vignetting;
    $("vignetting-out").textContent = s.vignetting ? "on" : "off";
    $("vignetting-radius").disabled = $("vignetting-shift").disabled = !s.vignetting;
    $("shape-out").textContent = "";
    $("angle-out").textContent = spec.has_angle ? `${s.angle_deg.toFixed(1)}°` : "—";
    $("blades-out").textContent = String(s.blades);
    $("aspect-out").textContent = s.aspect.toFixed(2);
    $("fstop-out").textContent = `f/${s.fstop.toFixed(s.fstop < 10 ? 1 : 0)}`;
    $("focus-distance-out").textContent = `${s.focus_distance_m.toFixed(3)} m`;
    const info = this.info;
    if (info) {
      const dof = info.depth_of_field;
      const far = dof.far_m === null ? "∞" : `${dof.far_m.toFixed(3)} m`;
      $("settings").textContent = `${info.describe} · ${this.width}×${this.height} px · sharp from ${dof.near_m.toFixed(3)} m to ${far}`;
      $("dof-text").textContent =
        `Depth of field for c = ${dof.coc_rule} = ${dof.coc_mm.toFixed(4)} mm: ${dof.near_m.toFixed(3)} m to ${far}` +
        ` (hyperfocal ${dof.hyperfocal_m.toFixed(2)} m). A light at infinity blurs to ${info.coc_px_at_infinity.toFixed(1)} px.`;
    }
  }

  // --- matched aperture from a `bokehfit compare --json` result

  async loadMatched() {
    const file = $("matched-file").files[0];
    if (!file) return;
    try {
      const text = await file.text();
      const m = await fetchJSON("/matched", { method: "POST", headers: writeHeaders(this.config, "application/json"), body: text });
      this.state.shape = m.shape;
      this.state.angle_deg = m.angle_deg;
      if (m.blades !== null) this.state.blades = m.blades;
      if (m.aspect !== null) this.state.aspect = m.aspect;
      if (m.fstop !== null) this.state.fstop = m.fstop;
      // The real-lens features: the document's, or the defaults where it has none (null).
      const d = this.config.defaults;
      this.state.roundness = m.roundness;
      this.state.squeeze = m.squeeze;
      this.state.rim = m.rim;
      this.state.vignetting = m.vignetting !== null;
      this.state.vignetting_radius = m.vignetting !== null ? m.vignetting.radius : d.vignetting_radius;
      this.state.vignetting_shift = m.vignetting !== null ? m.vignetting.shift : d.vignetting_shift;
      this.state.chromatic_red = m.chromatic !== null ? m.chromatic.red : d.chromatic_red;
      this.state.chromatic_blue = m.chromatic !== null ? m.chromatic.blue : d.chromatic_blue;
      await this.apply();
      const fstop = m.fstop !== null ? `, f/${m.fstop.toFixed(2)}` : "";
      this.showMessage(`Matched aperture from ${file.name}: ${m.describe}${fstop}` + (m.notes.length ? ` (${m.notes.join("; ")})` : ""));
    } catch (error) {
      this.showMessage(`${file.name}: ${error.message}`, true);
    } finally {
      $("matched-file").value = "";
    }
  }

  // --- the custom mask aperture from a PNG: the server builds its table, the GPU gets it

  async loadMask() {
    const file = $("mask-file").files[0];
    if (!file) return;
    try {
      const body = await file.arrayBuffer();
      const m = await fetchJSON(this.config.mask_upload.url, { method: "POST", headers: writeHeaders(this.config, "image/png"), body });
      const response = await fetch(m.table_url);
      if (!response.ok) throw new Error(`${m.table_url}: HTTP ${response.status}`);
      const table = new Float32Array(await response.arrayBuffer());
      if (table.length !== m.table_floats) throw new Error(`the mask's tables have ${table.length} values, not ${m.table_floats}`);
      // The tables first: the shader reads them only once the uniform says shape mask.
      if (this.renderer) this.renderer.setMaskTable(table);
      this.state.mask = m.mask;
      this.state.shape = "mask";
      this.maskName = file.name;
      await this.apply();
      this.showMessage(`Mask from ${file.name}: ${m.describe}`);
    } catch (error) {
      this.showMessage(`${file.name}: ${error.message}`, true);
    } finally {
      $("mask-file").value = "";
    }
  }

  // --- save the render as PNG, the settings in tEXt chunks and the file name

  settingsRecord() {
    return {
      bokehfit_version: this.config.bokehfit_version,
      scene: this.config.scene.name,
      width: this.width,
      height: this.height,
      spp: this.spp,
      seed: this.info.values.seed,
      exposure_ev: this.config.exposure_ev,
      lens: this.info.lens,
      depth_of_field: this.info.depth_of_field,
      command_line:
        `bokehfit render --scene ${this.config.scene.name} --shape ${this.state.shape}` +
        ` --angle ${this.info.lens.angle_deg} --fstop ${this.info.lens.fstop}` +
        ` --focus-distance ${this.info.lens.focus_distance_m}` +
        this.info.shape_flags +
        (this.shapes[this.state.shape].tabulated ? ` --mask ${this.maskName}` : "") +
        this.featureFlags() +
        ` --spp ${this.spp} --size ${this.width}x${this.height} --out frame.png`,
    };
  }

  // The render command's flags of the real-lens features that are on.
  featureFlags() {
    const l = this.info.lens;
    return (
      (l.roundness !== 0 ? ` --roundness ${l.roundness}` : "") +
      (l.squeeze !== 1 ? ` --squeeze ${l.squeeze}` : "") +
      (l.rim !== 0 ? ` --rim ${l.rim}` : "") +
      (l.vignetting !== null ? ` --vignetting ${l.vignetting.radius},${l.vignetting.shift}` : "") +
      (l.chromatic !== null ? ` --chromatic ${l.chromatic.red},${l.chromatic.blue}` : "")
    );
  }

  fileName() {
    const l = this.info.lens;
    const shape = this.info.label.replace(/[^a-z0-9.]+/gi, "") + ("aspect" in l && l.aspect !== null ? l.aspect : "");
    const angle = this.shapes[l.shape].has_angle ? `_${this.info.canonical_angle_deg.toFixed(1)}deg` : "";
    return `bokehfit_${this.config.scene.name}_${shape}${angle}_f${l.fstop.toFixed(2)}_focus${l.focus_distance_m.toFixed(3)}m_${this.spp}spp.png`;
  }

  async pngBytes() {
    if (!this.renderer) throw new Error("nothing rendered: this browser has no WebGPU");
    const blob = await new Promise((resolve) => $("render").toBlob(resolve, "image/png"));
    if (!blob) throw new Error("the canvas gave no image");
    const png = new Uint8Array(await blob.arrayBuffer());
    const record = this.settingsRecord();
    return withTextChunks(png, [
      ["Software", `bokehfit ${this.config.bokehfit_version} view`],
      ["Description", `${this.info.describe}, ${record.spp} spp, ${this.width}x${this.height}`],
      ["bokehfit", JSON.stringify(record)],
    ]);
  }

  async savePNG() {
    try {
      const bytes = await this.pngBytes();
      const url = URL.createObjectURL(new Blob([bytes], { type: "image/png" }));
      const a = document.createElement("a");
      a.href = url;
      a.download = this.fileName();
      document.body.append(a);
      a.click();
      a.remove();
      setTimeout(() => URL.revokeObjectURL(url), 10000);
      this.showMessage(`Saved ${a.download}`);
    } catch (error) {
      this.showMessage(`Cannot save: ${error.message}`, true);
    }
  }
}

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
