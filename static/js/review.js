// The curators' review grid: keyboard-first approve/reject of prefiltered frames, bulk decisions,
// an undo stack and a large view. Decisions run one after another, in the order the keys were
// pressed, so each sends the revision the previous one returned and undo undoes what it says.
import { api, el, poll } from "./api.js";
import { focusTile as focusGridTile, pageOffset, serial, setCursor, stepOf } from "./grid.js";

const $ = (id) => document.getElementById(id);
const root = $("review");
const grid = $("review-grid");
const filters = $("review-filters");
const reasonPicker = $("reason-picker");
const viewer = $("viewer");
const help = $("help");
const media = root.dataset.media;
const csrf = document.querySelector('meta[name="csrf-token"]')?.content ?? "";

const PAGE = 48;
const EMPTY_RECHECK_MS = 5000;  // the queue fills while the prefilter runs: look again while it is empty
const MARK = { yes: "✓", no: "✗", unknown: "?" };
const STEPS = { ArrowLeft: "left", h: "left", ArrowRight: "right", l: "right", ArrowUp: "up", k: "up",
                ArrowDown: "down", j: "down" };

const view = { items: [], total: 0, offset: 0, focus: 0, anchor: null, selected: new Set(), questions: [],
               after: null, before: null, prev: null, next: null };
const latest = new Map();  // frame id → newest known item, also for frames on other pages (undo needs them)
const mine = new Map();    // frame id → the state this session's decisions left it in, for the counters
const undoStack = [];      // [{decision, frames: [{before, after, mineBefore}]}]
let recheck;

// ---- data -------------------------------------------------------------------------------------

const enqueue = serial((err) => say(err.message, "error"));

function query() {
  const f = filters.elements;
  const params = new URLSearchParams({ state: f.state.value, limit: PAGE, offset: view.offset });
  setCursor(params, view);
  if (root.dataset.videoId) params.set("video_id", root.dataset.videoId);
  if (f.keep.value) params.set("keep", f.keep.value);
  if (f.question.value) {
    params.set("question", f.question.value);
    params.set("answer", f.answer.value);
  }
  return params;
}

async function load() {
  clearTimeout(recheck);
  const page = await api(`${root.dataset.frames}?${query()}`);
  Object.assign(view, { items: page.items, total: page.total, questions: page.questions, focus: 0, anchor: null,
                        prev: page.prev, next: page.next });
  if (!page.prev) view.offset = 0;
  view.selected.clear();
  page.items.forEach((item) => latest.set(item.id, item));
  const hadFocus = document.activeElement === document.body || grid.contains(document.activeElement);
  grid.replaceChildren(...page.items.map((item) => renderTile(el("li", { className: "tile", role: "option" }), item)));
  if (!page.items.length) {
    grid.append(el("li", { className: "empty", role: "none" }, "No frames here — looking again every few seconds."));
    recheck = setTimeout(() => enqueue(load), EMPTY_RECHECK_MS);
  }
  $("review-range").textContent = page.total
    ? `${view.offset + 1}–${view.offset + page.items.length} of ${page.total}${page.total_exact ? "" : "+"}` : "0 of 0";
  $("prev-page").disabled = !page.prev;
  $("next-page").disabled = !page.next;
  history.replaceState(null, "", urlFor(query()));
  paint();
  if (hadFocus) focusTile();
}

function urlFor(params) {
  params.delete("limit");
  if (params.get("offset") === "0") params.delete("offset");
  if (params.get("state") === "prefiltered") params.delete("state");
  return params.size ? `?${params}` : location.pathname;
}

