// Propagation runs as server jobs, one per region (illusion, then support), so two jobs never write
// the same frames' drafts at once; the page polls them for a progress bar.
import { api } from "../api.js";
import { encodeCounts } from "./rle.js";

const POLL_MS = 400;
const FINISHED = ["succeeded", "failed", "interrupted"];
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// regions: [{kind, runs}] of one pair; progress(fraction 0..1, text). Resolves to the frame ids written and skipped.
export async function propagate({ api: base, jobs, frame, pair, regions, count, progress }) {
  const written = new Set(), skipped = new Set();
  for (const [n, { kind, runs }] of regions.entries()) {
    const mask = { size: [frame.height, frame.width], counts: encodeCounts(runs) };
    let job = await api(`${base}/frames/${frame.id}/propagate`, { method: "POST", body: { pair, kind, mask, count } });
    while (!FINISHED.includes(job.state)) {
      progress((n + job.progress) / regions.length, `${kind}: ${Math.round(job.progress * 100)}%`);
      await sleep(POLL_MS);
      job = await api(`${jobs}/${job.id}`);
    }
    if (job.state !== "succeeded") throw new Error(`propagation ${job.state}${job.error ? `: ${job.error}` : ""}`);
    job.result.frames.forEach((id) => written.add(id));
    job.result.skipped.forEach((id) => skipped.add(id));
  }
  progress(1, `${written.size} frames`);
  return { written, skipped };
}
