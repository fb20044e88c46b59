// Paging through an API list by its keyset cursors (the pager macro's ‹ › buttons, [ ] and p n),
// with the filters and the position in the address, so that a reload or a shared link lands on
// the same page. The page draws the items; this module knows where they are.
import { api } from "./api.js";
import { isShortcut } from "./keys.js";
import { sayFailure } from "./session_ended.js";

const KEYS = { "[": -1, p: -1, "]": 1, n: 1 };
const MOST = 500;  // the largest page the list APIs serve (their `limit` maximum in webapp/api)

// A count from the address as an integer in min..max; `fallback` when it is not a number at all.
function count(text, min, max, fallback) {
  const n = Math.trunc(Number(text));
  return text && Number.isFinite(n) ? Math.min(max, Math.max(min, n)) : fallback;
}

// src: the API list; form: its filters (every named control is a query parameter); size: items a
// page (?limit= in the address overrides it); draw(page): show page.items; range: "61–97 of 97";
// status: where a failure is said (the page's own messages there are left alone).
// Returns { load, refresh }: load() to poll (it throws), refresh() to show once (it says what failed).
export function pagedList({ src, form, size, draw, range, status }) {
  const prevButton = document.getElementById("prev-page");
  const nextButton = document.getElementById("next-page");
  const controls = [...form.elements].filter((c) => c.name);
  const start = new URLSearchParams(location.search);  // a reload or a shared link
  const perPage = count(start.get("limit"), 1, MOST, size);
  for (const c of controls) if (start.has(c.name)) c.value = start.get(c.name);
  let view = { offset: count(start.get("offset"), 0, Infinity, 0), after: start.get("after"),
               before: start.get("before") };
  let shown = { offset: 0, items: [], prev: null, next: null };
  let queue = Promise.resolve();
  let failed = "";  // this pager's failure on the status line, taken back once a page loads

  function params() {
    const q = new URLSearchParams();
    for (const c of controls) if (c.value) q.set(c.name, c.value);
    if (view.offset) q.set("offset", view.offset);
    if (view.after) q.set("after", view.after);
    if (view.before) q.set("before", view.before);
    if (perPage !== size) q.set("limit", perPage);
    return q;
  }

  async function show() {
    const query = params();
    query.set("limit", perPage);
    const page = await api(`${src}?${query}`);
    if (!page.items.length && page.prev) {
      // Past the end (what was there has left the filter meanwhile): the last page instead where
      // the total tells its offset, else the first page, the one whose offset is known.
      view = { offset: 0, after: null, before: page.total != null ? page.prev : null };
      return show();
    }
    const n = page.items.length;
    // Offsets are counted here, not by the server: pin them at the ends, where they are known.
    if (!page.prev) view = { offset: 0, after: null, before: null };  // the first page: a plain address
    else if (page.total != null) view.offset = Math.max(0, page.next ? Math.min(view.offset, page.total - n) : page.total - n);
    shown = { ...view, ...page };
    const q = params();
    history.replaceState(history.state, "", `${location.pathname}${q.size ? `?${q}` : ""}${location.hash}`);
    range.textContent = n ? `${view.offset + 1}–${view.offset + n}${page.total != null ? ` of ${page.total}` : ""}` : "none";
    prevButton.disabled = !page.prev;
    nextButton.disabled = !page.next;
    if (status.textContent === failed) status.textContent = "";
    failed = "";
    draw(page);
  }

  // One request at a time, in order: each of the keys pressed faster than pages load moves one page.
  function serially(task) {
    const run = queue.then(task);
    queue = run.catch(() => {});
    return run;
  }
  const said = (run) => run.catch(sayFailure((text) => { status.textContent = failed = text; }));
  const load = () => serially(show);
  const refresh = () => said(load());

  // From the page on screen, known once the requests before have been answered.
  const move = (direction) => said(serially(() => {
    const to = direction > 0 ? shown.next : shown.prev;
    if (!to) return;
    view = direction > 0 ? { offset: shown.offset + shown.items.length, after: to, before: null }
                         : { offset: Math.max(0, shown.offset - perPage), after: null, before: to };
    return show();
  }));

  form.addEventListener("change", () => said(serially(() => {
    view = { offset: 0, after: null, before: null };
    return show();
  })));
  form.addEventListener("submit", (event) => event.preventDefault());
  prevButton.addEventListener("click", () => move(-1));
  nextButton.addEventListener("click", () => move(1));
  document.addEventListener("keydown", (event) => {
    if (!(event.key in KEYS) || !isShortcut(event)) return;
    event.preventDefault();
    move(KEYS[event.key]);
  });
  return { load, refresh };
}
