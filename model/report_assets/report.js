// Click a column head of a sortable table to sort by it (numbers by value, text alphabetically);
// a second click reverses. Used by evaluation reports, standalone or served by the app.
for (const table of document.querySelectorAll("table.sortable")) {
  const heads = [...table.tHead.rows[0].cells];
  heads.forEach((head, column) => {
    head.tabIndex = 0;
    const sort = () => {
      const ascending = head.dataset.order !== "asc";
      heads.forEach((h) => delete h.dataset.order);
      head.dataset.order = ascending ? "asc" : "desc";
      const key = (row) => {
        const cell = row.cells[column];
        const value = cell.dataset.v ?? cell.textContent;
        const number = Number.parseFloat(value);
        return Number.isNaN(number) ? value : number;
      };
      const rows = [...table.tBodies[0].rows].sort((a, b) => {
        const [x, y] = [key(a), key(b)];
        const order = typeof x === "number" && typeof y === "number" ? x - y : String(x).localeCompare(String(y));
        return ascending ? order : -order;
      });
      table.tBodies[0].append(...rows);
    };
    head.addEventListener("click", sort);
    head.addEventListener("keydown", (event) => { if (event.key === "Enter") sort(); });
  });
}
