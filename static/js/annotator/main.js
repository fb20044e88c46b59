// The annotation page: clicks → masks for illusion/support pairs, touch-ups, drafts, submit.
import { api } from "../api.js";
import { area, maskToRle, rleToMask } from "./rle.js";
import { PAIR_COLOURS, View } from "./view.js";

const root = document.getElementById("annotate");
const API = root.dataset.api;
const LEASE_S = Number(root.dataset.leaseS);
const $ = (id) => document.getElementById(id);
const status = $("status");
const view = new View($("canvas"));
const csrf = document.querySelector('meta[name="csrf-token"]').content;

let frame = null;          // GET /frames/{id}
let pairs = [];            // [{illusion: Region, support: Region}]
let current = { pair: 0, kind: "illusion" };
let tool = "click";        // click | brush | eraser
let brush = 12;            // radius in image pixels
let undo = [], redo = [];
let readOnly = false;
let dirty = false;
let saveTimer = null;
let leaseTimer = null;

const emptyRegion = () => ({ mask: null, points: [], box: null });
const region = () => pairs[current.pair][current.kind];

function say(text, kind = "info") {
  status.textContent = text;
  status.className = `status ${kind}`;
}

// --- loading -------------------------------------------------------------------------------

async function open(frameId) {
  clearTimeout(saveTimer);
  if (dirty) await saveDraft();
  const detail = await api(`${API}/frames/${frameId}`);
  let lease = detail.lease.mine;
  if (!lease && !detail.lease.held_by_other && !detail.submitted && detail.state === "approved") {
    lease = await api(`${API}/frames/${frameId}/lease`, { method: "POST" }).then(() => true, () => false);
  }
  frame = detail;
  readOnly = !lease;
  history.replaceState(null, "", `/annotate/${frame.id}`);
  pairs = [];
  for (const r of detail.regions) {
    while (pairs.length <= r.pair) pairs.push({ illusion: emptyRegion(), support: emptyRegion() });
    const points = (r.clicks || []).filter((c) => Array.isArray(c)).map((c) => [...c]);
    pairs[r.pair][r.kind] = { mask: rleToMask(r.mask), points, box: null };
  }
  if (!pairs.length) pairs.push({ illusion: emptyRegion(), support: emptyRegion() });
  restoreLocalDraft();
  current = { pair: 0, kind: "illusion" };
  undo = [];
  redo = [];
  $("illusion-type").value = detail.illusion_type ?? $("illusion-type").value ?? "";
  const image = new Image();
  image.src = root.dataset.media + detail.image;
  await image.decode();
  view.setImage(image);
  recompose();
  renderPanel();
  $("frame-info").textContent = `frame #${frame.id} · video ${frame.video_id} · index ${frame.index} · ${frame.time_s.toFixed(2)} s · ${frame.width}×${frame.height}`;
  $("prepare-note").hidden = detail.embedding_ready || readOnly;
  $("preview-link").href = `/frames/${frame.id}/preview`;
  say(readOnly ? (detail.lease.held_by_other ? "Someone else is annotating this frame: read-only."
    : `This frame is ${detail.state}: read-only.`) : "Click inside the illusion; right-click to exclude.",
  readOnly ? "warn" : "info");
  clearInterval(leaseTimer);
  if (!readOnly) leaseTimer = setInterval(renewLease, (LEASE_S / 3) * 1000);
}

async function next() {
  try {
    const { frame_id: id } = await api(`${API}/queue/annotate/next`, { method: "POST" });
    await open(id);
  } catch (err) {
    frame = null;
    view.image = null;
    view.draw();
    say(/no approved frames/.test(err.message) ? "All done — no approved frames are waiting. 🎉" : err.message, "done");
  }
}

async function renewLease() {
  try {
    await api(`${API}/frames/${frame.id}/lease`, { method: "POST" });
  } catch (err) {
    readOnly = true;
    say(`${err.message} — press N for another frame.`, "error");
  }
}

// --- regions ---------------------------------------------------------------------------------

