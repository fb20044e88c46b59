// The jobs table, refreshed every two seconds: each job links to its own page; failed ones can be retried.
import { api, el, poll } from "./api.js";
import { joined, madeLinks, summary } from "./job_summary.js";

const table = document.getElementById("jobs");
const canRetry = table.dataset.canRetry === "true";
const canReview = table.dataset.canReview === "true";

function row(job) {
  const retry = canRetry && (job.state === "failed" || job.state === "interrupted")
    ? el("button", { type: "button", className: "ghost small", onclick: () => api(`${table.dataset.src}/${job.id}/retry`, { method: "POST" }).then(refresh) }, "Retry")
    : "";
  const failed = job.state === "failed" || job.state === "interrupted";
  return el("tr", { dataset: { jobId: job.id, state: job.state } },
    el("td", {}, el("a", { href: `${table.dataset.page}${job.id}` }, `#${job.id}`)), el("td", {}, job.kind),
    el("td", { className: "state-cell" }, el("span", { className: `state ${job.state}` }, job.state), " ", retry),
    el("td", {}, el("progress", { max: 1, value: job.progress }), ` ${Math.round(job.progress * 100)}%`),
    el("td", {}, job.created_by ?? "—"), el("td", {}, job.created_at.replace("T", " ").slice(0, 16)),
    el("td", { className: failed ? "outcome error" : "outcome" }, summary(job)),
    el("td", { className: "made" }, ...joined(madeLinks(job, { canReview }))));
}

async function refresh() {
  const { items } = await api(table.dataset.src);
  table.tBodies[0].replaceChildren(...(items.length ? items.map(row) : [el("tr", {}, el("td", { colSpan: 8 }, "No jobs yet."))]));
}

poll(refresh, 2000);
