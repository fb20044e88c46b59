// The jobs table, refreshed every two seconds, with a retry button for failed jobs.
import { api, el, poll } from "./api.js";

const table = document.getElementById("jobs");
const canRetry = table.dataset.canRetry === "true";

function row(job) {
  const retry = canRetry && (job.state === "failed" || job.state === "interrupted")
    ? el("button", { type: "button", onclick: () => api(`${table.dataset.src}/${job.id}/retry`, { method: "POST" }).then(refresh) }, "Retry")
    : "";
  return el("tr", { dataset: { jobId: job.id, state: job.state } },
    el("td", {}, String(job.id)), el("td", {}, job.kind),
    el("td", {}, el("span", { className: `state ${job.state}` }, job.state)),
    el("td", {}, el("progress", { max: 1, value: job.progress }), ` ${Math.round(job.progress * 100)}%`),
    el("td", {}, job.created_by ?? "—"), el("td", {}, job.created_at.replace("T", " ").slice(0, 19)),
    el("td", { className: "error" }, job.error ?? ""), el("td", {}, retry));
}

async function refresh() {
  const { items } = await api(table.dataset.src);
  table.tBodies[0].replaceChildren(...(items.length ? items.map(row) : [el("tr", {}, el("td", { colSpan: 8 }, "No jobs yet."))]));
}

poll(refresh, 2000);