function snapshot() {
  const r = region();
  undo.push({ at: { ...current }, region: { mask: r.mask && r.mask.slice(), points: r.points.map((p) => [...p]), box: r.box } });
  if (undo.length > 50) undo.shift();
  redo = [];
}

function restore(from, to) {
  const step = from.pop();
  if (!step) return;
  const r = pairs[step.at.pair][step.at.kind];
  to.push({ at: step.at, region: { mask: r.mask && r.mask.slice(), points: r.points.map((p) => [...p]), box: r.box } });
  pairs[step.at.pair][step.at.kind] = step.region;
  current = { ...step.at };
  changed();
}

function changed() {
  dirty = true;
  recompose();
  renderPanel();
  storeLocalDraft();
  clearTimeout(saveTimer);
  saveTimer = setTimeout(saveDraft, 2000);
}

function recompose() {
  const list = [];
  pairs.forEach((p, i) => ["support", "illusion"].forEach((kind) => p[kind].mask && list.push({ pair: i, kind, mask: p[kind].mask })));
  view.compose(list);
  const r = frame ? region() : null;
  view.draw({ points: r?.points ?? [], box: r?.box ?? null, brush: view.marks?.brush });
}

async function segment() {
  const r = region();
  if (!r.points.some((p) => p[2] === 1) && !r.box) {
    r.mask = null;
    changed();
    return;
  }
  const body = { points: r.points.map(([x, y]) => [x, y]), labels: r.points.map((p) => p[2]), region_kind: current.kind };
  if (r.box) body.box = r.box;
  if (r.mask && r.points.length > 1) body.prev_mask = maskToRle(r.mask, frame.height, frame.width);
  const started = performance.now();
  const at = { ...current };
  try {
    const result = await api(`${API}/frames/${frame.id}/segment`, { method: "POST", body });
    pairs[at.pair][at.kind].mask = rleToMask(result.mask);
    const ms = Math.round(performance.now() - started);
    say(`mask in ${ms} ms · ${result.area.toLocaleString()} px${result.embedding_cached ? "" : " (this frame was prepared on the click)"}`);
    $("prepare-note").hidden = true;
    changed();
  } catch (err) {
    say(err.message, "error");
  }
}

function paint(x, y, value) {
  const r = region();
  if (!r.mask) r.mask = new Uint8Array(frame.width * frame.height);
  const x0 = Math.max(0, Math.floor(x - brush)), x1 = Math.min(frame.width - 1, Math.ceil(x + brush));
  const y0 = Math.max(0, Math.floor(y - brush)), y1 = Math.min(frame.height - 1, Math.ceil(y + brush));
  for (let yy = y0; yy <= y1; yy++) {
    for (let xx = x0; xx <= x1; xx++) {
      if ((xx - x) ** 2 + (yy - y) ** 2 <= brush * brush) r.mask[yy * frame.width + xx] = value;
    }
  }
}

// --- saving ----------------------------------------------------------------------------------

function payloadRegions() {
  const out = [];
  pairs.forEach((p, i) => ["illusion", "support"].forEach((kind) => {
    const r = p[kind];
    if (r.mask && area(r.mask)) out.push({ pair: i, kind, mask: maskToRle(r.mask, frame.height, frame.width), clicks: r.points });
  }));
  return out;
}

const localKey = () => `illusion-studio:draft:${frame.id}`;

function storeLocalDraft() {
  // Written on every change, so a crash or a closed tab between server saves loses nothing.
  try {
    localStorage.setItem(localKey(), JSON.stringify({ base: frame.annotation_version, regions: payloadRegions(),
      illusion_type: $("illusion-type").value }));
  } catch { /* storage full or disabled: the server draft still holds */ }
}

