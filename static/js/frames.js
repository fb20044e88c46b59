// The frames browser: a paged grid of every frame, filtered by state (and video), the filter and
// the page kept in the address. A tile opens the frame on the Annotate page, the one page that
// shows a single frame: editable there when its state allows, read-only otherwise.
import { el } from "./api.js";
import { stepOf } from "./grid.js";
import { keyboardHelp } from "./help.js";
import { isShortcut } from "./keys.js";
import { framePlace } from "./labels.js";
import { pagedList } from "./pager.js";

const grid = document.getElementById("frame-grid");
const filters = document.getElementById("frame-filters");
const ARROWS = { ArrowLeft: "left", ArrowRight: "right", ArrowUp: "up", ArrowDown: "down" };

function tile(frame) {
  const place = framePlace(frame);
  return el("li", { dataset: { frameId: frame.id, state: frame.state } },
    el("a", { href: grid.dataset.open + frame.id, title: `Open ${place}` },
      el("img", { src: grid.dataset.media + (frame.thumb ?? frame.image), loading: "lazy", alt: `frame #${frame.id}`,
                  width: 240 }),
      el("span", { className: "caption" }, `${place} · `, el("span", { className: `state ${frame.state}` }, frame.state),
         // an annotated frame whose sample could not be made: why, on the tile (its job has the retry)
         frame.generate_failed ? el("span", { className: "sample-blocker", title: frame.generate_failed.error ?? "" },
                                    ` · no sample: ${frame.generate_failed.error ?? "generate failed"}`) : "")));
}

function draw(page) {
  grid.replaceChildren(...(page.items.length ? page.items.map(tile)
    : [el("li", { className: "empty" }, "No frames here. Frames appear when videos are ingested (see Ingest and Jobs).")]));
}

const { refresh } = pagedList({ src: grid.dataset.src, form: filters, size: 60, draw,
                                range: document.getElementById("frame-total"),
                                status: document.getElementById("frame-status") });

// The video filter comes from a link (a job's "Made" column): ✕ drops it.
document.querySelector("#video-filter button")?.addEventListener("click", (event) => {
  filters.elements.video_id.value = "";
  event.target.closest("#video-filter").remove();
  filters.dispatchEvent(new Event("change"));
});

// Arrow keys move between the tiles once one has the focus (Tab); Enter opens it, as links do.
document.addEventListener("keydown", (event) => {
  const tiles = [...grid.querySelectorAll("a")];
  const at = tiles.indexOf(document.activeElement);
  if (!(event.key in ARROWS) || at < 0 || !isShortcut(event)) return;
  event.preventDefault();
  tiles[Math.min(tiles.length - 1, Math.max(0, at + stepOf(ARROWS[event.key], grid)))].focus();
});

keyboardHelp([
  ["`]` or `n`", "next page"],
  ["`[` or `p`", "previous page"],
  ["`Tab`, then `←` `→` `↑` `↓`", "move between the frames"],
  ["`Enter`", "open the frame on the Annotate page (read-only unless approved or annotated)"],
], { note: "The filter and the page are in the address: a reload or a shared link shows the same frames." });
refresh();
