// What the keyboard-first grids (review, samples) share: one task at a time, in the order the keys
// were pressed, paging that keeps the curator's place while decided items leave the filter, and
// the keyboard itself.

export function serial(onError) {
  let queue = Promise.resolve();
  return (task) => (queue = queue.then(task).catch(onError));
}

const STEPS = { ArrowLeft: "left", h: "left", ArrowRight: "right", l: "right", ArrowUp: "up", k: "up",
                ArrowDown: "down", j: "down" };

// A grid page's keyboard help (help.js): the moves listenKeys knows and the paging keys around the
// page's own `rows`; `noun`: what a tile shows ("frame", "sample").
export const gridHelp = (noun, rows) => [
  ["`←` `→` `↑` `↓` or `h` `l` `k` `j`", "move"],
  ["`Home` `End`", `first / last ${noun} of the page`],
  ...rows,
  ["`n` `p` or `]` `[`", "next / previous page"],
];

// Arrow-key moves in a CSS grid: ±1 sideways, ±(tiles per row) up and down.
export function stepOf(direction, grid, oneColumn = false) {
  const columns = oneColumn ? 1 : getComputedStyle(grid).gridTemplateColumns.split(" ").length;
  return { left: -1, right: 1, up: -columns, down: columns }[direction];
}

// The next (1) or previous (-1) page into `view` — its keyset cursor (the API's next/prev) and the
// offset to show — and `load()` it; or `say()` there is none.
export async function turnPage(view, direction, { size, inFilter, load, say }) {
  if (!(direction > 0 ? view.next : view.prev)) return say(`This is the ${direction > 0 ? "last" : "first"} page.`);
  if (direction > 0) {
    // Decided items have left the filter: the next page starts after the ones still in it.
    Object.assign(view, { offset: view.offset + view.items.filter(inFilter).length, after: view.next, before: null });
  } else {
    Object.assign(view, { offset: Math.max(0, view.offset - size), after: null, before: view.prev });
  }
  await load();
}

// A page's cursors into the request (and the address, for deep links).
export function setCursor(params, view) {
  if (view.after) params.set("after", view.after);
  if (view.before) params.set("before", view.before);
}

export function focusTile(grid, index) {
  const node = grid.children[index];
  if (!node?.classList.contains("tile")) return;
  node.focus({ preventScroll: true });
  node.scrollIntoView({ block: "nearest" });
}

// The page's shortcuts: `step(direction, shift)` for arrows and h/j/k/l, `commands[key]` for the
// other keys, `withCtrl[key]` for Ctrl/⌘ + key. `help` is the shortcut dialog (help.js) and `picker`
// the reason picker: they have keys of their own. `focus()` gives the keyboard back to the grid.
export function listenKeys({ help, picker, focus, step, commands, withCtrl = {} }) {
  document.addEventListener("keydown", (event) => {
    if (event.defaultPrevented || picker.open || help.open) return;
    const target = event.target;
    if (target.closest("input, select, textarea")) {
      if (event.key === "Escape") focus();
      return;
    }
    if (["Enter", " "].includes(event.key) && target.closest("button, a, summary")) return;  // let them press
    if (event.key === "Escape" && document.querySelector("dialog[open]")) return;  // the dialog closes itself
    const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
    let run;
    if (event.ctrlKey || event.metaKey) run = withCtrl[key];
    else if (!event.altKey) run = STEPS[key] ? () => step(STEPS[key], event.shiftKey) : commands[key];
    if (!run) return;
    event.preventDefault();
    run();
  });
}

// Toolbar buttons (by id) act like their keys, then hand the keyboard back to the grid, unless what
// they did left a dialog open.
export function actLikeKeys(buttons, focus) {
  for (const [id, run] of Object.entries(buttons)) {
    document.getElementById(id)?.addEventListener("click", async () => {
      await run();
      if (!document.querySelector("dialog[open]")) focus();
    });
  }
}
