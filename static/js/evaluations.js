// The evaluations list (refreshed every two seconds) and the launch form, which posts to the API.
import { api, el, poll } from "./api.js";
import { sessionEnded } from "./session_ended.js";

const root = document.getElementById("evaluations");
const table = document.getElementById("evaluation-list");
const form = document.getElementById("launch-evaluation");

const fixed = (v) => (typeof v === "number" ? v.toFixed(2) : "—");

function headline(evaluation) {
  const first = evaluation.methods[0];
  return fixed(evaluation.summary?.headline?.[first]?.all?.epe);
}

function row(e) {
  const link = el("a", { href: `${root.dataset.page}/${e.id}` }, `#${e.id}`);
  const samples = e.has_results
    ? el("a", { href: `${root.dataset.samples}?evaluation=${e.id}&sort=error` }, "samples by error") : "";
  return el("tr", { dataset: { evaluationId: e.id, state: e.state } },
    el("td", {}, link), el("td", {}, el("span", { className: `state ${e.state}`, title: e.error ?? "" }, e.state)),
    el("td", {}, el("progress", { max: 1, value: e.progress ?? 0 })),
    el("td", {}, el("code", {}, e.format), ` ${e.dataset}`), el("td", {}, e.methods.join(", ")),
    el("td", {}, e.resolution ?? ""), el("td", { className: "num" }, String(e.summary?.samples ?? "—")),
    el("td", { className: "num" }, headline(e)), el("td", {}, e.created_by ?? "—"), el("td", {}, samples));
}

async function refresh() {
  const { items } = await api(root.dataset.src);
  table.tBodies[0].replaceChildren(...(items.length ? items.map(row)
    : [el("tr", {}, el("td", { colSpan: 10 }, "No evaluations yet."))]));
}

function launchBody() {
  const f = form.elements;
  const body = {};
  for (const name of ["run", "data", "format", "resolution", "checkpoint", "predictions", "align"]) {
    body[name] = f[name].value.trim() || null;
  }
  body.methods = [...form.querySelectorAll("input[name=methods]:checked")].map((i) => i.value);
  return body;
}

const error = document.getElementById("launch-error");
form.addEventListener("submit", async (event) => {
  event.preventDefault();
  error.hidden = true;
  try {
    const evaluation = await api(form.dataset.src, { method: "POST", body: launchBody() });
    location.href = `${root.dataset.page}/${evaluation.id}`;
  } catch (err) {
    error.textContent = err.message;
    error.hidden = sessionEnded(err);
  }
});

poll(refresh, 2000);
