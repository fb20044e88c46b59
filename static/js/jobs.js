// The jobs table, a page of it refreshed every two seconds: each job links to its own page; failed
// ones can be retried. The state filter and the page are kept in the address.
import { api, el, poll } from "./api.js";
import { keyboardHelp } from "./help.js";
import { FAILED, RETRYABLE, joined, madeLinks, summary } from "./job_summary.js";
import { pagedList } from "./pager.js";
import { sayFailure } from "./session_ended.js";

const table = document.getElementById("jobs");
const filters = document.getElementById("job-filters");
const status = document.getElementById("jobs-status");
const canRetry = table.dataset.canRetry === "true";
const canReview = table.dataset.canReview === "true";

function row(job) {
  const retry = canRetry && RETRYABLE.includes(job.state)
    ? el("button", { type: "button", className: "ghost small", onclick: () => retryJob(job) }, "Retry")
    : "";
  const failed = FAILED.includes(job.state);
  return el("tr", { dataset: { jobId: job.id, state: job.state } },
    el("td", {}, el("a", { href: `${table.dataset.page}${job.id}` }, `#${job.id}`)), el("td", {}, job.kind),
    el("td", { className: "state-cell" }, el("span", { className: `state ${job.state}` }, job.state), " ", retry),
    el("td", {}, el("progress", { max: 1, value: job.progress }), ` ${Math.round(job.progress * 100)}%`),
    el("td", {}, job.created_by ?? "—"), el("td", {}, job.created_at.replace("T", " ").slice(0, 16)),
    el("td", { className: failed ? "outcome error" : "outcome" }, summary(job)),
    el("td", { className: "made" }, ...joined(madeLinks(job, { canReview }))));
}

function draw({ items }) {
  const none = filters.elements.state.value ? `No ${filters.elements.state.value} jobs here.` : "No jobs yet.";
  table.tBodies[0].replaceChildren(...(items.length ? items.map(row) : [el("tr", {}, el("td", { colSpan: 8 }, none))]));
}

const { load, refresh } = pagedList({ src: table.dataset.src, form: filters, size: 50, draw,
                                      range: document.getElementById("jobs-range"), status });

// The answer stays on the status line until the next retry: the table's refreshes leave it there.
async function retryJob(job) {
  status.textContent = "";
  try {
    await api(`${table.dataset.src}/${job.id}/retry`, { method: "POST" });
  } catch (err) {
    sayFailure((text) => { status.textContent = `Job #${job.id} was not retried: ${text}`; })(err);
    return;
  }
  refresh();
}

keyboardHelp([["`]` or `n`", "next page (older jobs)"], ["`[` or `p`", "previous page (newer jobs)"]],
             { note: "The state filter and the page are in the address: a reload or a shared link shows the same jobs." });
poll(load, 2000);
