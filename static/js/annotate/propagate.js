// Propagation: the current plane's masks carried to the next frames of the video as drafts. It runs
// as server jobs, one per region (illusion, then support), so two jobs never write the same frames'
// drafts at once; the page polls them for a progress bar.
import { api } from "../api.js";
import { choose } from "../dialogs.js";
import { plural } from "../labels.js";
import { sayFailure } from "../session_ended.js";
import { editable } from "./editing.js";
import { planeName, say } from "./messages.js";
import { $, API, page, prefs, root, savePrefs, sleep, ui } from "./page.js";
import { encodeCounts } from "./rle.js";
import * as S from "./state.js";

const POLL_MS = 400;
const FINISHED = ["succeeded", "failed", "interrupted"];
let propagating = false;

// P: asks how many frames, then runs the jobs with a progress bar under the button.
export async function propagate() {
  if (!editable()) return;
  if (propagating) return say("A propagation is already running.");
  const pair = S.pairOf(page.history.doc, ui.pair);
  const name = planeName(pair.id);
  const regions = S.KINDS.filter((kind) => pair[kind]?.area).map((kind) => ({ kind, runs: pair[kind].runs }));
  if (!regions.length) return say(`${name} has no mask to propagate yet.`, "error");
  $("propagate-what").textContent = `${name}'s ${regions.map((r) => r.kind).join(" and ")}`;
  $("propagate-count").value = prefs.propagate;
  if (await choose($("propagate-dialog")) !== "go") return;
  const count = Math.min(100, Math.max(1, Number($("propagate-count").value) || 5));
  savePrefs({ propagate: count });
  propagating = true;
  $("propagation").hidden = false;
  const progress = (fraction, text) => {
    $("propagate-progress").value = fraction;
    $("propagate-text").textContent = text;
  };
  try {
    const { written, skipped } = await runJobs({ frame: page.frame, pair: pair.id, regions, count, progress });
    say(`Propagated ${name} to ${plural(written.size, "frame")} as drafts`
      + (skipped.size ? ` (${skipped.size} skipped: submitted or held by someone else)` : "") + ". → to check them.", "ok");
  } catch (err) {
    sayFailure(say)(err);
  } finally {
    propagating = false;
    setTimeout(() => { if (!propagating) $("propagation").hidden = true; }, 4000);
  }
}

// regions: [{kind, runs}] of one pair; progress(fraction 0..1, text). Resolves to the frame ids written and skipped.
async function runJobs({ frame, pair, regions, count, progress }) {
  const written = new Set(), skipped = new Set();
  for (const [n, { kind, runs }] of regions.entries()) {
    const mask = { size: [frame.height, frame.width], counts: encodeCounts(runs) };
    let job = await api(`${API}/frames/${frame.id}/propagate`, { method: "POST", body: { pair, kind, mask, count } });
    while (!FINISHED.includes(job.state)) {
      progress((n + job.progress) / regions.length, `${kind}: ${Math.round(job.progress * 100)}%`);
      await sleep(POLL_MS);
      job = await api(`${root.dataset.jobs}/${job.id}`);
    }
    if (job.state !== "succeeded") throw new Error(`propagation ${job.state}${job.error ? `: ${job.error}` : ""}`);
    job.result.frames.forEach((id) => written.add(id));
    job.result.skipped.forEach((id) => skipped.add(id));
  }
  progress(1, plural(written.size, "frame"));
  return { written, skipped };
}
