// One run, live: its figures every two seconds, the curve points it has not shown yet
// (GET …/metrics?after=<last step>), so the charts grow without a reload, and the tail of rank 0's log.
import { api, el, poll } from "./api.js";
import { lineChart } from "./chart.js";
import { keyboardHelp } from "./help.js";
import { isShortcut } from "./keys.js";
import { plural } from "./labels.js";
import { LIVE, duration, fixed, short } from "./runs.js";
import { sessionEnded } from "./session_ended.js";

const root = document.getElementById("run");
const $ = (id) => document.getElementById(id);
const charts = $("charts");
const curves = { loss: [], lr: [], epe: [] };
const plots = {
  loss: lineChart(charts, { title: "training loss" }),
  epe: lineChart(charts, { title: "validation EPE", yLabel: "px" }),
  lr: lineChart(charts, { title: "learning rate" }),
};
let lastStep = -1;
let lastValStep = -1;
let lastVal = null;
let finished = false;

function addPoints({ step, val }) {
  for (const p of step) {
    if (p.loss != null) curves.loss.push([p.step, p.loss]);
    if (p.lr != null) curves.lr.push([p.step, p.lr]);
    lastStep = Math.max(lastStep, p.step);
  }
  for (const p of val) {
    const epe = p.metrics?.all?.epe;
    if (epe != null) curves.epe.push([p.step, epe]);
    lastValStep = Math.max(lastValStep, p.step);
  }
  if (step.length || val.length) {
    for (const key of Object.keys(curves)) {
      // A resumed run repeats steps after its checkpoint: keep the newest point per step.
      const byStep = new Map(curves[key].map(([x, y]) => [x, y]));
      curves[key] = [...byStep.entries()].sort((a, b) => a[0] - b[0]);
    }
    plots.loss.update([{ name: "loss", points: curves.loss }]);
    plots.epe.update([{ name: "val EPE", points: curves.epe }]);
    plots.lr.update([{ name: "lr", points: curves.lr }]);
  }
}

function showValidation(val) {
  if (!val || (lastVal && lastVal.step === val.step)) return;
  lastVal = val;
  $("val-caption").textContent = `Validation at step ${val.step}: left · ground truth · prediction · confidence · error.`;
  const body = $("val-metrics").tBodies[0];
  body.replaceChildren(...Object.entries(val.metrics).map(([region, m]) =>
    el("tr", { dataset: { region } }, el("th", {}, region.replace("_", "-")), el("td", {}, fixed(m.epe)),
       el("td", {}, fixed(m.bad2, 2)), el("td", {}, fixed(m.bad3, 2)))));
  $("val-metrics").hidden = false;
  $("val-images").replaceChildren(...val.images.map((path) => el("li", {},
    el("figure", {}, el("img", { src: root.dataset.files + path, alt: `validation ${path}`, loading: "lazy" }),
       el("figcaption", {}, path)))));
}

function showCheckpoints(files) {
  $("checkpoints").tBodies[0].replaceChildren(...(files.length ? files.map((f) => el("tr", {},
    el("td", {}, el("a", { href: root.dataset.checkpoints + f.name, download: "" }, f.name)),
    el("td", {}, f.step == null ? "best" : String(f.step)),
    el("td", {}, `${(f.bytes / 2 ** 20).toFixed(1)} MiB`))) : [el("tr", {}, el("td", { colSpan: 3 }, "None yet."))]));
}

// An init_stereo start: how many tensors came from the file and which started fresh (once the engine has said).
function showInit(init) {
  if (!init || init.loaded == null || !$("run-init") || !$("init-details").hidden) return;
  $("init-counts").textContent = `: ${init.loaded} tensors from the file, ${init.fresh} started fresh, ` +
    `${init.unused} of the file's without a place here.`;
  for (const part of ["loaded", "fresh", "unused"]) {
    $(`init-${part}`).replaceChildren(...init[`${part}_keys`].map((key) => el("li", {}, el("code", {}, key))));
  }
  $("init-details").hidden = false;
}

