// photo_state.js: the photo page's state and what it loads: the compares on the page, the
// person's picks and the undo history, the requests to the server, and the places (which disc a
// pick is, and every mark drawn on the photo).

import { $ } from "./common.js";

const TOKEN = document.querySelector('meta[name="bokehfit-token"]').content;
// A pick and a disc are the same place when the centres lie within this share of the diameter (labels.py's rule).
const SAME_PLACE = 0.25;

export const state = {
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

export async function getJson(path) {
  const response = await fetch(path, { cache: "no-store" });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
}

export async function postJson(path, body) {
  const response = await fetch(path, {
    method: "POST",
    headers: { "Content-Type": "application/json", "X-Bokehfit-Token": TOKEN },
    body: JSON.stringify(body),
  });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
}

export function showError(message) {
  $("error").textContent = message || "";
}

export function remember() {
  state.undo.push({ picks: state.picks.map(placeOf), shown: state.shown, selected: state.selected });
  $("undo").disabled = false;
}

// --- places -----------------------------------------------------------------------------------

function samePlace(a, b) {
  const d = Math.max(a.diameter_px, b.diameter_px);
  return Math.hypot(a.center_xy[0] - b.center_xy[0], a.center_xy[1] - b.center_xy[1]) <= SAME_PLACE * d;
}

export function pickOf(disc) {
  return state.picks.findIndex((p) => samePlace(p, disc));
}

export function placeOf(disc) {
  return { center_xy: [disc.center_xy[0], disc.center_xy[1]], diameter_px: disc.diameter_px };
}

export function role(disc) {
  return disc.used ? "used" : disc.usable ? "usable" : "rejected";
}

// Everything drawn: the shown fit's discs, the automatic candidates it lacks, the picks neither has.
export function marks() {
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

export const fmt = (value, digits) => (value === null || value === undefined ? "–" : Number(value).toFixed(digits));
