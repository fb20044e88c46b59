// The runs table (refreshed every two seconds, rows pickable for comparison) and the admins'
// launch form, which posts to the API and opens the new run's page.
import { api, el, poll } from "./api.js";
import { duration, fixed, runUrl } from "./runs.js";
import { sessionEnded } from "./session_ended.js";

const root = document.getElementById("models");
const table = document.getElementById("runs");
const compare = document.getElementById("compare");
const form = document.getElementById("launch");
const picked = new Set();

function row(run) {
  const pick = el("input", { type: "checkbox", checked: picked.has(run.run), ariaLabel: `compare run ${run.run}`,
                             onchange: (e) => { e.target.checked ? picked.add(run.run) : picked.delete(run.run); sync(); } });
  const link = el("a", { href: runUrl(root.dataset.runPage, run.run) }, `#${run.run}`);
  const state = el("span", { className: `state ${run.state}` }, run.state);
  return el("tr", { dataset: { runId: run.run, state: run.state } },
    el("td", {}, pick), el("td", {}, link, run.current ? el("span", { className: "badge current" }, " current") : ""),
    el("td", {}, state),
    el("td", {}, el("progress", { max: 1, value: run.progress }), ` ${run.step}/${run.steps}`),
    el("td", {}, run.preset), el("td", {}, el("code", { title: run.dataset.id }, run.dataset.id.slice(0, 12))),
    el("td", { className: "num" }, String(run.dataset.samples)),
    el("td", { className: "num" }, fixed(run.best_val_epe)),
    el("td", { className: "num" }, duration(run.duration_s)), el("td", {}, run.created_by ?? "—"));
}

function sync() {
  compare.disabled = picked.size < 2;
}

async function refresh() {
  const { items, current } = await api(root.dataset.src);
  table.tBodies[0].replaceChildren(...(items.length ? items.map(row)
    : [el("tr", {}, el("td", { colSpan: 10 }, "No runs yet."))]));
  document.getElementById("current-model").textContent = current
    ? `Current model: run ${current.run}, step ${current.step} (${current.checkpoint})`
    : "Current model: none promoted yet.";
}

compare.addEventListener("click", () => {
  location.href = `${root.dataset.compare}?ids=${[...picked].sort((a, b) => a - b).join(",")}`;
});

function launchBody() {
  const f = form.elements;
  const body = {};
  for (const name of ["preset", "crop", "devices", "split", "init_checkpoint"]) body[name] = f[name].value.trim();
  for (const name of ["steps", "batch", "iters", "nproc", "seed"]) body[name] = f[name].value ? Number(f[name].value) : null;
  body.lr = f.lr.value ? Number(f.lr.value) : null;
  body.video_ids = [...f.video_ids.selectedOptions].map((o) => Number(o.value));
  body.illusion_types = [...form.querySelectorAll("input[name=illusion_types]:checked")].map((i) => i.value);
  body.kinds = [...form.querySelectorAll("input[name=kinds]:checked")].map((i) => i.value);
  body.qa_ok = f.qa_ok.checked;
  return body;
}

if (form) {
  const error = document.getElementById("launch-error");
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    error.hidden = true;
    const button = form.querySelector("button[type=submit]");
    button.disabled = true;
    try {
      const run = await api(form.dataset.src, { method: "POST", body: launchBody() });
      location.href = runUrl(root.dataset.runPage, run.run);
    } catch (err) {
      error.textContent = err.message;
      error.hidden = sessionEnded(err);
      button.disabled = false;
    }
  });
}

poll(refresh, 2000);
