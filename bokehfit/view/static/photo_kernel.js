// photo_kernel.js: the kernel renderer on the GPU (kernel_mc.wgsl through WebGPU) and the maths
// that makes its counts the disc's model: the move to the fitted centre and the fitted edge blur.
//
// The selected disc's kernel is drawn by kernel_mc.wgsl (served as /photo/kernel_mc.wgsl, the WGSL that
// bokehfit.kernels.mc compiles; its aperture samplers are shaders/apertures.wgsl): stratified samples
// of the fitted aperture (shape, angle, roundness, squeeze, rim, the vignetting's cut at the disc's
// field position) counted in the pixels they land in. Its KernelParams and ApertureParams are packed
// by the layouts in /photo/info.json, with the values of the disc's tile (the fit's own aperture, from
// Aperture.shader_params on the server). Here the counts become the disc's coverage, are moved to the
// fitted centre, blurred by the fitted edge blur and given the fitted levels: the model, and the residual.

import { SETTERS, adapterName } from "./common.js";

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

export class KernelRenderer {
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
    return new KernelRenderer(config, device, pipeline, adapterName(adapter));
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