// One frame through the single endpoint, several through the bulk one; both come back as bulk-style results.
async function send(frames, decision, reason) {
  if (frames.length > 1) {
    const body = { decision, reason, items: frames.map((f) => ({ id: f.id, revision: f.revision })) };
    return (await api(root.dataset.bulk, { method: "POST", body })).results;
  }
  const [frame] = frames;
  // Not api(): it drops an error's body, and a 409 carries the frame's current state for its tile.
  const response = await fetch(`${root.dataset.reviewBase}${frame.id}/review`, {
    method: "POST", credentials: "same-origin",
    headers: { "Accept": "application/json", "Content-Type": "application/json", "X-CSRFToken": csrf },
    body: JSON.stringify({ decision, reason, revision: frame.revision }),
  });
  const data = await response.json().catch(() => ({}));
  return [response.ok ? { id: frame.id, status: 200, frame: data }
                      : { id: frame.id, status: response.status, frame: data.frame, error: data.error ?? response.statusText }];
}

// Applies results to tiles and counters; returns the ids that went through.
function settle(results) {
  const failed = results.filter((r) => r.status !== 200);
  for (const r of results) {
    if (r.frame) update(r.frame);
    tileOf(r.id)?.classList.toggle("conflict", r.status !== 200);
  }
  if (failed.length) {
    const first = failed[0].error.replace(/^./, (c) => c.toUpperCase());
    const shown = failed.every((r) => r.frame) ? " Its tile is refreshed now: decide again." : "";
    say(failed.length === 1 ? `${first}.${shown}` : `${failed.length} frames were not changed. ${first}.${shown}`, "error");
  }
  refreshFunnel().catch((err) => console.warn(err));
  return new Set(results.filter((r) => r.status === 200).map((r) => r.id));
}

function update(item) {
  latest.set(item.id, item);
  const i = view.items.findIndex((f) => f.id === item.id);
  if (i < 0) return;
  view.items[i] = item;
  renderTile(tileOf(item.id), item);
  if (viewer.open && i === view.focus) renderViewer();
}

function tally(id, state) {
  if (state === "approved" || state === "rejected") mine.set(id, state);
  else mine.delete(id);
  const count = (s) => [...mine.values()].filter((v) => v === s).length;
  $("count-approved").textContent = count("approved");
  $("count-rejected").textContent = count("rejected");
}

async function refreshFunnel() {
  $("count-funnel").textContent = (await api(root.dataset.funnel)).approved;
}

// ---- decisions --------------------------------------------------------------------------------

// The selection, or else the focused frame; the large view always acts on the frame it shows.
function targets() {
  if (viewer.open || !view.selected.size) return view.items.slice(view.focus, view.focus + 1);
  return view.items.filter((f) => view.selected.has(f.id));
}

async function decide(decision) {
  const chosen = targets();
  if (!chosen.length) return;
  const reason = decision === "reject" ? await pickReason(chosen.length) : "";
  if (decision === "reject" && !reason) return;
  const ids = chosen.map((f) => f.id);
  // Move on at once, so the curator never waits for the server between two keys.
  view.selected.clear();
  moveTo(Math.max(...ids.map(indexOf)) + 1);
  busy(ids, true);
  enqueue(async () => {
    try {
      const before = ids.map((id) => latest.get(id));
      const mineBefore = new Map(ids.map((id) => [id, mine.get(id)]));
      const done = settle(await send(before, decision, reason));
      if (!done.size) return;
      const frames = before.filter((f) => done.has(f.id))
        .map((f) => ({ before: f, after: latest.get(f.id), mineBefore: mineBefore.get(f.id) }));
      frames.forEach((f) => tally(f.after.id, f.after.state));
      undoStack.push({ decision, frames });
      const what = done.size === 1 ? `#${[...done][0]}` : plural(done.size);
      if (done.size === ids.length) say(decision === "approve" ? `Approved ${what}.` : `Rejected ${what}: ${reason}.`);
    } finally {
      busy(ids, false);
      paint();
    }
  });
}

