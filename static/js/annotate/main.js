// The click-annotation page: clicks become masks for illusion/support pairs, brush touch-ups, drafts
// saved on the server and in this browser, submit → the next frame from the queue, propagation, delete.
// A click shows its dot at once and the mask when the server answers; the page never blocks on it.
import { api, el } from "../api.js";
import { View } from "./canvas.js";
import { renderHelp, shortcutFor } from "./keys.js";
import { Layer } from "./layers.js";
import { encodeCounts, fromRuns, runsOf, toRuns } from "./rle.js";
import { propagate as runPropagation } from "./propagate.js";
import { FrameSession, call } from "./session.js";
import * as S from "./state.js";

const $ = (id) => document.getElementById(id);
const root = $("annotate");
const API = root.dataset.api;
const LEASE_S = Number(root.dataset.leaseS) || 600;
const EDITABLE = ["approved", "annotated"];
const QUEUE_RECHECK_MS = 8000;
const READY_RECHECK_MS = 2000;
const PREFS = "illusion-studio:annotate:prefs";
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

const prefs = { opacity: 0.5, brush: 8, propagate: 5, ...JSON.parse(localStorage.getItem(PREFS) ?? "{}") };
const ui = { pair: 1, kind: "illusion", hidden: false };
let frame = null;     // GET /frames/{id} of the frame on screen
let history = null;   // S.History of its annotation
let session = null;   // FrameSession while this annotator holds the frame; null = read-only
let stroke = null;    // the Layer being brushed
let segmenting = false;
let propagating = false;
let nav = Promise.resolve();
const layers = new WeakMap();  // runs → Layer

const view = new View($("canvas"), {
  point: (x, y, label) => edit((r) => ({ ...r, points: [...r.points, { x, y, label }], stale: true })),
  box: (box) => edit((r) => ({ ...r, box, stale: true })),
  strokeStart,
  strokeEnd,
  zoomed: (scale) => { $("zoom").textContent = `${Math.round(scale * 100)}%`; },
});
view.brush = prefs.brush;

// ---- messages -------------------------------------------------------------------------------------

function say(text, kind = "info") {
  $("message").textContent = text.charAt(0).toUpperCase() + text.slice(1);  // server messages start lowercase
  $("status").dataset.kind = kind;
}

function banner(text, action, run) {
  $("banner").hidden = !text;
  $("banner-text").textContent = text ?? "";
  $("banner-action").hidden = !action;
  $("banner-action").textContent = action ?? "";
  $("banner-action").onclick = run ? () => { banner(null); run(); } : null;
}

function saveState(text, kind = "") {
  $("save-state").textContent = text;
  $("save-state").dataset.kind = kind;
}

const plural = (n, word) => `${n} ${word}${n === 1 ? "" : "s"}`;
const pairName = (id) => `plane ${id}`;

// ---- loading frames -------------------------------------------------------------------------------

// Navigation runs one step at a time; `target` is read when the step starts, so two quick → presses
// move two frames.
function navigate(target, how = "push") {
  nav = nav.then(async () => {
    const id = await target();
    if (id == null) return;
    await leave();
    await open(id, how);
  }).catch((err) => say(err.message, "error"));
  return nav;
}

async function leave() {
  if (!session) return;
  const leaving = session;
  session = null;
  await leaving.flush();
  leaving.release();
}

async function fromQueue() {
  const res = await call(`${API}/queue/annotate/next`);
  if (res.status === 404) {
    showEmpty();
    return null;
  }
  if (!res.ok) throw new Error(res.error);
  return res.data.frame_id;
}

