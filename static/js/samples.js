// The samples grid: keyboard-first accept/reject of generated samples, filters, paging, and a way
// into each sample's page and 3D preview. Decisions run one after another, in key order.
import { api, el } from "./api.js";
import { notedReasonPicker } from "./dialogs.js";
import { actLikeKeys, focusTile as focusGridTile, gridHelp, listenKeys, serial, setCursor, stepOf, turnPage } from "./grid.js";
import { keyboardHelp } from "./help.js";
import { framePlace } from "./labels.js";
import { allowedDecisions, decisionShortcuts, keyFigures, rejectionText, rememberDecision, review, sessionCounts } from "./sample_review.js";
import { sayFailure } from "./session_ended.js";

const $ = (id) => document.getElementById(id);
const root = $("samples");
const grid = $("samples-grid");
const filters = $("sample-filters");
const picker = $("reason-picker");
const pickReason = notedReasonPicker(picker);
const canReview = root.dataset.canReview === "true";
const help = keyboardHelp(gridHelp("sample", [
  ...(canReview ? decisionShortcuts(picker) : []),
  ["`Enter`", "open the sample: 2D views and QA figures"],
  ["`v`", "open its 3D preview"],
  ["`d`", "thumbnails: image + masks → disparity → anaglyph"],
]));
const pages = root.dataset.pages;  // /samples

const PAGE = 48;
const THUMBS = ["masks", "disparity_after", "anaglyph"];

const view = { items: [], total: 0, offset: 0, focus: 0, after: null, before: null, prev: null, next: null };
// ?evaluation=ID&sort=error[&method=M&region=R]: the evaluation's samples, worst first (kept in the address).
const BY_ERROR = ["evaluation", "sort", "method", "region", "min_error"];
const byError = new URLSearchParams([...new URLSearchParams(location.search)].filter(([k]) => BY_ERROR.includes(k)));

const enqueue = serial(sayFailure(say));

// ---- data -------------------------------------------------------------------------------------

function query() {
  const f = filters.elements;
  const params = new URLSearchParams({ limit: PAGE, offset: view.offset });
  setCursor(params, view);
  if (f.state.value !== "all") params.set("state", f.state.value);
  if (f.flagged.value) params.set("flagged", f.flagged.value);
  if (byError.has("evaluation")) byError.forEach((value, key) => params.set(key, value));
  return params;
}

async function load(focusId) {
  const page = await api(`${root.dataset.list}?${query()}`);
  Object.assign(view, { items: page.items, total: page.total, prev: page.prev, next: page.next });
  if (!page.prev) view.offset = 0;
  view.focus = Math.max(0, view.items.findIndex((s) => s.id === focusId));
  grid.replaceChildren(...page.items.map((s) => renderTile(el("li", { className: "tile", role: "listitem" }), s)));
  if (!page.items.length) {
    grid.append(el("li", { className: "empty" },
                   "No samples here. Samples appear when annotated frames have been generated (see Jobs)."));
  }
  $("samples-range").textContent = page.total
    ? `${view.offset + 1}–${view.offset + page.items.length} of ${page.total}` : "0 of 0";
  $("prev-page").disabled = !page.prev;
  $("next-page").disabled = !page.next;
  history.replaceState(null, "", address());
  paint();
  focusTile();
}

// Filters, page and focus live in the address, so Back from a sample page lands where one left.
function address() {
  const f = filters.elements;
  const params = new URLSearchParams(byError);
  if (f.state.value !== "generated") params.set("state", f.state.value);
  if (f.flagged.value) params.set("flagged", f.flagged.value);
  if (f.thumb.value !== THUMBS[0]) params.set("thumb", f.thumb.value);
  if (view.offset) params.set("offset", view.offset);
  setCursor(params, view);
  const focused = view.items[view.focus];
  if (focused && view.focus) params.set("focus", focused.id);
  return params.size ? `?${params}` : location.pathname;
}