function restoreLocalDraft() {
  const raw = localStorage.getItem(localKey());
  if (!raw) return;
  const local = JSON.parse(raw);
  if (local.base !== frame.annotation_version || readOnly) {
    localStorage.removeItem(localKey());  // the server moved on: its version wins
    return;
  }
  pairs = [];
  for (const r of local.regions) {
    while (pairs.length <= r.pair) pairs.push({ illusion: emptyRegion(), support: emptyRegion() });
    pairs[r.pair][r.kind] = { mask: rleToMask(r.mask), points: r.clicks, box: null };
  }
  if (!pairs.length) pairs.push({ illusion: emptyRegion(), support: emptyRegion() });
  if (local.illusion_type) frame.illusion_type = local.illusion_type;
  dirty = true;
}

async function save(submit) {
  const body = { version: frame.annotation_version, regions: payloadRegions(), submit,
    illusion_type: $("illusion-type").value || null };
  const result = await api(`${API}/frames/${frame.id}/annotation`, { method: "POST", body });
  frame.annotation_version = result.annotation_version;
  dirty = false;
  localStorage.removeItem(localKey());
  return result;
}

async function saveDraft() {
  if (!frame || readOnly || !dirty) return;
  try {
    await save(false);
    $("saved").textContent = `draft saved ${new Date().toLocaleTimeString()}`;
  } catch (err) {
    say(`draft not saved: ${err.message}`, "error");
  }
}

async function submit() {
  if (readOnly) return say("read-only frame: nothing to submit", "warn");
  if (!$("illusion-type").value) {
    $("illusion-type").focus();
    return say("Choose the illusion type first (T).", "warn");
  }
  const missing = pairs.map((p, i) => (p.illusion.mask && area(p.illusion.mask) && !(p.support.mask && area(p.support.mask)) ? i + 1 : 0)).filter(Boolean);
  if (missing.length && !confirm(`Pair ${missing.join(", ")} has no support region — the wall around the illusion will be used. Submit anyway?`)) return;
  clearTimeout(saveTimer);
  try {
    await save(true);
    clearInterval(leaseTimer);
    say("Submitted — generating its sample. Next frame…", "ok");
    await next();
  } catch (err) {
    say(err.message, "error");
  }
}

async function deleteFrame(reason) {
  $("delete-dialog").close();
  try {
    await api(`${API}/frames/${frame.id}/delete`, { method: "POST", body: { reason } });
    dirty = false;
    localStorage.removeItem(localKey());
    await next();
  } catch (err) {
    say(err.message, "error");
  }
}

async function propagate() {
  const r = region();
  if (!r.mask || !area(r.mask)) return say("Nothing to propagate: this region has no mask yet.", "warn");
  const count = Number($("propagate-count").value) || 5;
  const bar = $("propagate-progress");
  try {
    const job = await api(`${API}/frames/${frame.id}/propagate`, { method: "POST",
      body: { pair: current.pair, kind: current.kind, mask: maskToRle(r.mask, frame.height, frame.width), count } });
    bar.hidden = false;
    for (;;) {
      await new Promise((resolve) => setTimeout(resolve, 500));
      const state = await api(`${root.dataset.jobs}/${job.id}`);
      bar.value = state.progress;
      if (state.state === "succeeded") {
        say(`Propagated to ${state.result.frames.length} frame(s) as drafts${state.result.skipped.length ? `, ${state.result.skipped.length} skipped (submitted or held)` : ""}.`, "ok");
        break;
      }
      if (["failed", "interrupted"].includes(state.state)) {
        say(`Propagation failed: ${state.error}`, "error");
        break;
      }
    }
  } catch (err) {
    say(err.message, "error");
  } finally {
    bar.hidden = true;
  }
}

// --- panel -----------------------------------------------------------------------------------