async function open(id, how) {
  root.dataset.state = "loading";
  const detail = await api(`${API}/frames/${id}`);
  const image = new Image();
  image.src = root.dataset.media + detail.image;
  const loaded = image.decode();

  let reason = null;
  if (!EDITABLE.includes(detail.state)) reason = `this frame is ${detail.state}`;
  else if (detail.lease.held_by_other) reason = "another annotator is working on it";
  else if (detail.submitted && !detail.lease.mine) reason = "it is submitted";
  else if (!detail.lease.mine) {
    const res = await call(`${API}/frames/${id}/lease`);
    if (res.ok) detail.lease = { ...detail.lease, mine: true, expires: res.data.lease_expires };
    else reason = res.status === 409 ? "another annotator is working on it" : res.error;
  }
  await loaded;

  frame = detail;
  const serverDoc = S.fromServer(detail);
  history = new S.History(serverDoc);
  ui.pair = serverDoc.pairs[0].id;
  ui.kind = "illusion";
  if (how === "push") window.history.pushState({ id }, "", `/annotate/${id}`);
  else window.history.replaceState({ id }, "", `/annotate/${id}`);
  $("frame-title").textContent = `Frame #${detail.id}`;
  $("preview-link").href = `/frames/${detail.id}/preview`;
  $("preview-link").hidden = detail.state === "approved";  // a sample exists only after a submit
  $("frame-info").textContent = `video ${detail.video_id} · frame ${detail.index} · ${detail.time_s.toFixed(1)} s · `
    + `${detail.width}×${detail.height}`;
  $("prev-frame").disabled = detail.prev_id == null;
  $("next-frame").disabled = detail.next_id == null;
  $("empty").hidden = true;
  $("timing").textContent = "";
  view.setImage(image);
  banner(null);
  if (reason) readOnly(reason);
  else {
    say(detail.regions.length ? `Draft loaded: ${plural(serverDoc.pairs.length, "plane")}.`
                              : "Click inside the illusion: the flat thing that looks 3D.");
    hold(serverDoc);
  }
  render();
  watchPreparing(detail);
  preloadNext(detail);
  root.dataset.state = "ready";
}

function readOnly(reason) {
  session = null;
  setTool("click");
  const submitted = reason === "it is submitted";
  say(`This frame is read-only: ${reason}.`);
  saveState(submitted ? "Submitted" : "Read-only", submitted ? "ok" : "");
  if (submitted) banner("Submitted — shown read-only.", "Edit this frame", takeOver);
  else banner(`Read-only: ${reason}.`, "Next frame from the queue ⏎", () => navigate(fromQueue));
  render();
}

async function takeOver() {
  const res = await call(`${API}/frames/${frame.id}/lease`);
  if (!res.ok) return readOnly(res.status === 409 ? "another annotator is working on it" : res.error);
  hold(history.doc);
  say("You hold this frame now; changes are saved as drafts until you submit again.");
  render();
}

function hold(serverDoc) {
  const held = frame;
  const here = (hook) => (...args) => frame === held && hook(...args);  // the page may have moved on
  session = new FrameSession(API, held, serverDoc, {
    saving: here(() => saveState("Saving…")),
    saved: here((doc, version) => {
      if (doc === history.doc) S.dropDraft(held.id);
      else S.storeDraft(held.id, version, history.doc, held.height, held.width);
      saveState(doc === history.doc ? "Draft saved" : "Unsaved changes", doc === history.doc ? "ok" : "");
    }),
    conflict: here((message) => {
      saveState("Not saved", "error");
      say(message, "error");
      banner("Someone else saved this frame since you opened it. Your changes are kept in this browser.",
             "Reload the frame", () => navigate(async () => held.id, "replace"));
    }),
    failed: here((message) => {
      saveState("Not saved — retrying", "error");
      say(`Could not save the draft (${message}); it is kept in this browser and retried.`, "error");
    }),
    leaseLost: here((message) => {
      readOnly("another annotator took it while your lease had run out");
      say(`${message}. Your changes are kept in this browser.`, "error");
    }),
  });
  session.keepLease(LEASE_S);
  if (frame.submitted) saveState("Submitted", "ok");
  else saveState(frame.annotation_version ? "Draft saved" : "New frame", frame.annotation_version ? "ok" : "");
  restoreDraft();
}

// A crash or a closed tab leaves the latest changes in localStorage; bring them back.
function restoreDraft() {
  const draft = S.loadDraft(frame.id);
  if (!draft) return;
  const mine = S.fromServer(draft);
  if (draft.base === frame.annotation_version) {
    commit(mine);
    say("Restored your unsaved changes from this browser.");
  } else {
    banner(`This browser kept changes you made to an older version of this frame (${new Date(draft.savedAt)
      .toLocaleString()}).`, "Use my changes", () => commit(mine));
  }
}

