// What the parts of the Annotate page share: its root element and settings, the frame on screen
// with its annotation history and the session holding it, the selected plane and region, and the
// view preferences this browser keeps.
import * as S from "./state.js";

export const $ = (id) => document.getElementById(id);
export const root = $("annotate");
export const API = root.dataset.api;
export const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

export const page = {
  frame: null,     // GET /frames/{id} of the frame on screen
  history: null,   // S.History of its annotation
  session: null,   // FrameSession while this annotator holds the frame; null = read-only
  stroke: null,    // the Layer being brushed
};
export const ui = { pair: 1, kind: "illusion", hidden: false };

const PREFS = "illusion-studio:annotate:prefs";
export const prefs = { opacity: 0.5, brush: 8, propagate: 5, ...JSON.parse(localStorage.getItem(PREFS) ?? "{}") };

export function savePrefs(values) {
  Object.assign(prefs, values);
  localStorage.setItem(PREFS, JSON.stringify(prefs));
}

// The region being edited: the selected kind of the selected plane.
export const current = () => S.pairOf(page.history.doc, ui.pair)?.[ui.kind] ?? null;
