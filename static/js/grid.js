// What the keyboard-first grids (review, samples) share: one task at a time, in the order the keys
// were pressed, and paging that keeps the curator's place while decided items leave the filter.

export function serial(onError) {
  let queue = Promise.resolve();
  return (task) => (queue = queue.then(task).catch(onError));
}

// Arrow-key moves in a CSS grid: ±1 sideways, ±(tiles per row) up and down.
export function stepOf(direction, grid, oneColumn = false) {
  const columns = oneColumn ? 1 : getComputedStyle(grid).gridTemplateColumns.split(" ").length;
  return { left: -1, right: 1, up: -columns, down: columns }[direction];
}

// The next or previous page — its keyset cursor (the API's next/prev) and the offset to show —
// or a message when there is none.
export function pageOffset(view, direction, pageSize, inFilter) {
  if (direction > 0) {
    if (!view.next) return "This is the last page.";
    // Decided items have left the filter: the next page starts after the ones still in it.
    return { offset: view.offset + view.items.filter(inFilter).length, after: view.next, before: null };
  }
  if (!view.prev) return "This is the first page.";
  return { offset: Math.max(0, view.offset - pageSize), after: null, before: view.prev };
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