// The frame's embedding is being computed by a worker: say so until it is there.
async function watchPreparing(detail) {
  $("preparing").hidden = detail.embedding_ready || !session;
  while (!$("preparing").hidden && frame === detail) {
    await sleep(READY_RECHECK_MS);
    const now = await api(`${API}/frames/${detail.id}`).catch(() => null);
    if (now?.embedding_ready && frame === detail) $("preparing").hidden = true;
  }
}

// The next frame of the video is the likely next one: have its image in the browser cache already.
function preloadNext(detail) {
  if (detail.next_id == null) return;
  setTimeout(() => api(`${API}/frames/${detail.next_id}`)
    .then((next) => { new Image().src = root.dataset.media + next.image; })
    .catch(() => {}), 500);
}

async function showEmpty() {
  frame = null;
  history = null;
  root.dataset.state = "empty";
  $("empty").hidden = false;
  $("frame-title").textContent = "Annotate";
  $("frame-info").textContent = "";
  $("preparing").hidden = true;
  banner(null);
  saveState("");
  say("All caught up: no approved frames are waiting.");
  view.setImage(null);
  render();
  while (root.dataset.state === "empty") {
    await sleep(QUEUE_RECHECK_MS);
    if (root.dataset.state === "empty" && !document.hidden) await checkQueue();
  }
}

async function checkQueue() {
  const res = await call(`${API}/queue/annotate/next`);
  if (res.ok) navigate(async () => res.data.frame_id);
}

// ---- editing ---------------------------------------------------------------------------------------

const current = () => S.pairOf(history.doc, ui.pair)?.[ui.kind] ?? null;

function editable() {
  if (session) return true;
  say(frame ? "This frame is read-only." : "No frame to annotate.", "error");
  return false;
}

function commit(doc) {
  history.push(doc);
  changed();
}

function edit(change) {
  if (!editable()) return;
  commit(S.setRegion(history.doc, ui.pair, ui.kind, S.region(change(current() ?? S.region()))));
}

function changed() {
  if (!S.pairOf(history.doc, ui.pair)) ui.pair = history.doc.pairs[0].id;
  render();
  persist();
  segmentStale();
}

// Every change goes to localStorage at once and to the server two seconds later (once the masks are in).
function persist() {
  if (!session) return;
  const doc = history.doc;
  if (doc === session.saved) {
    session.cancel();
    S.dropDraft(frame.id);
    saveState("Draft saved", "ok");
    return;
  }
  S.storeDraft(frame.id, session.version, doc, frame.height, frame.width);
  saveState("Unsaved changes");
  if (!S.staleRegions(doc).length) session.schedule(doc);
}

// Regions whose clicks changed get their mask from the server, one request at a time; clicks made
// meanwhile ride along with the next request.
async function segmentStale() {
  if (segmenting) return;
  segmenting = true;
  try {
    for (let next; history && (next = S.staleRegions(history.doc)[0]);) await segment(next);
  } finally {
    segmenting = false;
  }
  if (history) persist();
}

async function segment({ kind, region }) {
  const { id, width, height } = frame;
  const fresh = (runs) => history.swapRegion(region, S.region({ ...region, runs, stale: false }));
  if (!region.points.length && !region.box) return fresh(null);
  const body = { points: region.points.map((p) => [p.x, p.y]), labels: region.points.map((p) => p.label),
                 region_kind: kind };
  if (region.box) body.box = region.box;
  if (region.area) body.prev_mask = { size: [height, width], counts: encodeCounts(region.runs) };
  const started = performance.now();
  try {
    const result = await api(`${API}/frames/${id}/segment`, { method: "POST", body });
    if (frame?.id !== id) return;
    const ms = Math.round(performance.now() - started);
    fresh(runsOf(result.mask));
    $("timing").textContent = ms < 1000 ? `mask in ${ms} ms` : `mask in ${(ms / 1000).toFixed(1)} s`;
    $("timing").title = `${result.model_id}, score ${result.score.toFixed(2)}, `
      + `${result.embedding_cached ? "cached embedding" : "embedding computed on this click"}`;
    if (result.embedding_cached === false) $("preparing").hidden = true;
    say(result.area ? `${kind === "illusion" ? "Illusion" : "Support"} of ${pairName(ui.pair)}: `
      + `${result.area.toLocaleString()} px.` : "No mask at this click — try a point further inside.");
  } catch (err) {
    if (frame?.id !== id) return;
    fresh(region.runs);
    say(`Segmentation failed: ${err.message}`, "error");
  }
  render();
}

