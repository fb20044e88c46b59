// Two or more runs: loss and validation EPE of all of them on one chart each, and their last
// validation metrics side by side; refreshed while any of them runs.
import { api, el, poll } from "./api.js";
import { COLORS, lineChart } from "./chart.js";
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

function table(runs) {
  const head = el("tr", {}, el("th", {}, "Metric"), ...runs.map((r) =>
    el("th", {}, el("a", { href: runUrl(root.dataset.runPage, r.run) }, `run ${r.run}`), ` (${r.preset}, ${r.state})`)));
  const rows = [
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
  done = runs.every((r) => !LIVE.has(r.state));
}

poll(refresh, 3000);
