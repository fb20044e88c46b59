// The shortcuts, in one table that both the key handler and the keyboard help (help.js) read, so the
// help can never describe keys that don't work. Rows without `keys` are mouse gestures, shown in the
// help only; its `?` row is help.js's own.

const DIGITS = ["1", "2", "3", "4", "5", "6", "7", "8", "9"];

const SHORTCUTS = [
  { group: "Segment" },
  { show: ["Click"], does: "include a point (green)" },
  { show: ["Right-click", "Alt+Click"], does: "exclude a point (red)" },
  { show: ["Drag"], does: "box around the object" },
  { keys: ["i"], show: ["I"], does: "illusion mode: the flat thing that looks 3D", command: "illusion" },
  { keys: ["s"], show: ["S"], does: "support mode: the real surface it lies on", command: "support" },
  { keys: ["n"], show: ["N"], does: "add a plane (a new illusion/support pair)", command: "addPair" },
  { keys: DIGITS, show: ["1", "…", "9"], does: "select a pair", command: "selectPair" },
  { keys: ["Backspace"], show: ["Backspace"], does: "remove the current pair", command: "removePair" },
  { keys: ["Escape"], show: ["Esc"], does: "clear the current region's clicks and mask", command: "clear" },
  { group: "Touch up" },
  { keys: ["c"], show: ["C"], does: "click tool", command: "clickTool" },
  { keys: ["b"], show: ["B"], does: "brush (right button erases)", command: "brush" },
  { keys: ["e"], show: ["E"], does: "eraser (right button paints)", command: "eraser" },
  { keys: ["[", "]"], show: ["[", "]"], does: "smaller / larger brush", command: "brushSize", repeat: true },
  { keys: ["Ctrl+z"], show: ["Ctrl+Z"], does: "undo", command: "undo", repeat: true },
  { keys: ["Ctrl+Shift+z", "Ctrl+y"], show: ["Ctrl+Shift+Z", "Ctrl+Y"], does: "redo", command: "redo", repeat: true },
  { group: "View" },
  { show: ["Wheel"], does: "zoom at the cursor" },
  { keys: ["+", "=", "-"], show: ["+", "−"], does: "zoom in / out", command: "zoom", repeat: true },
  { keys: ["0"], show: ["0"], does: "fit the frame", command: "fit" },
  { show: ["Space+Drag", "Middle-drag"], does: "pan" },
  { keys: ["o", "Shift+o"], show: ["O", "Shift+O"], does: "masks more / less opaque", command: "opacity", repeat: true },
  { keys: ["h"], show: ["H"], does: "hide / show the masks and proposals", command: "hide" },
  { group: "Frame" },
  { keys: ["t"], show: ["T"], does: "illusion type of the selected plane", command: "pickType" },
  { keys: ["Enter"], show: ["Enter"], does: "submit and take the next frame", command: "submit" },
  { keys: ["ArrowLeft", "ArrowRight"], show: ["←", "→"], does: "previous / next frame of the video", command: "step" },
  { keys: ["p"], show: ["P"], does: "propagate the current pair to the next frames", command: "propagate" },
  { keys: ["Delete", "x"], show: ["Del", "X"], does: "delete the frame (redundant or imperceptible)", command: "deleteFrame" },
  { group: "Proposals" },
  { keys: ["a"], show: ["A"], does: "accept the highlighted proposal as a plane; clicks correct it", command: "acceptProposal" },
  { keys: ["r"], show: ["R"], does: "reject the highlighted proposal", command: "rejectProposal" },
  { keys: ["Tab", "Shift+Tab"], show: ["Tab", "Shift+Tab"], does: "highlight the next / previous proposal",
    command: "highlightProposal", repeat: true },
  { keys: ["v"], show: ["V"], does: "show all proposals, those under the threshold too (again: hide them)",
    command: "showAllProposals" },
];

// "Ctrl+Shift+z" style names; Shift only counts where it doesn't already pick the character ("?", "+").
function keyName(event) {
  const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
  const shift = event.shiftKey && (/^[a-z]$/.test(key) || key.length > 1);
  return `${event.ctrlKey || event.metaKey ? "Ctrl+" : ""}${event.altKey ? "Alt+" : ""}${shift ? "Shift+" : ""}${key}`;
}

const byKey = new Map(SHORTCUTS.flatMap((s) => (s.keys ?? []).map((k) => [k, s])));

// The shortcut an event means, with the key that chose it among the row's keys.
export function shortcutFor(event) {
  const key = keyName(event);
  const shortcut = byKey.get(key);
  if (!shortcut || (event.repeat && !shortcut.repeat)) return null;
  return { command: shortcut.command, key };
}

// The table as keyboardHelp (help.js) takes it: group headings, and each row's keys in backticks.
export const helpRows = () => SHORTCUTS.map((s) => s.group ?? [s.show.map((k) => `\`${k}\``).join(" "), s.does]);