function strokeStart() {
  if (!editable()) return null;
  const r = current();
  const mask = r?.area ? fromRuns(r.runs, frame.height, frame.width) : new Uint8Array(frame.width * frame.height);
  stroke = new Layer(mask, frame.width, frame.height, S.colourOf(ui.pair), ui.kind === "support", true);
  render();
  return stroke;
}

function strokeEnd() {
  const runs = toRuns(stroke.mask, frame.height, frame.width);
  stroke = null;
  edit((r) => ({ ...r, runs, stale: false }));
  // the stroke is the latest word on this mask: an older failure or timing no longer applies
  $("timing").textContent = "";
  say(`${ui.kind === "illusion" ? "Illusion" : "Support"} of ${pairName(ui.pair)}: painted by hand.`);
}

function layerOf(pairId, kind, runs) {
  const colour = S.colourOf(pairId), hatched = kind === "support";
  let layer = layers.get(runs);
  if (!layer || layer.hex !== colour || layer.hatched !== hatched) {
    layer = new Layer(fromRuns(runs, frame.height, frame.width), frame.width, frame.height, colour, hatched);
    layer.hex = colour;
    layers.set(runs, layer);
  }
  return layer;
}

// ---- commands ---------------------------------------------------------------------------------------

function selectKind(kind) {
  ui.kind = kind;
  render();
  say(`${kind === "illusion" ? "Illusion" : "Support"} of ${pairName(ui.pair)}: `
    + (kind === "illusion" ? "click the flat thing that looks 3D." : "click the real surface it lies on."));
}

function setTool(tool) {
  view.tool = view.tool === tool && tool !== "click" ? "click" : tool;
  view.cursor();
  render();
}

function undoRedo(which) {
  if (!editable()) return;
  if (!history[which]()) return say(`Nothing to ${which}.`);
  changed();
  say(which === "undo" ? "Undone." : "Redone.");
}

async function submit() {
  if (!frame) return checkQueue();
  if (!session) return navigate(fromQueue);
  while (segmenting) await sleep(50);
  const doc = history.doc;
  const used = doc.pairs.filter((p) => p.illusion?.area || p.support?.area);
  if (!used.length) return say("Click the illusion first: there is nothing to submit yet.", "error");
  const noIllusion = used.find((p) => !p.illusion?.area);
  if (noIllusion) {
    selectPairId(noIllusion.id, "illusion");
    return say(`${pairName(noIllusion.id)} has a support region but no illusion: click the illusion.`, "error");
  }
  if (!doc.type) {
    const type = await ask($("type-dialog"));
    if (!type) return say("Not submitted: it needs an illusion type (T, or Enter again to choose).", "error");
    commit({ ...history.doc, type });
    return submit();
  }
  const noSupport = used.filter((p) => !p.support?.area);
  if (noSupport.length) {
    $("confirm-title").textContent = `${noSupport.map((p) => pairName(p.id)).join(", ").replace(/^p/, "P")} `
      + `${noSupport.length === 1 ? "has" : "have"} no support region — submit anyway?`;
    if (await ask($("confirm-dialog")) !== "yes") return say("Not submitted: add the support, or submit anyway.");
  }
  say("Submitting…");
  const res = await session.submit(history.doc);
  if (!res.ok) {
    if (res.status === 409) session.hooks.conflict(res.error);
    return say(res.error, "error");
  }
  S.dropDraft(frame.id);
  const done = frame.id;
  session = null;
  await navigate(fromQueue);
  if (frame && frame.id !== done) say(`Submitted frame #${done}. This is the next one.`, "ok");
}

