// The machine's proposals for the frame on screen (GET /frames/{id}: `proposals`, computed ahead by
// the propose job), shown as dashed outlines while the annotator holds the frame. Accepting one makes
// it a plane of the annotation, with the proposal's masks and type and {proposal_id} among both
// regions' clicks: the annotator's work from then on, corrected with clicks like any mask, and an
// undo brings the proposal back. Rejecting one tells the server at once. Proposals stay outside the
// annotation's history: one the document took is simply not shown. One is highlighted at a time, the
// best first; the keys act on it. Those scoring under the threshold in force when the frame was scanned
// (`hidden`) are left out unless the annotator asks to see all (V, or the panel's "Show all"); left
// untouched, they get the fate `hidden` on submit, which is no verdict on them.
import { plural } from "../labels.js";
import { call } from "../request.js";
import { sessionEnded } from "../session_ended.js";
import { commit, editable, selectPair } from "./editing.js";
import { planeName, say } from "./messages.js";
import { API, page, ui } from "./page.js";
import { outlineOf } from "./outline.js";
import { render } from "./render.js";
import { fromRuns, runsOf } from "./rle.js";
import * as S from "./state.js";

// frame: the id they belong to; all: every proposal the frame had, whatever its fate; items: the
// pending ones, best first; note: why there are none (the server's words); ready: every proposer has
// looked; rejected: ids rejected here (a lookup already under way must not bring them back);
// highlight: the highlighted one's id; showAll: the hidden ones shown too (kept from frame to frame).
const offer = { frame: null, all: [], items: [], note: "", ready: true, rejected: new Set(), highlight: null,
                showAll: false };
const outlines = new Map();  // proposal id → { illusion, support } outlines of the frame on screen

// Takes the proposals of a frame detail: when the frame opens, and each time it is looked up again.
export function offerProposals(detail) {
  if (offer.frame !== detail.id) {
    outlines.clear();
    Object.assign(offer, { frame: detail.id, rejected: new Set(), highlight: null });
  }
  offer.all = detail.proposals ?? [];
  offer.items = offer.all.filter((p) => p.fate === "pending");
  offer.note = detail.proposals_note ?? "";
  offer.ready = detail.proposals_ready ?? true;
}

// The first words on a fresh frame with proposals; null without.
export function proposalsHint() {
  const n = offer.items.filter(isShown).length, more = hiddenLeft();
  if (!n) {
    return more ? `${plural(more, "proposal")} ${under()} hidden: V shows them — or click inside the illusion.` : null;
  }
  const also = more ? ` (V shows ${more} more ${under()})` : "";
  return `${plural(n, "proposal")} dashed on the frame${also}: A accepts the highlighted one, R rejects it, Tab goes on — `
    + "or click inside the illusion.";
}

const isShown = (p) => offer.showAll || !p.hidden;
// The threshold in force when the frame was scanned, "0.50" (each proposer's, "0.50 / 0.30", if they differ).
const threshold = () => [...new Set(offer.all.map((p) => p.threshold.toFixed(2)))].join(" / ");
const under = () => `under the threshold ${threshold()}`;
// How many pending proposals under the threshold "show all" would add (none taken or rejected here).
function hiddenLeft() {
  if (offer.showAll) return 0;
  const taken = page.history ? S.proposalsIn(page.history.doc) : new Set();
  return offer.items.filter((p) => p.hidden && !taken.has(p.id) && !offer.rejected.has(p.id)).length;
}
export const showingAll = () => offer.showAll;

// V (or the panel's "Show all"): the proposals under the threshold shown too, or hidden again.
export function toggleShowAll() {
  offer.showAll = !offer.showAll;
  render();
  const n = offer.items.filter((p) => p.hidden).length;
  say(offer.showAll ? `Showing all proposals: ${plural(n, "proposal")} ${under()} too.`
    : `Showing the proposals scoring ${threshold()} or more only.`);
}

// Whether proposals are still being computed for a frame this annotator holds (worth looking again).
export const awaitingProposals = () => Boolean(page.session) && !offer.ready;

// The proposals on show: pending, at or above the threshold (all with "show all"), not rejected here, not
// taken into the annotation; none read-only.
export function shownProposals() {
  if (!page.session || offer.frame !== page.frame?.id) return [];
  const taken = S.proposalsIn(page.history.doc);
  return offer.items.filter((p) => isShown(p) && !taken.has(p.id) && !offer.rejected.has(p.id));
}

export const highlighted = (shown = shownProposals()) => shown.find((p) => p.id === offer.highlight) ?? shown[0] ?? null;

// "plane-break 0.93 · picture"
export const proposalLabel = (p) => `${p.source} ${p.score.toFixed(2)} · ${p.illusion_type ?? "type?"}`
  + (p.hidden ? ` · under ${p.threshold.toFixed(2)}` : "");