// ---- decisions --------------------------------------------------------------------------------

async function decide(decision) {
  const sample = view.items[view.focus];
  if (!sample) return;
  if (!canReview) return say("Only curators accept or reject samples.", "error");
  if (!allowedDecisions(sample.state).includes(decision)) {
    return say(sample.state === "accepted" ? `Sample #${sample.id} is already accepted (Reject takes it out of the dataset).`
      : `Sample #${sample.id} is rejected: its frame went back to the annotators, and comes back as a new sample.`);
  }
  const said = decision === "reject" ? await pickReason(`sample #${sample.id}`) : {};
  if (decision === "reject" && !said.reason) return focusTile();
  moveTo(view.focus + 1);  // on at once: the curator never waits for the server between two keys
  const tile = tileOf(sample.id);
  tile?.classList.add("busy");
  enqueue(async () => {
    try {
      const updated = await review(`${root.dataset.list}/${sample.id}`, decision, said);
      update(updated);
      tally(updated);
      say(decision === "accept" ? `Accepted #${sample.id}.` : `Rejected #${sample.id}: ${rejectionText(said)}.`);
    } catch (err) {
      tile?.classList.add("conflict");
      throw err;
    } finally {
      tile?.classList.remove("busy");
    }
  });
}

function update(sample) {
  const i = view.items.findIndex((s) => s.id === sample.id);
  if (i < 0) return;
  view.items[i] = sample;
  renderTile(tileOf(sample.id), sample);
  paint();
}

function tally(sample) {
  showCounts(rememberDecision(sample));
}

function showCounts({ accepted, rejected }) {
  if (!canReview) return;
  $("count-accepted").textContent = accepted;
  $("count-rejected").textContent = rejected;
}

// The toolbar offers what the focused sample's state allows.
function showActions() {
  if (!canReview) return;
  const allowed = allowedDecisions(view.items[view.focus]?.state);
  $("accept").disabled = !allowed.includes("accept");
  $("reject").disabled = !allowed.includes("reject");
}

// ---- focus and paging -------------------------------------------------------------------------

function moveTo(index) {
  if (!view.items.length) return;
  view.focus = Math.min(Math.max(index, 0), view.items.length - 1);
  paint();
  focusTile();
  history.replaceState(null, "", address());
}

function step(direction) {
  moveTo(view.focus + stepOf(direction, grid));
}

function page(direction) {
  enqueue(() => turnPage(view, direction, { size: PAGE, inFilter, load, say }));
}

function open(suffix = "") {
  const sample = view.items[view.focus];
  if (sample) location.assign(`${pages}/${sample.id}${suffix}`);
}

function cycleThumbs() {
  const select = filters.elements.thumb;
  select.value = THUMBS[(THUMBS.indexOf(select.value) + 1) % THUMBS.length];
  showThumbs();
}

function showThumbs() {
  view.items.forEach((s) => renderTile(tileOf(s.id), s));
  history.replaceState(null, "", address());
  focusTile();
}

function focusTile() {
  focusGridTile(grid, view.focus);
}

// ---- rendering --------------------------------------------------------------------------------

const inFilter = (s) => ["all", s.state].includes(filters.elements.state.value)
  && (!filters.elements.flagged.value || String(s.flagged) === filters.elements.flagged.value);
const tileOf = (id) => grid.querySelector(`.tile[data-id="${id}"]`);

function paint() {
  [...grid.querySelectorAll(".tile")].forEach((node, i) => {
    node.classList.toggle("focused", i === view.focus);
    node.tabIndex = i === view.focus ? 0 : -1;
  });
  showActions();
}

