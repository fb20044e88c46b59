// Whether a keydown is meant for a page's shortcuts: not typed into a field, no Ctrl/⌘/Alt
// (the browser's own), and no dialog open over the page (it has keys of its own).
export function isShortcut(event) {
  if (event.ctrlKey || event.metaKey || event.altKey || event.defaultPrevented) return false;
  if (event.target.closest?.("input, select, textarea, [contenteditable]")) return false;
  return !document.querySelector("dialog[open]");
}
