// The evaluations list (refreshed every two seconds) and the launch form, which posts to the API.
import { api, el, poll } from "./api.js";
import { keyboardHelp } from "./help.js";
import { launch } from "./launch_form.js";
import { fixed } from "./runs.js";

const root = document.getElementById("evaluations");
const table = document.getElementById("evaluation-list");
const form = document.getElementById("launch-evaluation");


function headline(evaluation) {
  const first = evaluation.methods[0];
  return fixed(evaluation.summary?.headline?.[first]?.all?.epe, 2);
}

function row(e) {
  const link = el("a", { href: `${root.dataset.page}/${e.id}` }, `#${e.id}`);
  const samples = e.has_results
    ? el("a", { href: `${root.dataset.samples}?evaluation=${e.id}&sort=error` }, "samples by error") : "";
  return el("tr", { dataset: { evaluationId: e.id, state: e.state } },
    el("td", {}, link), el("td", {}, el("span", { className: `state ${e.state}`, title: e.error ?? "" }, e.state)),
    el("td", {}, el("progress", { max: 1, value: e.progress ?? 0 })),
    el("td", {}, el("code", {}, e.format), ` ${e.dataset}`), el("td", {}, e.methods.join(", ")),
    el("td", {}, e.resolution ?? ""), el("td", {}, e.checkpoint ?? "—"),
    el("td", { className: "num" }, String(e.summary?.samples ?? "—")),
    el("td", { className: "num" }, headline(e)), el("td", {}, e.created_by ?? "—"), el("td", {}, samples));
}

async function refresh() {
  const { items } = await api(root.dataset.src);
  table.tBodies[0].replaceChildren(...(items.length ? items.map(row)
    : [el("tr", {}, el("td", { colSpan: 11 }, "No evaluations yet."))]));
}

function launchBody() {
  const f = form.elements;
  const body = { resolution: f.resolution.value || null, align: f.align.value };
  body.methods = [...form.querySelectorAll("input[name=methods]:checked")].map((i) => i.value);
  if (f.source.value === "folder") {
    body.data = { root: f.data_root.value, path: f.data_path.value.trim(), format: f.data_format.value };
  } else if (f.run.value) {
    body.run = Number(f.run.value);
  }
  // Checkpoints by name, as `predict --checkpoint` takes them; each baseline (raft-stereo,
  // selective-raft, selective-igev) scores its own.
  if (f.checkpoint.value) body.checkpoint = f.checkpoint.value;
  for (const select of form.querySelectorAll("select[data-baseline]")) {
    if (body.methods.includes(select.dataset.baseline) && select.value) {
      body.checkpoints = { ...body.checkpoints, [select.dataset.baseline]: select.value };
    }
  }
  if (body.methods.includes("predictions")) {
    body.predictions = { root: f.predictions_root.value, path: f.predictions_path.value.trim() };
  }
  return body;
}

// The fields of the chosen samples, and the predictions folder only when its method is ticked.
function showParts() {
  for (const part of form.querySelectorAll("[data-source]")) part.hidden = part.dataset.source !== form.elements.source.value;
  for (const part of form.querySelectorAll("[data-needs]")) {
    part.hidden = !form.querySelector(`input[name=methods][value=${part.dataset.needs}]`).checked;
  }
}
form.addEventListener("change", showParts);
showParts();

form.addEventListener("submit", async (event) => {
  event.preventDefault();
  const evaluation = await launch(form, launchBody());
  if (evaluation) location.href = `${root.dataset.page}/${evaluation.id}`;
});

keyboardHelp([], {
  note: "Score methods on a run's held-out test split (samples its training never read) or on a folder inside a " +
    "registered dataset root. fusion, stereo and mono-align use the chosen checkpoint, raft-stereo its own (an imported " +
    "RAFT-Stereo checkpoint, or a raft-stereo run's), selective-raft and selective-igev each its own (an imported " +
    "Selective-RAFT or Selective-IGEV one); best and last are pinned to their step when the evaluation is launched. " +
    "A refused launch names its field under it.",
});

poll(refresh, 2000);
