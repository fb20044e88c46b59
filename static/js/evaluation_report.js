// An evaluation's report in the app: its database samples named as every page names them
// ("synthetic-0000 · frame #4 · 1.5 s" rather than the reader's "video_1/frame_000000") and linked
// to the evaluation's page of each (ground truth, prediction, error); its `?` help. Sorting is the
// report's own script (report.js), the same standalone and here.
import { api, el } from "./api.js";
import { keyboardHelp } from "./help.js";
import { isShortcut } from "./keys.js";
import { framePlace } from "./labels.js";

const root = document.getElementById("evaluation");
const PAGE = 500;  // the samples API's largest page

// The reader's name of a database sample (dataset/readers/version.py sample_name).
const readerName = (s) => `video_${s.video_id}/frame_${String(s.index).padStart(6, "0")}`;

// name → sample of every sample the evaluation scored (it pages by offset).
async function evaluatedSamples() {
  const found = new Map();
  for (let offset = 0; ; offset += PAGE) {
    const page = await api(`${root.dataset.samples}?${new URLSearchParams({ evaluation: root.dataset.id, sort: "error", limit: PAGE, offset })}`);
    for (const s of page.items) found.set(readerName(s), s);
    if (!page.more || !page.items.length) return found;
  }
}

async function nameSamples() {
  const samples = await evaluatedSamples();
  for (const cell of document.querySelectorAll(".sample-name[data-name]")) {
    const sample = samples.get(cell.dataset.name);
    if (!sample) continue;
    const method = cell.closest("tr")?.dataset.method;
    const href = root.dataset.samplePage.replace(/0$/, String(sample.id)) + (method ? `?method=${encodeURIComponent(method)}` : "");
    cell.replaceChildren(el("a", { href, title: `sample #${sample.id} (${cell.dataset.name})` }, framePlace(sample, sample.frame_id)));
    cell.dataset.sample = sample.id;
  }
}

const sortable = () => [...document.querySelectorAll("#per-sample thead th")];
const KEYS = {
  s: () => document.getElementById("samples-by-error")?.click(),
  w: () => document.querySelector(".evaluation-pictures")?.scrollIntoView(),
};
document.addEventListener("keydown", (event) => {
  if (!isShortcut(event)) return;
  const column = /^[1-9]$/.test(event.key) ? sortable()[Number(event.key) - 1] : null;
  const run = column ? () => column.click() : KEYS[event.key];
  if (!run) return;
  event.preventDefault();
  run();
});

keyboardHelp([
  ["`1`–`9`", "sort the samples by the 1st–9th column: the worst first, again for the best"],
  ["`s`", "the evaluation's samples on the Samples page, worst first"],
  ["`w`", "to the pictures of the worst and best samples"],
], { note: "Click a column head (or Tab to it and press Enter) to sort. A sample's name opens its page in this "
          + "evaluation: ground truth beside the method's prediction and its error map." });

if (root.dataset.hasResults === "true") nameSamples().catch((err) => console.warn(err));
