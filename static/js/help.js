// The `?` dialog listing a page's keyboard shortcuts. A page hands over its list once; the dialog,
// the `?` key and the page's [data-help] buttons are wired here, so every page explains itself alike.
import { el } from "./api.js";
import { isShortcut } from "./keys.js";

// "`r` or `x`, then `1`–`5`": the parts in backticks are keys, the rest reads as words.
function keys(text) {
  return text.split("`").map((part, i) => (i % 2 ? el("kbd", {}, part) : part)).filter((part) => part !== "");
}

// A table of shortcuts for each heading and the rows under it (one table where there is no heading).
function tables(shortcuts) {
  const groups = [];
  for (const entry of shortcuts) {
    const heading = typeof entry === "string";
    if (heading || !groups.length) groups.push({ title: heading ? entry : "", rows: [] });
    if (!heading) groups.at(-1).rows.push(el("tr", {}, el("td", {}, ...keys(entry[0])), el("td", {}, entry[1])));
  }
  return groups.map(({ title, rows }) => el("section", {}, title ? el("h3", {}, title) : "",
    el("table", { className: "keys" }, el("tbody", {}, ...rows))));
}

// shortcuts: [[keys, what they do]], with a heading (a string) before each group where a page has
// many; note: a line under the table (mouse use, say).
export function keyboardHelp(shortcuts, { note = "" } = {}) {
  // Opening focuses the title (autofocus): else the first focusable element, Close at the bottom, took
  // the focus and scrolled a help taller than the window (Annotate's) past its title.
  const dialog = el("dialog", { id: "keys-help", className: "keys-help" },
    el("h2", { id: "keys-help-title", tabIndex: -1, autofocus: true }, "Keyboard shortcuts"),
    el("div", { className: "keys-groups" }, ...tables([...shortcuts, ["`?`", "this help"]])),
    note ? el("p", { className: "muted" }, note) : "",
    el("form", { method: "dialog" }, el("button", {}, "Close")));
  dialog.setAttribute("aria-labelledby", "keys-help-title");
  document.body.append(dialog);
  document.addEventListener("keydown", (event) => {
    if (event.key !== "?" || !(dialog.open || isShortcut(event))) return;
    event.preventDefault();
    if (dialog.open) dialog.close();
    else dialog.showModal();
  });
  // The page's `?` button goes to the top bar's slot (base.html), so it is in one place on every page.
  const slot = document.querySelector(".topbar .help-slot");
  for (const button of document.querySelectorAll("[data-help]")) {
    slot?.append(button);
    button.addEventListener("click", () => dialog.showModal());
  }
  return dialog;
}
