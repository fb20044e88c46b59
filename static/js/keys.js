// Whether a keydown is meant for a page's shortcuts: not typed into a field, no Ctrl/⌘/Alt
// (the browser's own), and no dialog open over the page (it has keys of its own).
export function isShortcut(event) {
  if (browserKey(event) || event.defaultPrevented) return false;
  if (event.target.closest?.("input, select, textarea, [contenteditable]")) return false;
  return !document.querySelector("dialog[open]");
}

// Ctrl/⌘/Alt with a key is the browser's (Ctrl+1 switches tabs), never a page's or a dialog's choice.
export const browserKey = (event) => event.ctrlKey || event.metaKey || event.altKey;