async function deleteFrame() {
  if (!editable()) return;
  const reason = await ask($("delete-dialog"));
  if (!reason) return;
  const res = await call(`${API}/frames/${frame.id}/delete`, { body: { reason } });
  if (!res.ok) return say(res.error, "error");
  S.dropDraft(frame.id);
  const gone = frame.id;
  session.close();
  session = null;
  await navigate(fromQueue);
  say(`Deleted frame #${gone} (${reason}).`, "ok");
}

async function propagate() {
  if (!editable()) return;
  if (propagating) return say("A propagation is already running.");
  const pair = S.pairOf(history.doc, ui.pair);
  const regions = S.KINDS.filter((kind) => pair[kind]?.area).map((kind) => ({ kind, runs: pair[kind].runs }));
  if (!regions.length) return say(`${pairName(pair.id)} has no mask to propagate yet.`, "error");
  $("propagate-what").textContent = `${pairName(pair.id)}'s ${regions.map((r) => r.kind).join(" and ")}`;
  $("propagate-count").value = prefs.propagate;
  if (await ask($("propagate-dialog")) !== "go") return;
  const count = Math.min(100, Math.max(1, Number($("propagate-count").value) || 5));
  savePrefs({ propagate: count });
  propagating = true;
  $("propagation").hidden = false;
  const progress = (fraction, text) => {
    $("propagate-progress").value = fraction;
    $("propagate-text").textContent = text;
  };
  try {
    const { written, skipped } = await runPropagation({ api: API, jobs: root.dataset.jobs, frame, pair: pair.id,
                                                        regions, count, progress });
    say(`Propagated ${pairName(pair.id)} to ${plural(written.size, "frame")} as drafts`
      + (skipped.size ? ` (${skipped.size} skipped: submitted or held by someone else)` : "") + ". → to check them.", "ok");
  } catch (err) {
    say(err.message, "error");
  } finally {
    propagating = false;
    setTimeout(() => { if (!propagating) $("propagation").hidden = true; }, 4000);
  }
}

function selectPairId(id, kind = ui.kind) {
  ui.pair = id;
  ui.kind = kind;
  render();
}

function ask(dialog) {
  dialog.returnValue = "";
  dialog.showModal();
  return new Promise((resolve) => dialog.addEventListener("close", () => resolve(dialog.returnValue), { once: true }));
}

function setOpacity(value) {
  savePrefs({ opacity: Math.round(Math.min(1, Math.max(0.1, value)) * 100) / 100 });
  ui.hidden = false;
  render();
}

function setBrush(value) {
  savePrefs({ brush: Math.min(80, Math.max(1, Math.round(value))) });
  view.brush = prefs.brush;
  if (view.tool === "click") setTool("brush");
  render();
}

function savePrefs(values) {
  Object.assign(prefs, values);
  localStorage.setItem(PREFS, JSON.stringify(prefs));
}

const COMMANDS = {
  illusion: () => selectKind("illusion"),
  support: () => selectKind("support"),
  addPair: () => {
    if (!editable()) return;
    const [doc, id] = S.addPair(history.doc);
    selectPairId(id, "illusion");
    commit(doc);
    say(`Added ${pairName(id)}: click its illusion.`);
  },
  selectPair: (key) => {
    const pair = history?.doc.pairs[Number(key) - 1];
    if (pair) selectPairId(pair.id);
  },
  removePair: () => {
    if (!editable()) return;
    commit(S.removePair(history.doc, ui.pair));
    say(`Removed ${pairName(ui.pair)} (Ctrl+Z brings it back).`);
  },
  clear: () => {
    if (!editable() || !current()) return;
    commit(S.setRegion(history.doc, ui.pair, ui.kind, null));
    say(`Cleared the ${ui.kind} of ${pairName(ui.pair)} (Ctrl+Z brings it back).`);
  },
  clickTool: () => setTool("click"),
  brush: () => setTool("brush"),
  eraser: () => setTool("eraser"),
  brushSize: (key) => setBrush(key === "]" ? prefs.brush * 1.25 + 1 : prefs.brush / 1.25 - 1),
  undo: () => undoRedo("undo"),
  redo: () => undoRedo("redo"),
  zoom: (key) => view.zoomCentre(key === "-" ? 1 / 1.25 : 1.25),
  fit: () => view.fit(),
  opacity: (key) => setOpacity(prefs.opacity + (key === "o" ? 0.1 : -0.1)),
  hide: () => { ui.hidden = !ui.hidden; render(); },
  pickType: async () => {
    if (!editable()) return;
    const type = await ask($("type-dialog"));
    if (type) commit({ ...history.doc, type });
  },
  submit,
  step: (key) => navigate(() => (key === "ArrowLeft" ? frame?.prev_id : frame?.next_id)),
  propagate,
  deleteFrame,
  help: () => $("help").showModal(),
};

