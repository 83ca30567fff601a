// viewer_renderer.js: the viewer's WebGPU renderer and its buffers. It compiles the served path
// tracer (/pathtrace.wgsl), the point-light view (viewer_points.js) and the display pass
// (/display.wgsl), packs the RenderParams uniform by the served layout, queues batches of samples
// and shows what is accumulated.
//
// The display goes to a 2-D canvas, not a WebGPU one: headless Chromium on SwiftShader with
// the usual flags has no shared-image backing for a WebGPU canvas and loses the device at its
// first present, which would stop the render; one read-back a batch (1 MiB at 512×512) works
// everywhere.

import { SETTERS, adapterName } from "./common.js";
import { POINT_MAX_GROUPS, POINT_SAMPLES, POINTS_WGSL } from "./viewer_points.js";

export class NoWebGPU extends Error {}

export class Renderer {
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
    this.adapterName = adapterName(adapter);
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
    for (const f of this.layout.fields) {
      const v = values[f.name];
      if (v === undefined || v === null) throw new Error(`params.json lacks RenderParams.${f.name}`);
      const components = f.components === 1 ? [v] : v;
      if (!Array.isArray(components) || components.length !== f.components) {
        throw new Error(`params.json: RenderParams.${f.name} is a ${f.type}, ${f.components} values`);
      }
      const setter = SETTERS[f.scalar];
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