function renderPanel() {
  const list = $("pairs");
  list.replaceChildren(...pairs.map((p, i) => {
    const li = document.createElement("li");
    const [r, g, b] = PAIR_COLOURS[i % PAIR_COLOURS.length];
    li.style.setProperty("--pair", `rgb(${r} ${g} ${b})`);
    li.dataset.pair = i;
    for (const kind of ["illusion", "support"]) {
      const button = document.createElement("button");
      const px = p[kind].mask ? area(p[kind].mask) : 0;
      button.type = "button";
      button.className = `region ${kind}` + (current.pair === i && current.kind === kind ? " current" : "");
      button.dataset.kind = kind;
      button.textContent = `${kind} ${px ? `· ${px.toLocaleString()} px` : "· —"}`;
      button.addEventListener("click", () => { current = { pair: i, kind }; recompose(); renderPanel(); });
      li.append(button);
    }
    const title = document.createElement("span");
    title.className = "pair-title";
    title.textContent = `Pair ${i + 1}`;
    li.prepend(title);
    return li;
  }));
  $("mode").textContent = `${current.kind} · pair ${current.pair + 1} · ${tool}${tool === "click" ? "" : ` r=${brush}px`}`;
  $("opacity").value = view.opacity;
}

// --- input -----------------------------------------------------------------------------------

const canvas = $("canvas");
let drag = null;
let spaceDown = false;

canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  view.zoomAt(e.clientX, e.clientY, Math.exp(-e.deltaY * 0.0015));
}, { passive: false });

canvas.addEventListener("pointerdown", (e) => {
  if (!frame) return;
  canvas.setPointerCapture(e.pointerId);
  const [x, y] = view.clientToImage(e.clientX, e.clientY);
  if (e.button === 1 || spaceDown) {
    drag = { kind: "pan", last: [e.clientX, e.clientY] };
  } else if (readOnly) {
    drag = null;
  } else if (tool !== "click" && e.button === 0) {
    snapshot();
    drag = { kind: "paint" };
    paint(x, y, tool === "brush" ? 1 : 0);
    recompose();
  } else {
    drag = { kind: "click", start: [x, y], client: [e.clientX, e.clientY], negative: e.button === 2 || e.altKey };
  }
});

canvas.addEventListener("pointermove", (e) => {
  const [x, y] = view.clientToImage(e.clientX, e.clientY);
  if (tool !== "click") view.draw({ ...view.marks, brush: [x, y, brush] });
  if (!drag) return;
  if (drag.kind === "pan") {
    view.pan(e.clientX - drag.last[0], e.clientY - drag.last[1]);
    drag.last = [e.clientX, e.clientY];
  } else if (drag.kind === "paint") {
    paint(x, y, tool === "brush" ? 1 : 0);
    recompose();
  } else if (drag.kind === "click" && Math.hypot(e.clientX - drag.client[0], e.clientY - drag.client[1]) > 6 && !drag.negative) {
    drag.box = [Math.min(drag.start[0], x), Math.min(drag.start[1], y), Math.max(drag.start[0], x), Math.max(drag.start[1], y)];
    view.draw({ ...view.marks, box: drag.box });
  }
});

canvas.addEventListener("pointerup", (e) => {
  const d = drag;
  drag = null;
  if (!d || !frame) return;
  if (d.kind === "paint") return changed();
  if (d.kind !== "click") return;
  const [x, y] = d.start;
  if (x < 0 || y < 0 || x > frame.width - 1 || y > frame.height - 1) return;
  snapshot();
  const r = region();
  if (d.box) r.box = d.box.map((v, i) => Math.max(0, Math.min(v, i % 2 ? frame.height - 1 : frame.width - 1)));
  else r.points.push([Math.round(x * 10) / 10, Math.round(y * 10) / 10, d.negative ? 0 : 1]);
  recompose();
  segment();
});

