// The runs table (refreshed every two seconds, rows pickable for comparison) and the admins'
// launch form, which posts to the API and opens the new run's page.
import { api, el, poll } from "./api.js";
import { duration, fixed, runUrl } from "./runs.js";
import { keyboardHelp } from "./help.js";
import { launch, numberOrNull } from "./launch_form.js";

const root = document.getElementById("models");
const table = document.getElementById("runs");
const compare = document.getElementById("compare");
const form = document.getElementById("launch");
const estimate = document.getElementById("launch-estimate");
const picked = new Set();

function row(run) {
  const pick = el("input", { type: "checkbox", checked: picked.has(run.run), ariaLabel: `compare run ${run.run}`,
                             onchange: (e) => { e.target.checked ? picked.add(run.run) : picked.delete(run.run); sync(); } });
  const link = el("a", { href: runUrl(root.dataset.runPage, run.run) }, `#${run.run}`);
  const state = el("span", { className: `state ${run.state}` }, run.state);
  return el("tr", { dataset: { runId: run.run, state: run.state } },
    el("td", {}, pick), el("td", {}, link, ...(run.current ? [" ", el("span", { className: "badge current" }, "current")] : [])),
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
    ? `Current model: run ${current.run}, ${current.best ? "best checkpoint" : current.file}` +
      (current.step == null ? "" : ` (step ${current.step})`)
    : "Current model: none promoted yet.";
}

compare.addEventListener("click", () => {
  location.href = `${root.dataset.compare}?ids=${[...picked].sort((a, b) => a - b).join(",")}`;
});

function launchBody() {
  const f = form.elements;
  const body = { preset: f.preset.value, devices: f.devices.value, split: f.split.value.trim() };
  // An empty field is left out: the launch takes the preset's (or the schema's) value.
  for (const name of ["steps", "batch", "lr", "iters", "nproc", "seed"]) {
    const value = numberOrNull(f[name]);
    if (value !== null) body[name] = value;
  }
  if (f.crop.value.trim()) body.crop = f.crop.value.trim();
  // Checkpoints by name, as `predict --checkpoint` takes them: RUN:NAME or imported:NAME.
  if (f.init.value) body.init = f.init.value;
  if (f.init_stereo.value) body.init_stereo = f.init_stereo.value;
  if (f.source.value === "folder") {
    body.data = { root: f.data_root.value, path: f.data_path.value.trim(), format: f.data_format.value };
    return body;
  }
  body.video_ids = [...f.video_ids.selectedOptions].map((o) => Number(o.value));
  body.illusion_types = [...form.querySelectorAll("input[name=illusion_types]:checked")].map((i) => i.value);
  body.kinds = [...form.querySelectorAll("input[name=kinds]:checked")].map((i) => i.value);
  body.qa_ok = f.qa_ok.checked;
  return body;
}

// {preset: {steps, batch, lr, crop, iters}} where the page is given them, else {}.
const presets = form?.dataset.presets ? JSON.parse(form.dataset.presets) : {};
const PRESET_FIELDS = ["steps", "batch", "lr", "crop", "iters"];

// Each empty field's placeholder names the value the launch will take: the chosen preset's.
function showPresetValues() {
  const name = form.elements.preset.value;
  for (const field of PRESET_FIELDS) {
    const value = presets[name]?.[field];
    const says = value == null ? "preset's" : `${value} (${name}'s)`;
    form.elements[field].placeholder = field === "crop" ? `${says}; ${form.dataset.fits} fits the accepted samples` : says;
  }
}

// The estimate from the API (the nearest finished run of the preset, scaled to this batch, crop and
// iterations); a field it refuses is marked under that field, as a launch would be.
let asked = 0;
async function showEstimate() {
  const ask = ++asked;
  const note = (field) => form.querySelector(`[data-error-for="${CSS.escape(field)}"]`);
  for (const field of ESTIMATE_FIELDS) {
    const n = note(field);
    if (n?.dataset.fromEstimate) { n.hidden = true; delete n.dataset.fromEstimate; }
  }
  let text;
  try {
    text = (await api(form.dataset.estimate, { method: "POST", body: estimateBody() })).text;
  } catch (err) {
    if (ask !== asked) return;
    const field = err.field?.split(".")[0];
    const n = field ? note(field) : null;
    if (n) {
      n.textContent = err.reason ?? err.message;
      n.hidden = false;
      n.dataset.fromEstimate = "1";
    }
    text = field ? `unknown until ${field} is corrected` : `unknown (${err.message})`;
  }
  if (ask === asked) estimate.textContent = `Estimated length: ${text}.`;
}

// What a step's time depends on, as the launch would send it.
const ESTIMATE_FIELDS = ["preset", "steps", "batch", "crop", "iters"];
function estimateBody() {
  const f = form.elements;
  const body = { preset: f.preset.value };
  for (const name of ["steps", "batch", "iters"]) {
    const value = numberOrNull(f[name]);
    if (value !== null) body[name] = value;
  }
  if (f.crop.value.trim()) body.crop = f.crop.value.trim();
  return body;
}

if (form) {
  // The data source shows the fields of the chosen one: the database's filters or a registered folder.
  const showSource = () => {
    for (const part of form.querySelectorAll("[data-source]")) part.hidden = part.dataset.source !== form.elements.source.value;
  };
  for (const radio of form.elements.source) radio.addEventListener("change", showSource);
  form.elements.preset.addEventListener("change", showPresetValues);
  for (const name of ESTIMATE_FIELDS) {
    form.elements[name].addEventListener("input", () => showEstimate().catch(console.warn));
  }
  showPresetValues();
  showEstimate().catch(console.warn);
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    const run = await launch(form, launchBody());
    if (run) location.href = runUrl(root.dataset.runPage, run.run);
  });
}

keyboardHelp([], {
  note: "Tick two or more runs to compare their curves. Launch fields left empty take the preset's values; a " +
    "refused launch names its field under it (a crop must fit the smallest image of the data and the machine's " +
    "memory; text that is not a number is refused too). The estimate above Launch is the steps times the median " +
    "step time of the finished run of the same preset nearest in batch, crop and iterations, scaled by " +
    "batch × pixels × iterations. Batch, crop and iterations start at the newest finished run's. Start from a " +
    "run's best or last checkpoint to fine-tune; an imported checkpoint says which presets it fits.",
});

poll(refresh, 2000);
