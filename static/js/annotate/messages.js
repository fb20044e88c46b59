// What the page tells the annotator: the status line, the banner over the stage with its one
// action, the save state in the header, and the names of planes and regions in all of them.
import { $, page } from "./page.js";

export function say(text, kind = "info") {
  $("message").textContent = text.charAt(0).toUpperCase() + text.slice(1);  // server messages start lowercase
  $("status").dataset.kind = kind;
}

export function banner(text, action, run) {
  $("banner").hidden = !text;
  $("banner-text").textContent = text ?? "";
  $("banner-action").hidden = !action;
  $("banner-action").textContent = action ?? "";
  $("banner-action").onclick = run ? () => { banner(null); run(); } : null;
}

export function saveState(text, kind = "") {
  $("save-state").textContent = text;
  $("save-state").dataset.kind = kind;
}

// Planes are numbered 1, 2, … in the order the panel lists them (and the keys 1–9 pick them),
// whatever ids the server stored: the demo's start at 0.
const planeNumber = (id) => page.history.doc.pairs.findIndex((p) => p.id === id) + 1;
export const planeName = (id) => `plane ${planeNumber(id)}`;
export const regionName = (kind, id) => `${kind === "illusion" ? "Illusion" : "Support"} of ${planeName(id)}`;
