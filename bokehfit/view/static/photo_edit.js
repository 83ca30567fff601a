// photo_edit.js: editing the discs with the pointer: a click drops a disc from the picks or picks
// it again, Shift+drag (or Add disc, then drag) adds one, the wheel zooms about the pointer, a drag
// pans; hovering a disc tells what it is.

import { $ } from "./common.js";
import { canvas, draw, photoXY } from "./photo_draw.js";
import { changed, select } from "./photo_results.js";
import { marks, pickOf, placeOf, remember, state } from "./photo_state.js";

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
