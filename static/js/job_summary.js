// What a job did and made, in words and links: shared by the jobs table and a job's own page.
import { el } from "./api.js";
import { formatNumber, plural } from "./labels.js";

// States a job ends in. A cancelled job is a train job whose run someone cancelled: it ended as they
// asked, so it is no failure (shown plainly, not in red), and it can be retried (resumed) like one.
export const ENDED = ["succeeded", "failed", "interrupted", "cancelled"];
export const FAILED = ["failed", "interrupted"];
export const RETRYABLE = [...FAILED, "cancelled"];

// One short line for a finished job's result.
export function summary(job) {
  const r = job.result;
  if (RETRYABLE.includes(job.state)) return job.error ?? job.state;
  if (!r) return "";
  if (r.skipped) {
    return `already in the workspace as video ${r.video_id}${r.video_name ? ` (“${r.video_name}”)` : ""}`
      + ` with ${plural(r.frames, "frame")}: nothing new to ingest`;
  }
  if (job.kind === "ingest") return `${plural(r.frames, "frame")}, ${plural(r.dropped_duplicates ?? 0, "near-duplicate")} dropped`;
  if (job.kind === "prefilter") return `${plural(r.frames, "frame")}: ${r.keep} kept, ${r.reject} dropped, ${r.undecided} to review`;
  if (job.kind === "propagate") return `drafts on ${plural(r.frames.length, "frame")}`;
  if (job.kind === "encode") return `${plural(r.encoded, "embedding")} for ${plural(r.frames, "frame")}`;
  if (job.kind === "propose") return `${plural(r.proposals, "proposal")} on ${plural(r.scanned, "new frame")} (${r.proposers.join(", ")})`;
  if (job.kind === "train") return trainSummary(r);
  if (job.kind === "evaluate") return evaluateSummary(r);
  if (job.kind === "generate" && r.sample_id != null) {
    return r.flags?.length ? `flagged: ${r.flags.join("; ")}` : "no QA flags";
  }
  if (job.kind === "export" || job.kind === "import") return r.samples != null ? plural(r.samples, "sample") : "";
  return "";
}

// "step 6/12 · loss 0.4123" while it runs; "12 steps · best val EPE 1.234 px" once it has ended.
function trainSummary(r) {
  const parts = [r.steps ? `step ${r.step}/${r.steps}` : plural(r.step ?? 0, "step")];
  if (r.loss != null) parts.push(`loss ${formatNumber(r.loss)}`);
  if (r.best_val_epe != null) parts.push(`best val EPE ${formatNumber(r.best_val_epe)} px`);
  return parts.join(" · ");
}

// "6 samples · sgbm EPE 2.5 px, predictions EPE 1.25 px" (each method's EPE on all pixels).
function evaluateSummary(r) {
  const methods = Object.entries(r.headline ?? {}).map(([m, regions]) => `${m} EPE ${formatNumber(regions.all?.epe)} px`);
  const failed = r.failed ? ` (${r.failed} failed)` : "";
  return [`${plural(r.samples ?? 0, "sample")}${failed}`, methods.join(", ")].filter(Boolean).join(" · ");
}

// Links to what the job worked on or made. Runs and evaluations are curators' pages: others get
// their names without a link.
export function madeLinks(job, { canReview }) {
  const p = job.params ?? {};
  const r = job.result ?? {};
  const links = [];
  const link = (href, text) => (canReview ? el("a", { href }, text) : el("span", {}, text));
  const runId = job.kind === "train" ? (r.run ?? p.run_id) : p.run;
  if (runId != null) links.push(link(`/models/runs/${runId}`, `run ${runId}`));
  const evaluationId = r.evaluation ?? p.evaluation;
  if (evaluationId != null) links.push(link(`/evaluations/${evaluationId}`, `evaluation #${evaluationId}`));
  const videoId = r.video_id ?? p.video_id;
  if (videoId != null) {
    // Named as the other pages name it when the job knows the name (ingest does).
    const label = r.video_name ?? `video #${videoId}`;
    links.push(el("a", { href: `${canReview ? "/review" : "/frames"}?video_id=${videoId}` }, label));
  }
  if (p.frame_id != null) links.push(el("a", { href: `/annotate/${p.frame_id}` }, `frame #${p.frame_id}`));
  for (const id of Array.isArray(r.frames) ? r.frames : []) links.push(el("a", { href: `/annotate/${id}` }, `frame #${id}`));
  for (const id of [r.sample_id, ...(r.sample_ids ?? [])].filter((v) => v != null)) {
    links.push(el("a", { href: `/samples/${id}` }, `sample #${id}`));
  }
  return links;
}

export function joined(nodes) {
  return nodes.flatMap((n, i) => (i ? [", ", n] : [n]));
}