// Puts the frames of the last decision back where they were: in the queue, or at their earlier verdict.
function undo() {
  enqueue(async () => {
    const entry = undoStack.pop();
    if (!entry) return say("Nothing to undo.");
    const groups = Map.groupBy(entry.frames, ({ before }) => `${before.state}\n${before.last_review?.reason ?? ""}`);
    const restored = [];
    for (const frames of groups.values()) {
      const { state, last_review: last } = frames[0].before;
      const decision = { prefiltered: "reset", approved: "approve", rejected: "reject" }[state];
      const now = frames.map((f) => latest.get(f.after.id));
      const done = settle(await send(now, decision, state === "rejected" ? last?.reason || "undo" : ""));
      for (const f of frames.filter((f) => done.has(f.after.id))) {
        tally(f.after.id, f.mineBefore);
        restored.push(f.after.id);
      }
    }
    if (restored.length) {
      say(`Undid ${entry.decision} of ${plural(restored.length)}.`);
      const i = indexOf(restored[0]);
      if (i >= 0) moveTo(i);
    }
    paint();
  });
}

function pickReason(count) {
  $("reason-target").textContent = count > 1 ? `${count} frames` : "this frame";
  reasonPicker.returnValue = "";
  reasonPicker.showModal();
  return new Promise((resolve) => reasonPicker.addEventListener("close", () => resolve(reasonPicker.returnValue),
                                                                 { once: true }));
}

// ---- focus, selection, paging -----------------------------------------------------------------

function moveTo(index, extend = false) {
  if (!view.items.length) return;
  const to = Math.min(Math.max(index, 0), view.items.length - 1);
  if (extend) {
    view.anchor ??= view.focus;
    const [lo, hi] = [Math.min(view.anchor, to), Math.max(view.anchor, to)];
    view.selected = new Set(view.items.slice(lo, hi + 1).map((f) => f.id));
  } else {
    view.anchor = null;
    view.selected.clear();
  }
  view.focus = to;
  paint();
  focusTile();
  if (viewer.open) renderViewer();
}

function step(direction, extend) {
  moveTo(view.focus + stepOf(direction, grid, viewer.open), extend);
}

function toggle(index) {
  const id = view.items[index].id;
  if (!view.selected.delete(id)) view.selected.add(id);
  view.focus = index;
  view.anchor = index;
  paint();
}

function selectPage() {
  view.selected = new Set(view.items.map((f) => f.id));
  paint();
}

function page(direction) {
  enqueue(async () => {
    const next = pageOffset(view, direction, PAGE, inFilter);
    if (typeof next === "string") return say(next);
    Object.assign(view, next);
    await load();
  });
}

function focusTile() {
  if (!viewer.open) focusGridTile(grid, view.focus);
}

// ---- rendering --------------------------------------------------------------------------------

const inFilter = (item) => ["all", item.state].includes(filters.elements.state.value);
const indexOf = (id) => view.items.findIndex((f) => f.id === id);
const tileOf = (id) => grid.querySelector(`.tile[data-id="${id}"]`);
const plural = (n) => (n === 1 ? "1 frame" : `${n} frames`);
const answerOf = (value) => (value === true ? "yes" : value === false ? "no" : "unknown");
const verdictOf = (keep) => (keep === true ? "keep" : keep === false ? "drop" : "no verdict");
const formatNumber = (v) => (typeof v === "number" ? String(Number(v.toPrecision(3))) : String(v));
const timeOf = (item) => `${item.time_s.toFixed(1)} s`;

function paint() {
  [...grid.querySelectorAll(".tile")].forEach((node, i) => {
    node.classList.toggle("focused", i === view.focus);
    node.tabIndex = i === view.focus ? 0 : -1;
    node.ariaSelected = String(view.selected.has(view.items[i].id));
  });
  const n = view.selected.size;
  $("approve").textContent = n ? `Approve ${n}` : "Approve";
  $("reject").textContent = n ? `Reject ${n}…` : "Reject…";
  $("undo").disabled = !undoStack.length;
}

function busy(ids, on) {
  ids.forEach((id) => tileOf(id)?.classList.toggle("busy", on));
}

