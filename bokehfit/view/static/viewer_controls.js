// viewer_controls.js: the viewer's settings in the URL and in its controls. The first settings
// come from the URL (viewer.js lists its options); the sliders, the shape list, the mode and scene
// toggles and the clicks in the top-down sketch change them, and syncControls shows them. The
// methods are the Viewer's (viewer.js adds them to its prototype), so `this` is the page.

import { $ } from "./common.js";

export const query = new URLSearchParams(location.search);

// The real-lens features' sliders (design.md §3b): state key = range and default key of
// /config.json; the element id is the key with dashes.
const FEATURE_SLIDERS = ["roundness", "squeeze", "rim", "vignetting_radius", "vignetting_shift", "chromatic_red", "chromatic_blue"];

export function parseSize(text) {
  const m = /^\s*(\d+)\s*[xX×]\s*(\d+)\s*$/.exec(text || "");
  return m ? [parseInt(m[1], 10), parseInt(m[2], 10)] : null;
}

export const controls = {
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
  },

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
  },

  setMode(mode) {
    document.body.dataset.mode = mode;
    const t = $("mode-toggle");
    t.textContent = mode === "edit" ? "View" : "Edit";
    t.setAttribute("aria-pressed", String(mode === "edit"));
    t.title = mode === "edit" ? "Back to view mode (key E)" : "Edit the settings (key E)";
    this.sketch.hover = null;
    this.sketch.draw(this.state, this.info);
  },

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
  },

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
  },
};
