// The curators' review grid: keyboard-first approve/reject of prefiltered frames, bulk decisions,
// an undo stack and a large view. Decisions run one after another, in the order the keys were
// pressed, so each sends the revision the previous one returned and undo undoes what it says.
import { api, el, poll } from "./api.js";
import { reasonPicker, reasonShortcut } from "./dialogs.js";
import { actLikeKeys, focusTile as focusGridTile, gridHelp, listenKeys, serial, setCursor, stepOf, turnPage } from "./grid.js";
import { keyboardHelp } from "./help.js";
import { plural } from "./labels.js";
import { call } from "./request.js";
import { frameTile } from "./review_tile.js";
import * as largeView from "./review_viewer.js";
import { sayFailure, sessionEnded } from "./session_ended.js";

const $ = (id) => document.getElementById(id);
const root = $("review");
const grid = $("review-grid");
const filters = $("review-filters");
const picker = $("reason-picker");
const pickReason = reasonPicker(picker);
const viewer = $("viewer");
const help = keyboardHelp(gridHelp("frame", [
  ["`a`", "approve the frame, or every selected frame"],
  reasonShortcut(picker),
  ["`Shift` + move", "select a range"],
  ["`Ctrl`/`⌘` + `A`", "select the page"],
  ["`Esc`", "clear the selection, close a dialog"],
  ["`u` or `Ctrl` + `Z`", "undo the last decision"],
  ["`Enter` or `Space`", "large view, where approve, reject and the arrows work too"],
]), { note: "Mouse: click focuses, Shift+click selects a range, Ctrl/⌘+click toggles, double-click opens the large view." });
const media = root.dataset.media;

const PAGE = 48;
const EMPTY_RECHECK_MS = 5000;  // the queue fills while the prefilter runs: look again while it is empty

const view = { items: [], total: 0, offset: 0, focus: 0, anchor: null, selected: new Set(), questions: [],
               after: null, before: null, prev: null, next: null };
const latest = new Map();  // frame id → newest known item, also for frames on other pages (undo needs them)
const mine = new Map();    // frame id → the state this session's decisions left it in, for the counters
const undoStack = [];      // [{decision, frames: [{before, after, mineBefore}]}]
let recheck;

// ---- data -------------------------------------------------------------------------------------

const enqueue = serial(sayFailure(say));

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
  // Not api(): a 409 carries the frame's current state for its tile.
  const res = await call(`${root.dataset.reviewBase}${frame.id}/review`,
                         { body: { decision, reason, revision: frame.revision } });
  if (sessionEnded(res.error)) throw res.error;
  return [res.ok ? { id: frame.id, status: 200, frame: res.data }
                 : { id: frame.id, status: res.status, frame: res.data.frame, error: res.error.message }];
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
  const label = chosen.length > 1 ? plural(chosen.length, "frame") : "this frame";
  const reason = decision === "reject" ? await pickReason(label) : "";
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
      const what = done.size === 1 ? `#${[...done][0]}` : plural(done.size, "frame");
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
      say(`Undid ${entry.decision} of ${plural(restored.length, "frame")}.`);
      const i = indexOf(restored[0]);
      if (i >= 0) moveTo(i);
    }
    paint();
  });
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
  enqueue(() => turnPage(view, direction, { size: PAGE, inFilter, load, say }));
}

function focusTile() {
  if (!viewer.open) focusGridTile(grid, view.focus);
}

// ---- rendering --------------------------------------------------------------------------------

const inFilter = (item) => ["all", item.state].includes(filters.elements.state.value);
const indexOf = (id) => view.items.findIndex((f) => f.id === id);
const tileOf = (id) => grid.querySelector(`.tile[data-id="${id}"]`);
const shown = () => ({ media, questions: view.questions });

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
  return frameTile(node, item, { ...shown(), settled: !inFilter(item) });
}

function renderViewer() {
  largeView.show(viewer, view.items[view.focus], shown());
}

function openViewer() {
  if (view.items.length) largeView.open(viewer, view.items[view.focus], shown());
}

// On the page's status line and the large view's.
function say(text, kind = "info") {
  for (const line of [$("review-status"), $("viewer-status")]) {
    line.textContent = text;
    line.dataset.kind = kind;
  }
}

// ---- input ------------------------------------------------------------------------------------

const toggleViewer = () => (viewer.open ? viewer.close() : openViewer());

listenKeys({
  help, picker, focus: focusTile, step,
  commands: {
    a: () => decide("approve"), r: () => decide("reject"), x: () => decide("reject"), u: undo,
    Enter: toggleViewer, " ": toggleViewer,
    n: () => page(1), "]": () => page(1), p: () => page(-1), "[": () => page(-1),
    Home: () => moveTo(0, false), End: () => moveTo(view.items.length - 1, false),
    Escape: () => moveTo(view.focus),  // clears the selection
  },
  withCtrl: { a: selectPage, z: undo },
});

grid.addEventListener("click", (event) => {
  const node = event.target.closest(".tile");
  if (!node) return;
  const index = indexOf(Number(node.dataset.id));
  if (event.ctrlKey || event.metaKey) toggle(index);
  else moveTo(index, event.shiftKey);
});
grid.addEventListener("dblclick", (event) => event.target.closest(".tile") && openViewer());

largeView.listen(viewer, { prev: () => step("left"), next: () => step("right"), approve: () => decide("approve"),
                          reject: () => decide("reject") });
viewer.addEventListener("close", focusTile);
help.addEventListener("close", focusTile);

actLikeKeys({ "approve": () => decide("approve"), "reject": () => decide("reject"), "undo": undo,
              "select-page": selectPage, "prev-page": () => page(-1), "next-page": () => page(1) }, focusTile);

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
