// photo_draw.js: the photo and the discs on its canvas: the view (zoom and pan), each mark's
// outline in the report's colours, the circle being drawn, and the mapping between the photo's
// pixels and the page.

import { $ } from "./common.js";
import { marks, state } from "./photo_state.js";

const COLOURS = { used: "#009e73", usable: "#56b4e9", rejected: "#d55e00", dropped: "#999999", added: "#ffffff" };
export const canvas = $("photo");
const ctx = canvas.getContext("2d");
export const image = new Image();

// --- drawing ----------------------------------------------------------------------------------

export function fitView() {
  const { width, height } = state.info;
  const scale = Math.min(canvas.width / width, canvas.height / height);
  state.view = { scale, x: (canvas.width - width * scale) / 2, y: (canvas.height - height * scale) / 2 };
}

export function resize() {
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

export function draw() {
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

export function photoXY(event) {
  const box = canvas.getBoundingClientRect();
  const ratio = canvas.width / box.width;
  const cx = (event.clientX - box.left) * ratio, cy = (event.clientY - box.top) * ratio;
  return [(cx - state.view.x) / state.view.scale, (cy - state.view.y) / state.view.scale];
}

// Client coordinates of a photo pixel (the tests click through this).
export function clientXY(x, y) {
  const box = canvas.getBoundingClientRect();
  const ratio = canvas.width / box.width;
  return [box.left + (x * state.view.scale + state.view.x) / ratio, box.top + (y * state.view.scale + state.view.y) / ratio];
}
