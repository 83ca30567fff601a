// photo_refit.js: the refit of the picked discs (POST /photo/refit, polled, cancellable), undo and
// reset, the saved discs file, and the shapes a refit may try.

import { $ } from "./common.js";
import { changed, showResult } from "./photo_results.js";
import { getJson, placeOf, postJson, remember, showError, state } from "./photo_state.js";

const POLL_MS = 200;

export async function loadJob(job) {
  const [doc, tiles] = await Promise.all([getJson(`/photo/result.json?job=${job}`), getJson(`/photo/tiles.json?job=${job}`)]);
  return { job, doc, tiles };
}

export function setRunning(job) {
  state.running = job;
  document.body.dataset.state = job === null ? "idle" : "running";
  $("cancel").hidden = job === null;
  $("refit").disabled = job !== null || state.picks.length === 0;
  if (job === null) $("progress").textContent = "";
}

export async function waitFor(job) {
  for (;;) {
    const status = await getJson(`/photo/job?job=${job}`);
    if (status.state !== "running") return status;
    const steps = status.total ? ` ${status.done}/${status.total}` : "";
    $("progress").textContent = `${status.stage}${steps} · ${status.elapsed_s.toFixed(1)} s`;
    await new Promise((resolve) => setTimeout(resolve, POLL_MS));
  }
}

export async function refit() {
  showError("");
  const body = { discs: state.picks.map(placeOf) };
  if (state.shapes) body.shapes = state.shapes;
  let job;
  try {
    ({ job } = await postJson("/photo/refit", body));
  } catch (error) {
    showError(error.message);
    return;
  }
  setRunning(job);
  try {
    const status = await waitFor(job);
    if (status.state === "done") {
      const result = await loadJob(job);
      state.undo.push({ picks: state.picks.map(placeOf), shown: state.shown, selected: state.selected });
      $("undo").disabled = false;
      state.shown = result;
      if (!result.doc.discs.some((d) => d.index === state.selected)) state.selected = null;
      $("progress").textContent = "";
      showResult();
      $("progress").textContent = `refit in ${status.elapsed_s.toFixed(1)} s`;
    } else if (status.state === "failed") {
      showError(status.error);
    } else {
      showError("refit cancelled");
    }
  } catch (error) {
    showError(error.message);
  } finally {
    const text = $("progress").textContent;
    setRunning(null);
    $("progress").textContent = text.startsWith("refit in") ? text : "";
    changed();
  }
}

export function undo() {
  const last = state.undo.pop();
  if (!last) return;
  state.picks = last.picks;
  state.shown = last.shown;
  state.selected = last.selected;
  $("undo").disabled = state.undo.length === 0;
  showResult();
  changed();
}

export function reset() {
  remember();
  state.shown = state.auto;
  state.picks = autoPicks();
  state.selected = null;
  showResult();
  changed();
}

export function autoPicks() {
  return state.auto.doc.discs.filter((d) => d.usable).map(placeOf);
}

export async function saveDiscs() {
  showError("");
  try {
    const file = await postJson("/photo/discs-file", { discs: state.picks.map(placeOf) });
    const blob = new Blob([JSON.stringify(file, null, 1) + "\n"], { type: "application/json" });
    const link = document.createElement("a");
    link.href = URL.createObjectURL(blob);
    link.download = `${state.info.file.replace(/\.[^.]*$/, "")}_discs.json`;
    document.body.appendChild(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(link.href), 10_000);
  } catch (error) {
    showError(error.message);
  }
}

export function shapesUi() {
  const list = $("shapes").querySelector(".list");
  for (const name of state.info.shapes) {
    const label = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox";
    box.value = name;
    box.checked = true;
    box.addEventListener("change", () => {
      const chosen = [...list.querySelectorAll("input:checked")].map((b) => b.value);
      state.shapes = chosen.length === state.info.shapes.length ? null : chosen;
      const left = state.info.shapes.filter((name) => !chosen.includes(name));
      $("shape-summary").textContent = !state.shapes ? "all" : !chosen.length ? "none"
        : left.length < chosen.length ? `all but ${left.join(", ")}` : chosen.join(", ");
    });
    label.append(box, ` ${name}`);
    list.appendChild(label);
  }
}
