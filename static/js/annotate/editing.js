// Changes to the annotation and what follows each one: a redraw, the copy in this browser at once,
// the server's a moment later, and masks for the regions whose clicks changed. The panel's and the
// keys' edits of planes, regions and types are here too.
import { choose } from "../dialogs.js";
import { planeName, regionName, say, saveState } from "./messages.js";
import { $, current, page, ui } from "./page.js";
import { render } from "./render.js";
import { segmentStale } from "./segment.js";
import * as S from "./state.js";

export function editable() {
  if (page.session) return true;
  say(page.frame ? "This frame is read-only." : "No frame to annotate.", "error");
  return false;
}

export function commit(doc) {
  page.history.push(doc);
  changed();
}

// Changes the current region: `change(region)` returns its new fields.
export function edit(change) {
  if (!editable()) return;
  commit(S.setRegion(page.history.doc, ui.pair, ui.kind, S.region(change(current() ?? S.region()))));
}

function changed() {
  if (!S.pairOf(page.history.doc, ui.pair)) ui.pair = page.history.doc.pairs[0].id;
  render();
  persist();
  segmentStale();
}

// Every change goes to localStorage at once and to the server two seconds later (once the masks are in).
export function persist() {
  const { session, frame } = page;
  if (!session) return;
  const doc = page.history.doc;
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

export function undoRedo(which) {
  if (!editable()) return;
  if (!page.history[which]()) return say(`Nothing to ${which}.`);
  changed();
  say(which === "undo" ? "Undone." : "Redone.");
}

export function selectPair(id, kind = ui.kind) {
  ui.pair = id;
  ui.kind = kind;
  render();
}

export function selectKind(kind) {
  ui.kind = kind;
  render();
  say(`${regionName(kind, ui.pair)}: `
    + (kind === "illusion" ? "click the flat thing that looks 3D." : "click the real surface it lies on."));
}

export function addPair() {
  if (!editable()) return;
  const type = S.pairOf(page.history.doc, ui.pair)?.type ?? null;
  const [doc, id] = S.addPair(page.history.doc, type);
  selectPair(id, "illusion");
  commit(doc);
  say(`Added ${planeName(id)}${type ? ` (${type}; T changes it)` : ""}: click its illusion.`);
}

export function removePair() {
  if (!editable()) return;
  const name = planeName(ui.pair);
  commit(S.removePair(page.history.doc, ui.pair));
  say(`Removed ${name} (Ctrl+Z brings it back).`);
}

export function clearRegion() {
  if (!editable() || !current()) return;
  commit(S.setRegion(page.history.doc, ui.pair, ui.kind, null));
  say(`Cleared the ${ui.kind} of ${planeName(ui.pair)} (Ctrl+Z brings it back).`);
}

// A plane's illusion type (null: not chosen yet).
export function setType(type, pairId = ui.pair) {
  if (!editable()) return;
  commit(S.setPairType(page.history.doc, pairId, type));
}

// The type dialog for a plane (T: the selected one; a submit: the first without a type); resolves
// to the type chosen, "" when cancelled.
export async function pickType(pairId = ui.pair) {
  if (!editable()) return "";
  $("type-title").textContent = `Illusion type of ${planeName(pairId)}`;
  const type = await choose($("type-dialog"));
  if (type) setType(type, pairId);
  return type;
}