function renderTile(node, item) {
  const image = node.querySelector("img") ?? el("img", {
    src: media + item.thumb, loading: "lazy", alt: "", width: 320, height: Math.round(320 * item.height / item.width),
  });
  node.dataset.id = item.id;
  node.dataset.state = item.state;
  node.classList.toggle("settled", !inFilter(item));
  node.ariaLabel = `Frame ${item.id}, video ${item.video_id} at ${timeOf(item)}, ${item.state}, VLM ${verdictOf(item.prefilter_keep)}`;
  node.replaceChildren(
    el("div", { className: "thumb" }, image,
       el("span", { className: `badge state ${item.state}` }, item.state),
       el("span", { className: `badge verdict ${verdictOf(item.prefilter_keep).replace(" ", "-")}`,
                    title: item.prefilter?.reason ?? "" }, `VLM ${verdictOf(item.prefilter_keep)}`)),
    el("div", { className: "meta" }, el("strong", {}, `#${item.id}`), ` video ${item.video_id} · ${timeOf(item)}`,
       lastReview(item)),
    answerChips(item.prefilter?.answers),
    metricList(item.prefilter?.metrics ?? {}),
  );
  return node;
}

function lastReview(item) {
  const last = item.last_review;
  if (!last || item.state === "prefiltered") return "";
  return el("span", { className: "reviewed", title: `${last.decision} by ${last.user ?? "?"} at ${last.at}` },
            last.reason ? `${last.reason} · ${last.user ?? ""}` : last.user ?? "");
}

function answerChips(answers) {
  return el("ol", { className: "answers" }, ...view.questions.map((question, i) => {
    const answer = answerOf(answers?.[i]);
    return el("li", { className: answer, title: `${i + 1}. ${question}: ${answer}` }, MARK[answer]);
  }));
}

function metricList(metrics) {
  return el("dl", { className: "metrics" }, ...Object.entries(metrics).map(([name, value]) =>
    el("div", { title: name }, el("dt", {}, name.replaceAll("_", " ")), el("dd", {}, formatNumber(value)))));
}

function renderViewer() {
  const item = view.items[view.focus];
  const result = item.prefilter;
  const image = $("viewer-image");
  image.src = media + item.image;
  image.alt = `Frame ${item.id}, full resolution`;
  viewer.ariaLabel = `Frame ${item.id}`;
  $("viewer-info").replaceChildren(
    el("h2", {}, `Frame #${item.id}`, el("span", { className: `badge state ${item.state}` }, item.state)),
    el("p", { className: "muted" }, `video ${item.video_id} · index ${item.index} · ${timeOf(item)} · ${item.width}×${item.height}`),
    item.last_review && item.state !== "prefiltered"
      ? el("p", {}, `${item.last_review.decision === "approve" ? "Approved" : "Rejected"}`,
           item.last_review.reason ? ` (${item.last_review.reason})` : "", ` by ${item.last_review.user ?? "?"}`)
      : "",
    result ? el("p", {}, el("strong", {}, `VLM ${verdictOf(result.keep)}`), result.reason ? ` — ${result.reason}` : "")
           : el("p", { className: "muted" }, "No VLM result yet."),
    result ? el("p", { className: "muted" }, `${result.backend} · ${result.model_id} · prompt ${result.prompt_version}`) : "",
    el("table", { className: "questions" }, ...view.questions.map((question, i) => {
      const answer = answerOf(result?.answers?.[i]);
      return el("tr", {}, el("td", { className: "n" }, `${i + 1}`), el("td", {}, question),
                el("td", { className: `answer ${answer}` }, answer));
    })),
    metricList(result?.metrics ?? {}),
    result?.raw ? el("details", {}, el("summary", {}, "Raw VLM answer"), el("pre", {}, result.raw)) : "",
  );
}

function openViewer() {
  if (!view.items.length) return;
  $("viewer-status").textContent = "";
  renderViewer();
  viewer.showModal();
  viewer.focus();  // not its first button, where Enter or Space would press it
}

