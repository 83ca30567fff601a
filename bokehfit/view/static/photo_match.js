// photo_match.js: the disc selected in the table beside its fitted model: its metrics, its crop,
// the kernel drawn by the kernel renderer (photo_kernel.js) at the fit's levels and the residual;
// without WebGPU, the model drawn in Python.

import { $ } from "./common.js";
import { KernelRenderer } from "./photo_kernel.js";
import { fmt, role, state } from "./photo_state.js";

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

export function showMatch() {
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

// drawTile: the kernel renderer on a tile of one's own (the tests draw apertures the photo has not).
export async function drawTile(tile) {
  const renderer = await kernelRenderer();
  if (!renderer) return { error: kernels.failed };
  const drawn = await renderer.draw(tile);
  return { kernels: drawn.kernels.map((k) => Array.from(k)), profiles: drawn.channels.map((c) => Array.from(c)) };
}
