// The canvas and its tools: a click or a box adds to the current region's prompts (segment.js turns
// them into its mask), the brush and the eraser paint its mask by hand; and the view settings the
// panel and the keys change (tool, brush size, mask opacity, masks hidden).
import { View } from "./canvas.js";
import { edit, editable } from "./editing.js";
import { Layer } from "./layers.js";
import { regionName, say } from "./messages.js";
import { $, current, page, prefs, savePrefs, ui } from "./page.js";
import { render } from "./render.js";
import { fromRuns, toRuns } from "./rle.js";
import * as S from "./state.js";

export const view = new View($("canvas"), {
  point: (x, y, label) => edit((r) => ({ ...r, points: [...r.points, { x, y, label }], stale: true })),
  box: (box) => edit((r) => ({ ...r, box, stale: true })),
  strokeStart,
  strokeEnd,
  zoomed: (scale) => { $("zoom").textContent = `${Math.round(scale * 100)}%`; },
});
view.brush = prefs.brush;

function strokeStart() {
  if (!editable()) return null;
  const { width, height } = page.frame;
  const r = current();
  const mask = r?.area ? fromRuns(r.runs, height, width) : new Uint8Array(width * height);
  page.stroke = new Layer(mask, width, height, S.colourOf(ui.pair), ui.kind === "support", true);
  render();
  return page.stroke;
}

function strokeEnd() {
  const runs = toRuns(page.stroke.mask, page.frame.height, page.frame.width);
  page.stroke = null;
  edit((r) => ({ ...r, runs, stale: false }));
  // the stroke is the latest word on this mask: an older failure or timing no longer applies
  $("timing").textContent = "";
  say(`${regionName(ui.kind, ui.pair)}: painted by hand.`);
}

// Picking the tool in use again goes back to clicking.
export function setTool(tool) {
  view.tool = view.tool === tool && tool !== "click" ? "click" : tool;
  view.cursor();
  render();
}

export function setBrush(radius) {
  savePrefs({ brush: Math.min(80, Math.max(1, Math.round(radius))) });
  view.brush = prefs.brush;
  if (view.tool === "click") setTool("brush");
  render();
}

export function setOpacity(value) {
  savePrefs({ opacity: Math.round(Math.min(1, Math.max(0.1, value)) * 100) / 100 });
  ui.hidden = false;
  render();
}

export function toggleMasks() {
  ui.hidden = !ui.hidden;
  render();
}
