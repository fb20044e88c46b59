// Two or more runs: loss and validation EPE of all of them on one chart each, and their last
// validation metrics side by side; refreshed while any of them runs.
import { api, el, poll } from "./api.js";
import { COLORS, lineChart } from "./chart.js";
import { keyboardHelp } from "./help.js";
import { isShortcut } from "./keys.js";
import { plural } from "./labels.js";
import { LIVE, fixed, runUrl } from "./runs.js";

const root = document.getElementById("compare");
const ids = root.dataset.ids ? root.dataset.ids.split(",").map(Number) : [];
const charts = document.getElementById("compare-charts");
const loss = lineChart(charts, { title: "training loss" });
const epe = lineChart(charts, { title: "validation EPE", yLabel: "px" });
const ROWS = [["all", "epe", "EPE all (px)"], ["all", "bad2", "bad-2 all (%)"], ["all", "bad3", "bad-3 all (%)"],
              ["illusion", "epe", "EPE illusion (px)"], ["illusion", "bad2", "bad-2 illusion (%)"],
              ["non_illusion", "epe", "EPE non-illusion (px)"], ["non_illusion", "bad2", "bad-2 non-illusion (%)"]];
let done = false;

const version = (r) => r.dataset.id.slice(0, 12);
// How a run split its dataset version: its seed and fractions decide which videos validate it.
const split = (r) => {
  const fractions = Object.entries(r.launch?.split ?? {}).map(([name, f]) => `${name} ${f}`).join(" / ");
  return `seed ${r.launch?.seed ?? 0}${fractions ? `, ${fractions}` : ""}`;
};

// The runs by `key`: key → "run 1, run 3".
function grouped(runs, key) {
  const groups = new Map();
  for (const r of runs) groups.set(key(r), [...(groups.get(key(r)) ?? []), `run ${r.run}`]);
  return groups;
}

// Runs of different dataset versions, or of one version split with different seeds or fractions, were
// validated on different samples: say so above the figures.
function samplesWarning(runs) {
  const versions = grouped(runs, (r) => r.dataset.id);
  const splits = grouped(runs, split);
  const line = document.getElementById("compare-versions");
  const caution = "so their validation figures are measured on different samples: compare them with care.";
  const list = (groups, label) => [...groups.entries()].map(([key, names]) => `${names.join(", ")}: ${label(key)}`).join("; ");
  if (versions.size > 1) {
    line.textContent = `These runs were trained on ${versions.size} different dataset versions (`
      + `${list(versions, (id) => id.slice(0, 12))}), ${caution}`;
  } else if (splits.size > 1) {
    line.textContent = `These runs share dataset version ${version(runs[0])} but split it differently (`
      + `${list(splits, (key) => key)}): the split follows the seed, ${caution}`;
  }
  line.hidden = versions.size < 2 && splits.size < 2;
}

function table(runs) {
  const head = el("tr", {}, el("th", {}, "Metric"), ...runs.map((r) =>
    el("th", {}, el("a", { href: runUrl(root.dataset.runPage, r.run) }, `run ${r.run}`), ` (${r.preset}, ${r.state})`)));
  const differ = new Set(runs.map((r) => r.dataset.id)).size > 1;
  const rows = [
    el("tr", { className: differ ? "differs" : "" }, el("th", {}, "dataset version"), ...runs.map((r) => el("td", {
      dataset: { run: r.run, version: r.dataset.id }, title: r.dataset.id },
      el("code", {}, version(r)), ` (${plural(r.dataset.samples, "sample")}, ${plural(r.dataset.splits?.val ?? 0, "validation sample")})`))),
    el("tr", { className: new Set(runs.map(split)).size > 1 ? "differs" : "" }, el("th", {}, "split"),
      ...runs.map((r) => el("td", { dataset: { run: r.run } }, split(r)))),
    el("tr", {}, el("th", {}, "validation step"), ...runs.map((r) => el("td", {}, String(r.last_val?.step ?? "—")))),
    ...ROWS.map(([region, key, label]) => el("tr", {}, el("th", {}, label),
      ...runs.map((r) => el("td", { dataset: { run: r.run } }, fixed(r.last_val?.metrics?.[region]?.[key], key === "epe" ? 3 : 2))))),
    el("tr", {}, el("th", {}, "best val EPE (px)"), ...runs.map((r) => el("td", {}, fixed(r.best_val_epe)))),
  ];
  const t = document.getElementById("compare-table");
  t.tHead.replaceChildren(head);
  t.tBodies[0].replaceChildren(...rows);
}

async function refresh() {
  if (done || ids.length === 0) return;
  const { items } = await api(`${root.dataset.runs}?ids=${ids.join(",")}`);
  const runs = ids.map((id) => items.find((r) => r.run === id)).filter(Boolean);
  const points = await Promise.all(runs.map((r) => api(`${runUrl(root.dataset.runApi, r.run)}/metrics`)));
  const series = (pick) => runs.map((r, i) => ({ name: `run ${r.run}`, color: COLORS[i % COLORS.length], points: pick(points[i]) }));
  loss.update(series((p) => p.step.filter((s) => s.loss != null).map((s) => [s.step, s.loss])));
  epe.update(series((p) => p.val.filter((v) => v.metrics?.all?.epe != null).map((v) => [v.step, v.metrics.all.epe])));
  table(runs);
  samplesWarning(runs);
  done = runs.every((r) => !LIVE.has(r.state));
}

document.addEventListener("keydown", (event) => {
  if (!isShortcut(event) || !/^[1-9]$/.test(event.key)) return;
  const link = document.querySelectorAll("#compare-table thead a")[Number(event.key) - 1];
  if (!link) return;
  event.preventDefault();
  link.click();
});
keyboardHelp([["`1`–`9`", "open the page of the 1st–9th run of the table"]],
             { note: "Each run keeps its colour on both charts. The page updates by itself while a run goes. "
                     + "Runs trained on different dataset versions, or on one split with different seeds or "
                     + "fractions, get a warning: their validation samples differ. "
                     + "To change the runs, tick others on the Models page." });
poll(refresh, 3000);
