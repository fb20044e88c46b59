// The Export page: each export whose job is queued or running follows it through the jobs API (as a
// job's own page does) until it ends; then its row shows what it made and offers the zip.
import { api, poll } from "./api.js";
import { keyboardHelp } from "./help.js";
import { summary } from "./job_summary.js";

const LIVE = new Set(["queued", "running"]);
const ENDED_BADLY = new Set(["failed", "interrupted"]);

function follow(row) {
  const part = (name) => row.querySelector(`[data-part="${name}"]`);
  const stop = poll(async () => {
    const job = await api(row.dataset.src);
    row.dataset.state = job.state;
    part("state").textContent = job.state;
    part("state").className = `state ${job.state}`;
    part("progress").value = job.progress;
    part("progress").hidden = !LIVE.has(job.state);
    part("summary").textContent = LIVE.has(job.state) ? `${Math.round(job.progress * 100)} %` : summary(job);
    part("summary").className = ENDED_BADLY.has(job.state) ? "error" : "muted";
    row.querySelector(".download").hidden = job.state !== "succeeded";
    row.querySelector("button[type=submit]").disabled = LIVE.has(job.state);
    if (!LIVE.has(job.state)) stop();
  }, 1500);
}

for (const row of document.querySelectorAll("#exports tr[data-src]")) {
  if (LIVE.has(row.dataset.state)) follow(row);
}

for (const form of document.querySelectorAll("form[data-confirm]")) {
  form.addEventListener("submit", (event) => {
    if (!window.confirm(form.dataset.confirm)) event.preventDefault();
  });
}

keyboardHelp([], {
  note: "Choose the format and the samples (states, videos; none selected: all) and Export: a refused option " +
    "says why under its field. The list follows each export's job; Download zip streams the finished folder as " +
    "one zip (its manifest.json at the top), named by the export's number. Delete removes its files; exports " +
    "also go by themselves after the retention the page names. The command line's `illusion-studio export` " +
    "writes the same layouts into a folder of your choice.",
});