// ---- rendering ------------------------------------------------------------------------------------

function render() {
  const doc = history?.doc;
  root.dataset.readonly = String(!session);
  const scene = view.scene;
  scene.opacity = prefs.opacity;
  scene.hidden = ui.hidden;
  scene.layers = [];
  scene.points = [];
  scene.box = null;
  if (doc) {
    for (const kind of ["support", "illusion"]) {  // an illusion lies on its support: draw it on top
      for (const p of doc.pairs) {
        const active = p.id === ui.pair && kind === ui.kind;
        if (active && stroke) scene.layers.push({ layer: stroke, active });
        else if (p[kind]?.area) scene.layers.push({ layer: layerOf(p.id, kind, p[kind].runs), active });
      }
    }
    const r = current();
    scene.points = r?.points ?? [];
    scene.box = r?.box ?? null;
    scene.colour = S.colourOf(ui.pair);
  }
  view.render();
  renderPanel(doc);
}

function renderPanel(doc) {
  for (const b of document.querySelectorAll(".segmented [data-kind]")) b.setAttribute("aria-pressed", b.dataset.kind === ui.kind);
  for (const b of document.querySelectorAll(".tools [data-tool]")) b.setAttribute("aria-pressed", b.dataset.tool === view.tool);
  $("brush-size").value = prefs.brush;
  $("brush-size-value").textContent = `${prefs.brush} px`;
  $("opacity").value = prefs.opacity;
  $("opacity-value").textContent = ui.hidden ? "hidden" : `${Math.round(prefs.opacity * 100)}%`;
  $("illusion-type").value = doc?.type ?? "";
  const locked = !session;
  for (const id of ["add-pair", "illusion-type", "propagate", "delete"]) $(id).disabled = locked;
  $("submit").innerHTML = "";
  $("submit").append(frame && locked ? "Next from the queue " : "Submit ", el("kbd", {}, "Enter"));
  $("submit").disabled = !frame && root.dataset.state !== "empty";
  $("pairs").replaceChildren(...(doc?.pairs ?? []).map((p, i) => pairRow(p, i)));
}

function pairRow(pair, i) {
  const chip = (kind) => {
    const area = pair[kind]?.area ?? 0;
    const stale = pair[kind]?.stale;
    return el("button", {
      type: "button", className: `chip ${kind}`, dataset: { chip: kind, done: area ? "yes" : "no" },
      title: `${kind} of ${pairName(pair.id)}: ${area ? `${area.toLocaleString()} px` : "none yet"}`,
      ariaPressed: String(pair.id === ui.pair && kind === ui.kind),
    }, el("span", { className: "mark" }, stale ? "…" : area ? "✓" : "○"), ` ${kind}`);
  };
  return el("li", {
    className: "pair", dataset: { pair: pair.id }, ariaCurrent: pair.id === ui.pair ? "true" : "false",
    style: `--pair: ${S.colourOf(pair.id)}`,
  },
  el("span", { className: "swatch", ariaHidden: "true" }),
  el("span", { className: "name" }, `Plane ${pair.id}`, i < 9 ? el("kbd", {}, String(i + 1)) : ""),
  el("span", { className: "chips" }, chip("illusion"), chip("support")),
  pairType(pair),
  el("button", { type: "button", className: "remove", title: "Remove this plane (Backspace)",
                 ariaLabel: `Remove plane ${pair.id}` }, "×"));
}

