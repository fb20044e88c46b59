// A paged grid of frames with lazy-loaded images; '[' and ']' page through.
import { api, el } from "./api.js";

const grid = document.getElementById("frame-grid");
const filters = document.getElementById("frame-filters");
const total = document.getElementById("frame-total");
const PAGE = 60;
let offset = 0;
let cursor = {};  // { after } or { before }: the keyset cursor of the page to load
let page = { prev: null, next: null };

async function load() {
  const params = new URLSearchParams({ limit: PAGE, offset, ...cursor });
  const state = filters.elements.state.value;
  if (state) params.set("state", state);
  page = await api(`${grid.dataset.src}?${params}`);
  if (!page.prev) offset = 0;
  total.textContent = page.total ? `${offset + 1}–${offset + page.items.length} of ${page.total}` : "no frames yet";
  grid.replaceChildren(...page.items.map((f) => el("li", { dataset: { frameId: f.id } },
    el("img", { src: grid.dataset.media + (f.thumb ?? f.image), loading: "lazy", alt: `frame ${f.id}`, width: 240 }),
    el("span", { className: "caption" }, `video ${f.video_id} · ${f.time_s.toFixed(1)} s · ${f.state}`),
  )));
  document.getElementById("prev-page").disabled = !page.prev;
  document.getElementById("next-page").disabled = !page.next;
}

const move = (delta) => {
  const to = delta > 0 ? page.next : page.prev;
  if (!to) return;
  offset = Math.max(0, offset + delta);
  cursor = delta > 0 ? { after: to } : { before: to };
  load();
};
document.getElementById("prev-page").addEventListener("click", () => move(-PAGE));
document.getElementById("next-page").addEventListener("click", () => move(PAGE));
filters.elements.state.addEventListener("change", () => { offset = 0; cursor = {}; load(); });
document.addEventListener("keydown", (event) => {
  if (event.target.closest("input, select, textarea")) return;
  if (event.key === "[") move(-PAGE);
  if (event.key === "]") move(PAGE);
});
load();