function renderTile(node, sample) {
  const thumb = filters.elements.thumb.value;
  node.dataset.id = sample.id;
  node.dataset.state = sample.state;
  node.classList.toggle("settled", !inFilter(sample));
  node.classList.toggle("flagged", sample.flagged);
  node.ariaLabel = `Sample ${sample.id}, ${framePlace(sample, sample.frame_id)}, ${sample.state}`
    + (sample.flagged ? `, flagged: ${sample.qa.flags.join("; ")}` : "");
  node.replaceChildren(
    el("div", { className: "thumb" },
       el("img", { src: `${pages}/${sample.id}/views/${thumb}.png?size=thumb`, loading: "lazy", alt: "",
                   width: 384, height: Math.round(384 * sample.height / sample.width) }),
       el("span", { className: `badge state ${sample.state}` }, sample.state),
       sample.flagged ? el("span", { className: "badge flagged", title: sample.qa.flags.join("\n") }, "⚑ flagged") : ""),
    el("div", { className: "meta" },
       el("a", { href: `${pages}/${sample.id}`, tabIndex: -1 }, el("strong", {}, `#${sample.id}`)),
       ` ${framePlace(sample, sample.frame_id)}`),
    el("dl", { className: "metrics" }, ...keyFigures(sample).map(([label, value, title, flagged]) =>
      el("div", { title, className: flagged ? "flagged" : "" }, el("dt", {}, label), el("dd", {}, value)))),
    sample.qa.flags?.length ? el("p", { className: "flags" }, sample.qa.flags.join(" · ")) : "",
    sample.evaluation ? errorLine(sample) : "",
  );
  return node;
}

function errorLine(sample) {
  const e = sample.evaluation;
  const unit = e.metric === "epe" ? " px" : " %";
  const value = typeof e.value === "number" ? `${e.value.toFixed(2)}${unit}` : "—";
  return el("p", { className: "evaluation-error" },
            el("a", { href: `${root.dataset.evaluations}/${e.id}/samples/${sample.id}?method=${e.method}`, tabIndex: -1 },
               `${e.method} ${e.metric} on ${e.region}: ${value}`));
}

function say(text, kind = "info") {
  const line = $("samples-status");
  line.textContent = text;
  line.dataset.kind = kind;
}

// ---- input ------------------------------------------------------------------------------------

listenKeys({
  help, picker, focus: focusTile, step,
  commands: {
    a: () => decide("accept"), r: () => decide("reject"), x: () => decide("reject"),
    Enter: () => open(), v: () => open("/preview"), d: cycleThumbs,
    n: () => page(1), "]": () => page(1), p: () => page(-1), "[": () => page(-1),
    Home: () => moveTo(0), End: () => moveTo(view.items.length - 1),
  },
});

grid.addEventListener("click", (event) => {
  const node = event.target.closest(".tile");
  if (node) moveTo([...grid.children].indexOf(node));
});
grid.addEventListener("dblclick", (event) => event.target.closest(".tile") && open());
help.addEventListener("close", focusTile);

actLikeKeys({ "open": () => open(), "open-3d": () => open("/preview"), "accept": () => decide("accept"),
              "reject": () => decide("reject"), "prev-page": () => page(-1), "next-page": () => page(1) }, focusTile);

filters.addEventListener("change", (event) => {
  if (event.target.name === "thumb") return showThumbs();
  Object.assign(view, { offset: 0, after: null, before: null });
  enqueue(() => load());
});

function restore() {
  const params = new URLSearchParams(location.search);
  if (byError.has("evaluation")) {
    filters.elements.state.value = "all";  // an evaluation's samples are whatever their state now
    say(`Samples of evaluation #${byError.get("evaluation")}, worst first by ${byError.get("sort") ?? "error"}.`);
  }
  for (const name of ["state", "flagged", "thumb"]) {
    if (params.has(name)) filters.elements[name].value = params.get(name);
  }
  view.offset = Math.max(0, Number(params.get("offset")) || 0);
  Object.assign(view, { after: params.get("after"), before: params.get("before") });
  return Number(params.get("focus")) || undefined;
}

const focusId = restore();
showCounts(sessionCounts());
enqueue(() => load(focusId));