// The pair's own illusion type; the first option follows the frame's type.
function pairType(pair) {
  const options = [...$("illusion-type").options].filter((o) => o.value)
    .map((o) => el("option", { value: o.value, selected: o.value === pair.type }, o.textContent));
  return el("select", {
    className: "pair-type", ariaLabel: `Illusion type of plane ${pair.id}`, disabled: !session,
    onclick: (event) => event.stopPropagation(),  // choosing a type is not selecting the pair
    onchange: (event) => { if (editable()) commit(S.setPairType(history.doc, pair.id, event.target.value || null)); },
  }, el("option", { value: "", selected: !pair.type }, "frame's type"), ...options);
}

// ---- wiring ----------------------------------------------------------------------------------------

document.addEventListener("keydown", (event) => {
  const open = document.querySelector("dialog[open]");
  if (open) {
    const choice = event.key.length === 1 && open.querySelector(`button[data-key="${event.key}"]`);
    if (choice) {
      event.preventDefault();
      open.close(choice.value);
    } else if (open.id === "help" && event.key === "?") {
      open.close();
    }
    return;
  }
  if (event.target.closest("input, select, textarea")) {
    if (event.key === "Escape") $("canvas").focus();
    return;
  }
  if (["Enter", " "].includes(event.key) && event.target.closest("button, a")) return;  // let them press
  const shortcut = shortcutFor(event);
  if (!shortcut || (!history && !["help", "submit"].includes(shortcut.command))) return;
  event.preventDefault();
  COMMANDS[shortcut.command](shortcut.key);
});

// Panel controls act like their keys, then hand the keyboard back to the canvas.
function onClick(target, run) {
  (typeof target === "string" ? $(target) : target).addEventListener("click", async (event) => {
    await run(event);
    if (!document.querySelector("dialog[open]")) $("canvas").focus({ preventScroll: true });
  });
}
onClick("prev-frame", () => COMMANDS.step("ArrowLeft"));
onClick("next-frame", () => COMMANDS.step("ArrowRight"));
onClick("help-button", COMMANDS.help);
onClick("add-pair", COMMANDS.addPair);
onClick("propagate", propagate);
onClick("submit", submit);
onClick("delete", deleteFrame);
onClick("check-again", checkQueue);
onClick("pairs", (event) => {
  const row = event.target.closest("[data-pair]");
  if (!row) return;
  const id = Number(row.dataset.pair);
  if (event.target.closest(".remove")) {
    selectPairId(id);
    return COMMANDS.removePair();
  }
  selectPairId(id, event.target.closest("[data-chip]")?.dataset.chip ?? ui.kind);
});
for (const b of document.querySelectorAll(".segmented [data-kind]")) onClick(b, () => selectKind(b.dataset.kind));
for (const b of document.querySelectorAll(".tools [data-tool]")) onClick(b, () => setTool(b.dataset.tool));
$("illusion-type").addEventListener("change", (event) => {
  if (editable()) commit({ ...history.doc, type: event.target.value || null });
  $("canvas").focus({ preventScroll: true });
});
$("opacity").addEventListener("input", (event) => setOpacity(Number(event.target.value)));
$("brush-size").addEventListener("input", (event) => setBrush(Number(event.target.value)));

window.addEventListener("popstate", (event) => {
  if (event.state?.id) navigate(async () => event.state.id, "none");
});
// Leaving: the lease goes back at once (keepalive outlives the page); the draft is in localStorage.
window.addEventListener("pagehide", () => session?.release());
// Back from the back/forward cache with the lease given away: take the frame up again.
window.addEventListener("pageshow", (event) => {
  if (event.persisted && frame) navigate(async () => frame.id, "replace");
});
document.addEventListener("visibilitychange", () => { if (document.hidden) session?.flush(); });

// Tests and the curious may look, read-only.
window.annotator = {
  get frame() { return root.dataset.state === "ready" ? frame : null; },
  get pairs() {
    return (history?.doc.pairs ?? []).map((p) => ({ id: p.id, illusion: p.illusion?.area ?? 0, support: p.support?.area ?? 0,
                                                   type: p.type ?? null }));
  },
  get dirty() { return Boolean(session && history.doc !== session.saved); },
  imageToClient: (x, y) => view.imageToClient(x, y),
};

renderHelp($("help-keys"));
render();
const start = Number(root.dataset.frameId);
navigate(start ? async () => start : fromQueue, "replace");
