// What a job did and made, in words and links: shared by the jobs table and a job's own page.
import { el } from "./api.js";
import { plural } from "./labels.js";

// One short line for a finished job's result.
export function summary(job) {
  const r = job.result;
  if (job.state === "failed" || job.state === "interrupted") return job.error ?? job.state;
  if (!r) return "";
  if (r.skipped) {
    return `already in the workspace as video ${r.video_id}${r.video_name ? ` (“${r.video_name}”)` : ""}`
      + ` with ${plural(r.frames, "frame")}: nothing new to ingest`;
  }
  if (job.kind === "ingest") return `${plural(r.frames, "frame")}, ${plural(r.dropped_duplicates ?? 0, "near-duplicate")} dropped`;
  if (job.kind === "prefilter") return `${plural(r.frames, "frame")}: ${r.keep} kept, ${r.reject} dropped, ${r.undecided} to review`;
  if (job.kind === "propagate") return `drafts on ${plural(r.frames.length, "frame")}`;
  if (job.kind === "encode") return `${plural(r.encoded, "embedding")} for ${plural(r.frames, "frame")}`;
  return "";
}

// Links to what the job worked on or made.
export function madeLinks(job, { canReview }) {
  const p = job.params ?? {};
  const r = job.result ?? {};
  const links = [];
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
