// Clicks become masks: regions whose clicks changed get their mask from the server, one request at
// a time; clicks made meanwhile ride along with the next request.
import { api } from "../api.js";
import { sessionEnded } from "../session_ended.js";
import { persist } from "./editing.js";
import { regionName, say } from "./messages.js";
import { $, API, page, sleep } from "./page.js";
import { render } from "./render.js";
import { encodeCounts, runsOf } from "./rle.js";
import * as S from "./state.js";

let segmenting = false;

export async function segmentStale() {
  if (segmenting) return;
  segmenting = true;
  try {
    for (let next; page.history && (next = S.staleRegions(page.history.doc)[0]);) await segment(next);
  } finally {
    segmenting = false;
  }
  if (page.history) persist();
}

// Resolves once no mask is on its way (a submit takes the masks along).
export async function masksArrived() {
  while (segmenting) await sleep(50);
}

async function segment({ pair, kind, region }) {
  const { id, width, height } = page.frame;
  // The mask goes wherever the history holds these clicks. Whether it is news: a brush stroke or an
  // undo may have replaced the region on screen meanwhile, and that speaks for it now.
  const fresh = (runs) => {
    const next = S.region({ ...region, runs, stale: false });
    page.history.swapRegion(region, next);
    return S.holds(page.history.doc, next);
  };
  if (!region.points.length && !region.box) return fresh(null);
  // Only "not this" clicks and no mask yet: there is nothing to take them from. Said here, without
  // asking the server (which would refuse it); the red dots stay for the first positive click.
  if (!region.points.some((p) => p.label === 1) && !region.box && !region.area) {
    fresh(null);
    $("timing").textContent = "";
    say("Start with a click inside the object: a right-click only takes away from a mask.");
    return render();
  }
  const body = { points: region.points.map((p) => [p.x, p.y]), labels: region.points.map((p) => p.label),
                 region_kind: kind };
  if (region.box) body.box = region.box;
  if (region.area) body.prev_mask = { size: [height, width], counts: encodeCounts(region.runs) };
  const started = performance.now();
  const timing = $("timing");
  try {
    const result = await api(`${API}/frames/${id}/segment`, { method: "POST", body });
    if (page.frame?.id !== id) return;
    const ms = Math.round(performance.now() - started);
    if (result.embedding_cached === false) $("preparing").hidden = true;
    if (fresh(runsOf(result.mask))) {
      timing.textContent = ms < 1000 ? `mask in ${ms} ms` : `mask in ${(ms / 1000).toFixed(1)} s`;
      timing.title = `${result.model_id}, score ${result.score.toFixed(2)}, `
        + `${result.embedding_cached ? "cached embedding" : "embedding computed on this click"}`;
      say(result.area ? `${regionName(kind, pair)}: ${result.area.toLocaleString()} px.`
                      : "No mask at this click — try a point further inside.");
    }
  } catch (err) {
    if (page.frame?.id !== id) return;
    if (fresh(region.runs) && !sessionEnded(err)) {
      timing.textContent = "";  // it timed an earlier click
      say(`Segmentation failed: ${err.message}`, "error");
    }
  }
  render();
}
