// viewer_files.js: what the viewer reads and writes as files, and its requests to the server: a
// `bokehfit compare --json` result as the matched aperture (POST /matched), a PNG as the custom mask
// aperture (POST /mask, then its tables from /mask_table), and the frame saved as a PNG with its
// settings. The methods are the Viewer's (viewer.js adds them to its prototype), so `this` is the page.

import { $ } from "./common.js";
import { withTextChunks } from "./png_text.js";

// A write (POST) names its content type and carries this run's token from the served page
// (the server refuses writes without both, so that no other web site can make them).
function writeHeaders(config, contentType) {
  const token = document.querySelector('meta[name="bokehfit-token"]').content;
  return { "Content-Type": contentType, [config.write_token_header]: token };
}

export async function fetchJSON(url, options) {
  const response = await fetch(url, options);
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || `${url}: HTTP ${response.status}`);
  return data;
}

export const files = {
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
  },

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
  },

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
  },

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
  },

  fileName() {
    const l = this.info.lens;
    const shape = this.info.label.replace(/[^a-z0-9.]+/gi, "") + ("aspect" in l && l.aspect !== null ? l.aspect : "");
    const angle = this.shapes[l.shape].has_angle ? `_${this.info.canonical_angle_deg.toFixed(1)}deg` : "";
    return `bokehfit_${this.config.scene.name}_${shape}${angle}_f${l.fstop.toFixed(2)}_focus${l.focus_distance_m.toFixed(3)}m_${this.spp}spp.png`;
  },

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
  },

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
  },
};
