// photo_results.js: what the page shows of a compare: the verdict, the fitted aperture, the
// candidates' table and the selected disc, all read from the compare's JSON document.

import { $ } from "./common.js";
import { draw } from "./photo_draw.js";
import { showMatch } from "./photo_match.js";
import { fmt, pickOf, role, state } from "./photo_state.js";

export function showResult() {
  const { doc } = state.shown;
  document.body.dataset.job = String(state.shown.job);
  document.body.dataset.status = doc.status;
  const verdict = $("verdict");
  verdict.textContent = doc.verdict;
  verdict.className = doc.status;
  $("details").textContent = doc.verdict_details || "";
  const a = doc.aperture;
  $("aperture-svg").innerHTML = state.shown.tiles.aperture_svg || "";
  const parts = [];
  if (a.shape) {
    parts.push(`${a.shape}${a.blades ? ` (${a.blades} blades)` : ""}`);
    if (a.angle_deg !== null) parts.push(`angle ${fmt(a.angle_deg, 2)}° ± ${fmt(a.angle_uncertainty_deg, 2)}°`);
    parts.push(`diameter ${fmt(a.diameter_px, 2)} px`);
    if (a.fstop !== null) parts.push(`f/${fmt(a.fstop, 2)}${a.fstop_bound === "upper" ? " (at most)" : ""}`);
    parts.push(`${a.discs_fitted} discs fitted`);
  } else {
    parts.push("no aperture fitted");
  }
  $("aperture-text").textContent = parts.join(" · ");
  $("save-json").href = `/photo/result.json?job=${state.shown.job}`;
  $("save-html").href = `/photo/report.html?job=${state.shown.job}`;
  const base = state.info.file.replace(/\.[^.]*$/, "");
  $("save-json").download = `${base}_bokehfit.json`;
  $("save-html").download = `${base}_bokehfit.html`;
  showTable();
  showMatch();
  draw();
}

export function showTable() {
  const { doc } = state.shown;
  const rows = [];
  const counts = { used: 0, usable: 0, rejected: 0 };
  for (const disc of doc.discs) {
    const r = role(disc);
    counts[r] += 1;
    const tr = document.createElement("tr");
    tr.dataset.index = String(disc.index);
    tr.dataset.role = r;
    tr.dataset.picked = String(pickOf(disc) >= 0);
    if (disc.index === state.selected) tr.className = "selected";
    const why = (disc.rejected_because || []).join("; ") + (pickOf(disc) >= 0 ? "" : (disc.rejected_because.length ? "; " : "") + "dropped");
    const cells = [disc.index, r, fmt(disc.center_xy[0], 1), fmt(disc.center_xy[1], 1), fmt(disc.diameter_px, 2),
      fmt(disc.fit_diameter_px, 2), fmt(disc.iou, 3), fmt(disc.angle_deg, 2), why];
    cells.forEach((value, i) => {
      const td = document.createElement("td");
      td.textContent = String(value);
      if (i === 1) td.className = `role-${r}`;
      tr.appendChild(td);
    });
    tr.addEventListener("click", () => select(disc.index));
    rows.push(tr);
  }
  $("candidates").tBodies[0].replaceChildren(...rows);
  document.body.dataset.used = String(counts.used);
  $("counts").textContent = `${doc.discs.length}: ${counts.used} used, ${counts.usable} usable, ${counts.rejected} rejected; ${state.picks.length} picked`;
}

export function select(index) {
  state.selected = index;
  showTable();
  showMatch();
  draw();
}

export function changed() {
  if (state.shown) showTable();
  $("refit").disabled = state.running !== null || state.picks.length === 0;
  draw();
}
