// The `?` dialog listing a page's keyboard shortcuts. A page hands over its list once; the dialog,
// the `?` key and the page's [data-help] buttons are wired here, so every page explains itself alike.
import { el } from "./api.js";
import { isShortcut } from "./keys.js";

// "`r` or `x`, then `1`–`5`": the parts in backticks are keys, the rest reads as words.
function keys(text) {
  return text.split("`").map((part, i) => (i % 2 ? el("kbd", {}, part) : part)).filter((part) => part !== "");
}

// shortcuts: [[keys, what they do]]; note: a line under the table (mouse use, say).
export function keyboardHelp(shortcuts, { note = "" } = {}) {
  const rows = [...shortcuts, ["`?`", "this help"]].map(([key, what]) =>
    el("tr", {}, el("td", {}, ...keys(key)), el("td", {}, what)));
  const dialog = el("dialog", { id: "keys-help", className: "keys-help" },
    el("h2", { id: "keys-help-title" }, "Keyboard shortcuts"),
    el("table", { className: "keys" }, el("tbody", {}, ...rows)),
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
  for (const button of document.querySelectorAll("[data-help]")) button.addEventListener("click", () => dialog.showModal());
  return dialog;
}