// The panel's line about them: why there are none, or how to go through them.
export function proposalsNote(shown) {
  const note = offer.note ? offer.note.charAt(0).toUpperCase() + offer.note.slice(1) : "";
  if (!offer.ready) return note || "Proposals are being computed…";
  if (shown.length) return note || "Dashed on the frame; Tab highlights the next one.";
  if (note) return note;
  const more = hiddenLeft();
  if (more) return `${plural(more, "proposal")} ${under()} ${more === 1 ? "is" : "are"} hidden: V shows them.`;
  return offer.all.length ? decidedNote() : "The proposers found nothing in this frame.";
}

// None left to decide, though the frame had some: how many, and what became of them (here, before a
// reload, or when the frame was submitted before a curator sent it back).
function decidedNote() {
  const taken = page.history ? S.proposalsIn(page.history.doc) : new Set();
  const took = offer.all.filter((p) => taken.has(p.id) || ["accepted", "edited"].includes(p.fate)).length;
  const hidden = offer.all.filter((p) => p.fate === "hidden").length, rejected = offer.all.length - took - hidden;
  const fates = [took && `${took} taken as ${took === 1 ? "a plane" : "planes"}`, rejected && `${rejected} rejected`,
                 hidden && `${hidden} left hidden`].filter(Boolean);
  return `The proposers found ${plural(offer.all.length, "proposal")} in this frame; none is left to decide: ${fates.join(", ")}.`;
}

// What the canvas draws: each shown proposal's outlines and label, the highlighted one last (on top).
export function proposalOutlines() {
  const shown = shownProposals(), chosen = highlighted(shown);
  return shown.filter((p) => p !== chosen).concat(chosen ?? []).flatMap((p) => {
    const drawn = outlinesOf(p);
    return drawn.illusion ? [{ ...drawn, label: proposalLabel(p), highlighted: p === chosen }] : [];
  });
}

function outlinesOf(p) {
  if (!outlines.has(p.id)) {
    const { height, width } = page.frame;
    const of = (rle) => outlineOf(fromRuns(runsOf(rle), height, width), width, height);
    outlines.set(p.id, { illusion: of(p.illusion), support: of(p.support) });
  }
  return outlines.get(p.id);
}

export function highlightProposal(id) {
  offer.highlight = id;
  render();
}

// Tab (1) / Shift+Tab (-1): the next or previous proposal, round the list.
export function cycleProposal(step) {
  const shown = shownProposals();
  if (!shown.length) return;
  const at = (shown.indexOf(highlighted(shown)) + step + shown.length) % shown.length;
  highlightProposal(shown[at].id);
  say(`Proposal ${at + 1} of ${shown.length}: ${proposalLabel(shown[at])} — A accepts it, R rejects it.`);
}

// The one to highlight once `id` goes: the one after it, else the one before.
function successor(shown, id) {
  const at = shown.findIndex((p) => p.id === id);
  return (shown[at + 1] ?? shown[at - 1])?.id ?? null;
}

// A (or the panel's Accept): a plane with the proposal's masks and type, selected so clicks correct it
// (segment.js sends the mask along with them).
export function acceptProposal(id = highlighted()?.id) {
  if (!editable()) return;
  const shown = shownProposals();
  const proposal = shown.find((p) => p.id === id);
  if (!proposal) return say("No proposal to accept.", "error");
  const masks = Object.fromEntries(S.KINDS.map((kind) => {
    const region = S.region({ runs: runsOf(proposal[kind]), extra: [{ proposal_id: proposal.id }] });
    return [kind, region.area ? region : null];
  }));
  const [doc, pairId] = S.putPair(page.history.doc, ui.pair, { type: proposal.illusion_type ?? null, ...masks });
  offer.highlight = successor(shown, proposal.id);
  selectPair(pairId, "illusion");
  commit(doc);
  const type = S.pairOf(doc, pairId).type ? "" : "; T gives its type";
  say(`Accepted ${proposalLabel(proposal)} as ${planeName(pairId)} — click to correct it${type}.`, "ok");
}

// R (or the panel's Reject): gone from the page at once, the server told; back if it refuses.
export async function rejectProposal(id = highlighted()?.id) {
  if (!editable()) return;
  const shown = shownProposals();
  const proposal = shown.find((p) => p.id === id);
  if (!proposal) return say("No proposal to reject.", "error");
  const frame = page.frame;
  offer.rejected.add(proposal.id);
  offer.highlight = successor(shown, proposal.id);
  render();
  const next = highlighted();
  say(`Rejected ${proposalLabel(proposal)}.${next ? ` Next: ${proposalLabel(next)}.` : ""}`);
  const res = await call(`${API}/frames/${frame.id}/proposals/${proposal.id}/reject`, { body: {} });
  if (res.ok || page.frame !== frame) return;
  offer.rejected.delete(proposal.id);
  offer.highlight = proposal.id;
  render();
  if (!sessionEnded(res.error)) say(`Could not reject ${proposalLabel(proposal)}: ${res.error.message}`, "error");
}

// Tab belongs to the proposals while there are some and the keyboard is not on one of the page's controls.
export const wantsTab = (event) => shownProposals().length > 0 && !event.target.closest("button, a, summary");