function showRun(run) {
  $("run-state").textContent = run.state;
  $("run-state").className = `state ${run.state}`;
  $("run-current").hidden = !run.current;
  $("run-progress").value = run.progress;
  $("fig-step").textContent = `${run.step}/${run.steps}`;
  $("fig-loss").textContent = short(run.loss);
  $("fig-lr").textContent = short(run.lr);
  $("fig-sps").textContent = fixed(run.samples_per_s, 2);
  $("fig-eta").textContent = LIVE.has(run.state) ? duration(run.eta_s) : "—";
  $("fig-epe").textContent = fixed(run.best_val_epe);
  $("fig-duration").textContent = duration(run.duration_s);
  $("fig-resumed").textContent = run.resumed_from_step ?? "—";
  $("run-reason").textContent = run.reason ?? "";
  $("run-reason").hidden = !run.reason;
  root.dataset.state = run.state;
  if (root.dataset.canAdmin === "true") {
    $("run-cancel").disabled = !LIVE.has(run.state);
    $("run-resume").disabled = !["interrupted", "failed", "cancelled"].includes(run.state);
    $("run-promote").disabled = !run.checkpoints.length;
  }
  showValidation(run.last_val);
  showCheckpoints(run.checkpoints);
  showInit(run.init);
}

const LOG_LINES = 400;

// The log's tail; the view stays at the newest line while "follow" is ticked.
async function refreshLog() {
  const log = await api(`${root.dataset.log}?lines=${LOG_LINES}`);
  const pre = $("run-log");
  const text = log.lines.join("\n");
  if (pre.textContent !== text) pre.textContent = text;
  if ($("log-follow").checked) pre.scrollTop = pre.scrollHeight;
  $("log-download").hidden = !log.files.length;
  $("log-follow").closest("label").hidden = !log.files.length;
  pre.hidden = !log.files.length;
  $("log-caption").textContent = !log.files.length
    ? (LIVE.has(root.dataset.state) ? "No log yet: the trainers have not started." : "No log: the trainers never started (see the job's log).")
    : `${log.more ? `The last ${plural(log.lines.length, "line")}` : "All"} of ${plural(log.files.length, "file")}`
      + ` (${(log.bytes / 1024).toFixed(1)} KiB)${LIVE.has(root.dataset.state) ? ", live" : ""}.`;
}

const metricsUrl = () => `${root.dataset.metrics}?after=${lastStep}&after_val=${lastValStep}`;

async function refresh() {
  if (finished) return;
  const [run, points] = await Promise.all([api(root.dataset.src), api(metricsUrl())]);
  addPoints(points);
  showRun(run);
  if (!LIVE.has(run.state)) {
    // One more round for the last points and lines, then the page stops asking.
    addPoints(await api(metricsUrl()));
    finished = true;
  }
  await refreshLog();
}

function control(id, path, body) {
  $(id)?.addEventListener("click", async () => {
    const status = $("control-status");
    status.textContent = "…";
    try {
      await api(`${root.dataset.src}/${path}`, { method: "POST", body: body?.() });
      status.textContent = `${path}: done`;
      finished = false;
      await refresh();
    } catch (err) {
      status.textContent = sessionEnded(err) ? "" : err.message;
    }
  });
}

control("run-cancel", "cancel");
control("run-resume", "resume");
control("run-promote", "promote", () => ({ checkpoint: $("promote-which").value }));
function toLog() {
  $("run-log").scrollIntoView({ block: "center" });
  $("run-log").focus();
}

const KEYS = {
  l: toLog,
  f: () => { $("log-follow").click(); },
  j: () => { if ($("run-job")) location.assign($("run-job").href); },
};
document.addEventListener("keydown", (event) => {
  const run = KEYS[event.key];
  if (!run || !isShortcut(event)) return;
  event.preventDefault();
  run();
});
$("log-follow").addEventListener("change", () => {
  if ($("log-follow").checked) $("run-log").scrollTop = $("run-log").scrollHeight;
});

keyboardHelp([
  ["`l`", "to rank 0's log"],
  ["`f`", "follow the log (stay at its newest line) on or off"],
  ["`j`", "the run's job: its parameters, timings and the log of every attempt"],
], { note: "The page updates by itself while the run is queued or running. The log is rank 0's output, "
          + "its files named relative to the workspace; Download has the whole of it. "
          + "Click a checkpoint to download it; Mark as current model (admins) makes the chosen one the model "
          + "predict and evaluate use." });
for (const plot of Object.values(plots)) plot.update([]);
poll(refresh, 2000);
