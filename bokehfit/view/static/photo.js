// photo.js: `bokehfit view PHOTO`. The photo with every candidate outlined, the verdict, the fitted
// aperture and the candidates' table, all read from the server's `compare --json` document of the
// fit shown (never recomputed here); the person's picks, sent to POST /photo/refit, which fits
// exactly those discs (compare --discs semantics) in a worker the page polls and may cancel. The
// selected disc's kernel is drawn in the browser by the project's WGSL kernel renderer (WebGPU).
//
// The page's modules, one job each: photo.js (this one: the start and the buttons), photo_state.js
// (the state, the requests, the places), photo_draw.js (the photo and the discs on its canvas),
// photo_edit.js (editing the discs with the pointer), photo_results.js (the verdict, the aperture
// and the table), photo_match.js (the selected disc beside its model), photo_kernel.js (the
// kernel renderer), photo_refit.js (refit, undo, reset, saves) and common.js (what the Cornell-box
// page shares).

import { $ } from "./common.js";
import { canvas, clientXY, draw, fitView, image, resize } from "./photo_draw.js";
import "./photo_edit.js";
import { drawTile } from "./photo_match.js";
import { changed, showResult } from "./photo_results.js";
import { autoPicks, loadJob, refit, reset, saveDiscs, setRunning, shapesUi, undo, waitFor } from "./photo_refit.js";
import { getJson, postJson, showError, state } from "./photo_state.js";

// --- start ---------------------------------------------------------------------------------------

async function start() {
  state.info = await getJson("/photo/info.json");
  $("name").textContent = state.info.file;
  $("size").textContent = `${state.info.width}×${state.info.height}`;
  document.title = `bokehfit view: ${state.info.file}`;
  shapesUi();
  image.src = "/photo/image.jpg";
  image.onload = draw;
  resize();
  fitView();
  setRunning(state.info.auto_job);
  const status = await waitFor(state.info.auto_job);
  setRunning(null);
  if (status.state !== "done") throw new Error(status.error || "the automatic compare did not finish");
  state.auto = await loadJob(state.info.auto_job);
  state.shown = state.auto;
  state.picks = autoPicks();
  showResult();
  changed();
  document.body.dataset.ready = "true";
}

$("refit").addEventListener("click", refit);
$("cancel").addEventListener("click", () => postJson("/photo/cancel", {}).catch((error) => showError(error.message)));
$("undo").addEventListener("click", undo);
$("reset").addEventListener("click", reset);
$("save-discs").addEventListener("click", saveDiscs);
$("add").addEventListener("click", () => {
  const on = $("add").getAttribute("aria-pressed") !== "true";
  $("add").setAttribute("aria-pressed", String(on));
});
window.addEventListener("keydown", (event) => {
  if ((event.ctrlKey || event.metaKey) && event.key === "z") {
    event.preventDefault();
    undo();
  }
});
new ResizeObserver(resize).observe(canvas);

window.photoView = { state, clientXY, refit, reset, undo, drawTile };

start().catch((error) => {
  document.body.dataset.state = "failed";
  $("verdict").textContent = `The compare failed: ${error.message}`;
  showError(error.message);
});