const KEYS = {
  i: () => setKind("illusion"), s: () => setKind("support"),
  n: () => { if (frame && !readOnly) { pairs.push({ illusion: emptyRegion(), support: emptyRegion() }); current = { pair: pairs.length - 1, kind: "illusion" }; renderPanel(); recompose(); } },
  b: () => setTool(tool === "brush" ? "click" : "brush"), e: () => setTool(tool === "eraser" ? "click" : "eraser"),
  "[": () => { brush = Math.max(1, Math.round(brush / 1.3)); renderPanel(); },
  "]": () => { brush = Math.min(400, Math.round(brush * 1.3) + 1); renderPanel(); },
  o: () => setOpacity(view.opacity + 0.15), O: () => setOpacity(view.opacity - 0.15),
  0: () => view.fit(), t: () => $("illusion-type").focus(), p: () => propagate(),
  x: () => !readOnly && $("delete-dialog").showModal(), Delete: () => !readOnly && $("delete-dialog").showModal(),
  Enter: () => submit(), ArrowLeft: () => frame?.prev_id && open(frame.prev_id), ArrowRight: () => frame?.next_id && open(frame.next_id),
  N: () => next(), "?": () => $("help").showModal(),
  Escape: () => { if (frame && !readOnly) { snapshot(); const r = region(); r.points = []; r.box = null; r.mask = null; changed(); } },
};

function setKind(kind) { current = { ...current, kind }; renderPanel(); recompose(); }
function setTool(next) { tool = next; canvas.dataset.tool = tool; renderPanel(); }
function setOpacity(value) { view.opacity = Math.min(1, Math.max(0.05, value)); renderPanel(); view.draw(); }

document.addEventListener("keydown", (e) => {
  if (e.target.closest("input, select, textarea") && e.key !== "Escape") return;
  if (document.querySelector("dialog[open]")) {
    const dialog = document.querySelector("dialog[open]");
    if (dialog.id === "delete-dialog" && (e.key === "1" || e.key === "2")) deleteFrame(e.key === "1" ? "redundant" : "imperceptible");
    return;
  }
  if (e.key === " ") { spaceDown = true; e.preventDefault(); return; }
  if ((e.ctrlKey || e.metaKey) && (e.key === "z" || e.key === "Z" || e.key === "y")) {
    e.preventDefault();
    if (readOnly) return;
    if (e.key === "y" || e.shiftKey) restore(redo, undo); else restore(undo, redo);
    return;
  }
  if (/^[1-9]$/.test(e.key)) {
    const index = Number(e.key) - 1;
    if (index < pairs.length) { current = { ...current, pair: index }; renderPanel(); recompose(); }
    return;
  }
  const action = KEYS[e.key];
  if (action && !e.ctrlKey && !e.metaKey) { e.preventDefault(); action(); }
});
document.addEventListener("keyup", (e) => { if (e.key === " ") spaceDown = false; });

$("illusion-type").addEventListener("change", () => { dirty = true; storeLocalDraft(); clearTimeout(saveTimer); saveTimer = setTimeout(saveDraft, 2000); });
$("opacity").addEventListener("input", (e) => setOpacity(Number(e.target.value)));
$("submit").addEventListener("click", submit);
$("skip").addEventListener("click", next);
$("add-pair").addEventListener("click", KEYS.n);
$("propagate").addEventListener("click", propagate);
$("delete").addEventListener("click", KEYS.x);
for (const button of document.querySelectorAll("#delete-dialog [data-reason]")) {
  button.addEventListener("click", () => deleteFrame(button.dataset.reason));
}
window.addEventListener("pagehide", () => {
  if (!frame || readOnly) return;
  if (dirty) storeLocalDraft();
  // keepalive lets the request outlive the page; sendBeacon could not carry the CSRF header.
  fetch(`${API}/frames/${frame.id}/lease/release`, { method: "POST", keepalive: true,
    headers: { "X-CSRFToken": csrf, "Content-Type": "application/json" }, body: "{}" });
});

// A read-only handle for tests and the curious: where an image pixel is on screen, and the state.
window.annotator = {
  imageToClient: (x, y) => view.imageToClient(x, y),
  get frame() { return frame; },
  get pairs() { return pairs.map((p) => ({ illusion: p.illusion.mask ? area(p.illusion.mask) : 0, support: p.support.mask ? area(p.support.mask) : 0 })); },
  get dirty() { return dirty; },
};

if (root.dataset.frameId) open(Number(root.dataset.frameId)).catch((err) => say(err.message, "error"));
else next();
