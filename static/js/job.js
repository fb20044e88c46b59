// One job's page: state and progress, what it made, its parameters, timings and log, live until it ends.
import { api, el, poll } from "./api.js";
import { keyboardHelp } from "./help.js";
import { ENDED, FAILED, joined, madeLinks, summary } from "./job_summary.js";
import { isShortcut } from "./keys.js";
import { formatNumber } from "./labels.js";
import { sessionEnded } from "./session_ended.js";

const root = document.getElementById("job");
const $ = (id) => document.getElementById(id);
const canReview = root.dataset.canReview === "true";
// A COCO RLE is no reading for a person; an evaluation's pictures are on its report.
const HIDDEN_PARAMS = new Set(["mask", "pictures"]);

const when = (iso) => (iso ? iso.replace("T", " ").slice(0, 19) : "—");
// The time every attempt ran (`took_s`), once the job has ended; "over 2 attempts" when it was retried.
function took(job) {
  const s = job.took_s;
  if (s == null) return "—";
  const text = s < 60 ? `${s.toFixed(1)} s` : `${Math.floor(s / 60)} min ${Math.round(s % 60)} s`;
  return job.attempts > 1 ? `${text} over ${job.attempts} attempts` : text;
}
// Server folders are no business of the page: a path shows as its file name. Numbers read as
// everywhere else (labels.js); lists and objects as short text, their numbers alike.
function readable(value, nested = false) {
  if (value == null) return "—";
  if (typeof value === "number") return formatNumber(value);
  if (typeof value === "string") return value.startsWith("/") ? value.split("/").pop() : value;
  if (Array.isArray(value)) return `${nested ? "[" : ""}${value.map((v) => readable(v, true)).join(", ")}${nested ? "]" : ""}`;
  const inner = Object.entries(value).map(([k, v]) => `${k}: ${readable(v, true)}`).join(", ");
  return nested ? `{${inner}}` : inner;
}

function pairs(object) {
  return Object.entries(object ?? {}).filter(([k]) => !HIDDEN_PARAMS.has(k))
    .flatMap(([k, v]) => [el("dt", {}, k.replaceAll("_", " ")), el("dd", { dataset: { key: k } }, readable(v))]);
}

const stop = poll(async () => {
  let job;
  try {
    job = await api(root.dataset.src);
  } catch (err) {
    if (!sessionEnded(err)) {
      $("job-summary").textContent = err.message;  // e.g. "no job 7" (or one this user may not see)
      $("job-summary").classList.add("error");
    }
    throw err;
  }
  $("job-kind").textContent = `· ${job.kind}`;
  $("job-state").textContent = job.state;
  $("job-state").className = `state ${job.state}`;
  $("job-progress").value = job.progress;
  $("job-summary").textContent = summary(job);
  $("job-summary").classList.toggle("error", FAILED.includes(job.state));
  $("job-made").replaceChildren(...joined(madeLinks(job, { canReview })));
  $("job-made-row").hidden = !$("job-made").childNodes.length;
  $("job-params").replaceChildren(...pairs(job.params));
  $("job-result").replaceChildren(...pairs(job.result));
  $("job-times").replaceChildren(
    el("dt", {}, "created"), el("dd", {}, `${when(job.created_at)} by ${job.created_by ?? "the system"}`),
    el("dt", {}, "started"), el("dd", {}, when(job.started_at)),
    el("dt", {}, "finished"), el("dd", {}, when(job.finished_at)),
    el("dt", {}, "took"), el("dd", {}, took(job)),
    el("dt", {}, "attempts"), el("dd", {}, String(job.attempts)));
  $("job-log").textContent = job.log || "(nothing logged yet)";
  if (ENDED.includes(job.state)) stop();
}, 1500);

const KEYS = {
  m: () => $("job-made").querySelector("a")?.click(),
  l: () => { $("job-log").scrollIntoView({ block: "center" }); $("job-log").focus(); },
  u: () => location.assign(root.dataset.list),
};
document.addEventListener("keydown", (event) => {
  const run = KEYS[event.key];
  if (!run || !isShortcut(event)) return;
  event.preventDefault();
  run();
});
keyboardHelp([
  ["`m`", "open the first thing the job made or worked on (a run, an evaluation, a video, a sample…)"],
  ["`l`", "to the log"],
  ["`u`", "up to all jobs"],
], { note: "The page updates by itself until the job ends. A training job's log holds every attempt; "
          + "its run's page has rank 0's log on its own, to download." });
