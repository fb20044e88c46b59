// One redraw of the page from its state: every plane's masks on the canvas (the one being brushed
// as it is painted), the proposals on show, the current region's clicks and box, then the panel.
import { Layer } from "./layers.js";
import { current, page, prefs, root, ui } from "./page.js";
import { renderPanel } from "./panel.js";
import { proposalOutlines } from "./proposals.js";
import { fromRuns } from "./rle.js";
import * as S from "./state.js";
import { view } from "./tools.js";

const layers = new WeakMap();  // runs → Layer

export function render() {
  const doc = page.history?.doc;
  root.dataset.readonly = String(!page.session);
  const scene = view.scene;
  scene.opacity = prefs.opacity;
  scene.hidden = ui.hidden;
  scene.layers = [];
  scene.proposals = [];
  scene.points = [];
  scene.box = null;
  if (doc) {
    for (const kind of ["support", "illusion"]) {  // an illusion lies on its support: draw it on top
      for (const p of doc.pairs) {
        const active = p.id === ui.pair && kind === ui.kind;
        if (active && page.stroke) scene.layers.push({ layer: page.stroke, active });
        else if (p[kind]?.area) scene.layers.push({ layer: layerOf(p.id, kind, p[kind].runs), active });
      }
    }
    scene.proposals = proposalOutlines();
    const r = current();
    scene.points = r?.points ?? [];
    scene.box = r?.box ?? null;
    scene.colour = S.colourOf(ui.pair);
  }
  view.render();
  renderPanel(doc);
}

function layerOf(pairId, kind, runs) {
  const { height, width } = page.frame;
  const colour = S.colourOf(pairId), hatched = kind === "support";
  let layer = layers.get(runs);
  if (!layer || layer.hex !== colour || layer.hatched !== hatched) {
    layer = new Layer(fromRuns(runs, height, width), width, height, colour, hatched);
    layer.hex = colour;
    layers.set(runs, layer);
  }
  return layer;
}