// The large view is modal and hides the page's status line, so it has its own.
function say(text, kind = "info") {
  for (const line of [$("review-status"), $("viewer-status")]) {
    line.textContent = text;
    line.dataset.kind = kind;
  }
}

// ---- input ------------------------------------------------------------------------------------

const COMMANDS = {
  a: () => decide("approve"), r: () => decide("reject"), x: () => decide("reject"), u: undo,
  Enter: () => (viewer.open ? viewer.close() : openViewer()), " ": () => (viewer.open ? viewer.close() : openViewer()),
  n: () => page(1), "]": () => page(1), p: () => page(-1), "[": () => page(-1),
  Home: () => moveTo(0, false), End: () => moveTo(view.items.length - 1, false),
  "?": () => help.showModal(),
  Escape: () => moveTo(view.focus),  // clears the selection
};

function command(event) {
  const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
  if (event.ctrlKey || event.metaKey) return { a: selectPage, z: undo }[key];
  if (event.altKey) return undefined;
  if (STEPS[key]) return () => step(STEPS[key], event.shiftKey);
  return COMMANDS[key];
}

document.addEventListener("keydown", (event) => {
  if (reasonPicker.open) {
    const reasons = [...reasonPicker.querySelectorAll("button.reason")].map((b) => b.value);
    const reason = reasons[Number(event.key) - 1];
    if (reason) {
      event.preventDefault();
      reasonPicker.close(reason);
    }
    return;
  }
  if (help.open) {
    if (event.key === "?") help.close();
    return;
  }
  const target = event.target;
  if (target.closest("input, select, textarea")) {
    if (event.key === "Escape") focusTile();
    return;
  }
  if (["Enter", " "].includes(event.key) && target.closest("button, a, summary")) return;  // let them press
  if (viewer.open && event.key === "Escape") return;  // the dialog closes itself
  const run = command(event);
  if (!run) return;
  event.preventDefault();
  run();
});

grid.addEventListener("click", (event) => {
  const node = event.target.closest(".tile");
  if (!node) return;
  const index = indexOf(Number(node.dataset.id));
  if (event.ctrlKey || event.metaKey) toggle(index);
  else moveTo(index, event.shiftKey);
});
grid.addEventListener("dblclick", (event) => event.target.closest(".tile") && openViewer());

viewer.addEventListener("click", (event) => {
  const action = event.target.closest("[data-action]")?.dataset.action;
  const actions = { prev: () => step("left"), next: () => step("right"), approve: () => decide("approve"),
                    reject: () => decide("reject"), close: () => viewer.close() };
  actions[action]?.();
  if (event.target === viewer) viewer.close();  // a click on the backdrop
});
viewer.addEventListener("close", focusTile);
help.addEventListener("close", focusTile);

// Toolbar buttons act like their keys, then hand the keyboard back to the grid.
for (const [id, run] of Object.entries({
  "approve": () => decide("approve"), "reject": () => decide("reject"), "undo": undo, "select-page": selectPage,
  "prev-page": () => page(-1), "next-page": () => page(1), "help-button": () => help.showModal(),
})) {
  $(id).addEventListener("click", async () => {
    await run();
    if (!help.open) focusTile();
  });
}

filters.addEventListener("change", () => {
  filters.elements.answer.disabled = !filters.elements.question.value;
  Object.assign(view, { offset: 0, after: null, before: null });
  enqueue(load);
});

// Filters and page come from the address, so a reload or a shared link lands on the same page.
function restore() {
  const params = new URLSearchParams(location.search);
  for (const name of ["state", "keep", "question", "answer"]) {
    if (params.has(name)) filters.elements[name].value = params.get(name);
  }
  filters.elements.answer.disabled = !filters.elements.question.value;
  view.offset = Math.max(0, Number(params.get("offset")) || 0);
  Object.assign(view, { after: params.get("after"), before: params.get("before") });
}

restore();
enqueue(load);
poll(refreshFunnel, 10000);
