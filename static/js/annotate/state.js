// The annotation of one frame as an immutable document, its undo history and its copy in this browser.
//
// doc    = { pairs: [{ id, type: "picture" | … | null, illusion: Region | null, support: Region | null }] }
//          (the illusion type belongs to each pair: a frame can hold a picture and a mirror)
// Region = { runs: COCO runs (column-major) | null, area, points: [{x, y, label}], box: [x0, y0, x1, y1] | null,
//            extra: other click entries kept as they came (e.g. {propagated_from}, {proposal_id}),
//            stale: mask lags the clicks }
// Every change makes a new doc that shares what did not change, so history is a list of docs and costs
// little, and "unchanged since the last save" is an identity check.
import { encodeCounts, runsOf, areaOf } from "./rle.js";

export const KINDS = ["illusion", "support"];
// Pair colours avoid green and red, which mark positive and negative clicks.
const COLOURS = ["#ff8a1f", "#22d3ee", "#a78bfa", "#facc15", "#f472b6", "#60a5fa"];
export const colourOf = (pairId) => COLOURS[((pairId - 1) % COLOURS.length + COLOURS.length) % COLOURS.length];

const HISTORY_LIMIT = 200;

const emptyDoc = () => ({ pairs: [{ id: 1, type: null, illusion: null, support: null }] });

export function region({ runs = null, points = [], box = null, extra = [], stale = false } = {}) {
  return { runs, area: runs ? areaOf(runs) : 0, points, box, extra, stale };
}

export const pairOf = (doc, id) => doc.pairs.find((p) => p.id === id);

export function setRegion(doc, pairId, kind, next) {
  return { ...doc, pairs: doc.pairs.map((p) => (p.id === pairId ? { ...p, [kind]: next } : p)) };
}

export function setPairType(doc, pairId, type) {
  return { ...doc, pairs: doc.pairs.map((p) => (p.id === pairId ? { ...p, type } : p)) };
}

// A new pair of the given type (the page passes the selected pair's).
export function addPair(doc, type = null) {
  const id = Math.max(0, ...doc.pairs.map((p) => p.id)) + 1;
  return [{ ...doc, pairs: [...doc.pairs, { id, type, illusion: null, support: null }] }, id];
}

// Gives a plane its masks and type (`fields`: { type, illusion, support }): the pair `pairId` when it
// holds nothing yet (a new frame's empty pair, a plane just added), else a new pair; [doc, its id].
// A null type keeps the pair's.
export function putPair(doc, pairId, fields) {
  const target = pairOf(doc, pairId);
  const [base, id] = target && isEmpty(target) ? [doc, pairId] : addPair(doc);
  return [{ ...base, pairs: base.pairs.map((p) => (p.id === id ? { ...p, ...fields, type: fields.type ?? p.type } : p)) }, id];
}

const isEmpty = (pair) => KINDS.every((k) => !pair[k] || (!pair[k].area && !pair[k].points.length && !pair[k].box));

// The ids of the proposals the document's regions came from (their {proposal_id} click entries).
export const proposalsIn = (doc) => new Set(doc.pairs.flatMap((p) => KINDS.flatMap((k) => p[k]?.extra ?? []))
  .map((entry) => entry?.proposal_id).filter(Number.isInteger));

export function removePair(doc, pairId) {
  const pairs = doc.pairs.filter((p) => p.id !== pairId);
  return { ...doc, pairs: pairs.length ? pairs : emptyDoc().pairs };
}

// Whether the document holds this very region object.
export const holds = (doc, region) => doc.pairs.some((p) => p.illusion === region || p.support === region);

// Replaces one region object wherever it occurs: a mask that arrives for a click belongs to every
// version of the document that holds that click, so undo never lands on a half-finished state.
function swapRegion(doc, old, next) {
  if (!holds(doc, old)) return doc;
  return { ...doc, pairs: doc.pairs.map((p) => ({ ...p, illusion: p.illusion === old ? next : p.illusion,
                                                        support: p.support === old ? next : p.support })) };
}

export function staleRegions(doc) {
  return doc.pairs.flatMap((p) => KINDS.filter((k) => p[k]?.stale).map((kind) => ({ pair: p.id, kind, region: p[kind] })));
}

export class History {
  constructor(doc) {
    this.doc = doc;
    this.past = [];
    this.future = [];
  }

  push(doc) {
    this.past.push(this.doc);
    if (this.past.length > HISTORY_LIMIT) this.past.shift();
    this.future = [];
    this.doc = doc;
  }

  undo() {
    if (!this.past.length) return false;
    this.future.push(this.doc);
    this.doc = this.past.pop();
    return true;
  }

  redo() {
    if (!this.future.length) return false;
    this.past.push(this.doc);
    this.doc = this.future.pop();
    return true;
  }

  swapRegion(old, next) {
    const swap = (d) => swapRegion(d, old, next);
    this.doc = swap(this.doc);
    this.past = this.past.map(swap);
    this.future = this.future.map(swap);
  }
}

// ---- to and from the server's form ------------------------------------------------------------

const counts = new WeakMap();  // runs → compressed string, computed once per mask

function compressed(runs) {
  if (!counts.has(runs)) counts.set(runs, encodeCounts(runs));
  return counts.get(runs);
}

// A stored region without a type of its own (saved before pairs had one) takes the annotation's.
export function fromServer(detail) {
  const doc = { pairs: [] };
  for (const r of detail.regions) {
    let pair = pairOf(doc, r.pair);
    if (!pair) doc.pairs.push(pair = { id: r.pair, illusion: null, support: null, type: null });
    pair.type ??= r.illusion_type ?? detail.illusion_type ?? null;
    const clicks = r.clicks ?? [];
    pair[r.kind] = region({
      runs: runsOf(r.mask),
      points: clicks.filter((c) => Number.isFinite(c?.x) && Number.isFinite(c?.y)),
      box: clicks.find((c) => Array.isArray(c?.box))?.box ?? null,
      extra: clicks.filter((c) => !Number.isFinite(c?.x) && !Array.isArray(c?.box)),
    });
  }
  doc.pairs.sort((a, b) => a.id - b.id);
  return doc.pairs.length ? doc : emptyDoc();
}

// The regions the API stores: every region with a mask (an empty one says nothing).
export function toServer(doc, height, width) {
  return doc.pairs.flatMap((p) => KINDS.filter((k) => p[k]?.area).map((kind) => {
    const r = p[kind];
    return { pair: p.id, kind, mask: { size: [height, width], counts: compressed(r.runs) },
             clicks: [...r.extra, ...r.points, ...(r.box ? [{ box: r.box }] : [])],
             ...(p.type ? { illusion_type: p.type } : {}) };
  }));
}

// ---- the copy in this browser -------------------------------------------------------------------
// Written on every change, so a crash or a closed tab between two server saves loses nothing.
// `base` is the server version the changes apply to: they are only restored onto that version.

const key = (frameId) => `illusion-studio:annotate:${frameId}`;

export function storeDraft(frameId, base, doc, height, width) {
  const draft = { base, savedAt: Date.now(), regions: toServer(doc, height, width) };
  try {
    localStorage.setItem(key(frameId), JSON.stringify(draft));
  } catch (err) {
    console.warn("could not keep the draft in this browser", err);  // storage full or disabled
  }
}

export function loadDraft(frameId) {
  try {
    return JSON.parse(localStorage.getItem(key(frameId)) ?? "null");
  } catch {
    return null;
  }
}

export const dropDraft = (frameId) => localStorage.removeItem(key(frameId));
