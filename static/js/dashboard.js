// Keeps the funnel counts and the proposers' figures live as frames move through the pipeline; `?`
// says what each count and column means.
import { api, el, poll } from "./api.js";
import { keyboardHelp } from "./help.js";

const funnel = document.getElementById("funnel");
const proposers = document.getElementById("proposers");
const COLUMNS = ["threshold", "frames", "proposals", "accepted", "edited", "rejected", "hidden", "acceptance_rate",
                 "median_iou", "misses", "ms_per_frame"];

poll(async () => {
  const counts = await api(funnel.dataset.src);
  const top = counts.frames || 1;
  for (const item of funnel.querySelectorAll("li[data-stage]")) {
    const stage = item.dataset.stage;
    item.querySelector(".count").textContent = counts[stage];
    item.querySelector(".bar")?.style.setProperty("--w", `${(100 * counts[stage] / top).toFixed(1)}%`);
  }
}, 5000);

// A figure as the table shows it: a rate in percent, an IoU to two places, "—" where there is none yet.
function figure(column, value) {
  if (value == null) return "—";
  if (column === "acceptance_rate") return `${Math.round(100 * value)} %`;
  if (["median_iou", "threshold"].includes(column)) return value.toFixed(2);
  return column === "ms_per_frame" ? `${value.toLocaleString()} ms` : value.toLocaleString();
}

// A row per proposer and threshold in force: a threshold changes what annotators see, so their figures
// are not to be mixed.
poll(async () => {
  const stats = Object.entries((await api(proposers.dataset.src)).proposers)
    .flatMap(([name, s]) => s.by_threshold.map((t) => [name, t])).filter(([, s]) => s.proposals || s.frames);
  const rows = stats.map(([name, s]) => el("tr", { dataset: { proposer: name, threshold: s.threshold } },
    el("th", { scope: "row" }, name), ...COLUMNS.map((c) => el("td", { dataset: { column: c } }, figure(c, s[c])))));
  const empty = el("tr", { className: "empty" }, el("td", { colSpan: COLUMNS.length + 1, className: "muted" }, "No proposals yet"));
  proposers.tBodies[0].replaceChildren(...(rows.length ? rows : [empty]));
}, 5000);

// No keys of its own: the help reads the counts and the columns (each one's title says it too, on hover).
keyboardHelp([
  "Funnel",
  ...[...funnel.querySelectorAll("li[data-stage]")].map((item) => [item.dataset.stage, item.title]),
  "Proposers",
  ...[...proposers.tHead.rows[0].cells].map((th) => [th.textContent, th.title]),
], { note: "The figures follow the pipeline live (every 5 s). A frame counts at every stage it has reached, "
          + "so each bar is at most the one above it." });

// Failed generate jobs, retried once their cause is fixed: the server queues those whose frames can become
// samples now and names the reason the others still cannot.
const retry = document.getElementById("retry-generates");
retry?.addEventListener("click", async () => {
  retry.disabled = true;
  const out = document.getElementById("retry-generates-result");
  try {
    const result = await api(retry.dataset.src, { method: "POST" });
    const still = result.still_blocked.map((b) => `${b.frame_ids.length} still cannot: ${b.reason}`);
    out.textContent = ` Queued ${result.retried.length} again.${still.length ? ` ${still.join(" ")}` : ""}`;
  } catch (err) {
    out.textContent = ` ${err.message}`;
  } finally {
    retry.disabled = false;
  }
});
