// Click a column head of a sortable table (or press Enter on it) to sort by it. The first click
// on a column of numbers puts the largest first — the worst, for errors: a report is opened to
// find where a method fails — and text A→Z; a second click reverses. Used by evaluation reports,
// standalone or served by the app.
for (const table of document.querySelectorAll("table.sortable")) {
  const heads = [...table.tHead.rows[0].cells];
  const body = table.tBodies[0];
  const numeric = (column) => [...body.rows].some((row) => row.cells[column]?.dataset.v !== undefined);
  heads.forEach((head, column) => {
    head.tabIndex = 0;
    head.title = numeric(column) ? "Sort by this column: the worst (largest) first; again: the best first" : "Sort by this column";
    const sort = () => {
      const first = numeric(column) ? "desc" : "asc";
      const order = head.dataset.order ? (head.dataset.order === "asc" ? "desc" : "asc") : first;
      heads.forEach((h) => delete h.dataset.order);
      head.dataset.order = order;
      const key = (row) => {
        const cell = row.cells[column];
        const value = cell.dataset.v ?? cell.textContent;
        const number = Number.parseFloat(value);
        return Number.isNaN(number) ? value : number;
      };
      // Cells without a number (a region the sample lacks) go last either way.
      const rows = [...body.rows].sort((a, b) => {
        const [x, y] = [key(a), key(b)];
        if (typeof x === "number" && typeof y === "number") return order === "asc" ? x - y : y - x;
        if (typeof x === "number" || typeof y === "number") return typeof x === "number" ? -1 : 1;
        return order === "asc" ? String(x).localeCompare(String(y)) : String(y).localeCompare(String(x));
      });
      body.append(...rows);
    };
    head.addEventListener("click", sort);
    head.addEventListener("keydown", (event) => { if (event.key === "Enter") sort(); });
  });
}
