// Modal dialogs that ask for one choice: the reject-reason picker of the review and samples pages,
// the Annotate page's type, delete and confirm dialogs.
import { browserKey } from "./keys.js";

// Opens `dialog`; resolves to the value of the button that closed it, "" when it was cancelled.
export function choose(dialog) {
  dialog.returnValue = "";
  dialog.showModal();
  return new Promise((resolve) => dialog.addEventListener("close", () => resolve(dialog.returnValue), { once: true }));
}

// While `dialog` is open, the key a button names in `data-key` chooses that button, unless it is
// typed into one of the dialog's fields. The listener captures, so it runs before the pages'
// shortcut handlers, which pass over a key taken here (defaultPrevented) even though the dialog has
// closed by the time they see it.
export function keyChoices(dialog) {
  document.addEventListener("keydown", (event) => {
    if (!dialog.open || event.key.length !== 1 || browserKey(event)) return;
    if (event.target.closest?.("input, textarea, select")) return;
    const button = dialog.querySelector(`button[data-key="${CSS.escape(event.key)}"]`);
    if (!button) return;
    event.preventDefault();
    dialog.close(button.value);
  }, { capture: true });
}

// The reason picker (reason_picker.html): `pick(label)` resolves to the chosen reason, "" when cancelled.
export function reasonPicker(dialog) {
  keyChoices(dialog);
  return (label) => {
    dialog.querySelector("#reason-target").textContent = label;
    return choose(dialog);
  };
}

// The reason picker with its note field (reason_picker.html's `note_chars`): `pick(label)` resolves
// to {reason, note}, reason "" when cancelled. The note starts empty each time; Enter in it picks
// nothing (a form's Enter would press its first button, the first reason).
export function notedReasonPicker(dialog) {
  const pick = reasonPicker(dialog);
  const note = dialog.querySelector("input[name=note]");
  note.addEventListener("keydown", (event) => { if (event.key === "Enter") event.preventDefault(); });
  return async (label) => {
    note.value = "";
    const reason = await pick(label);
    return { reason, note: reason ? note.value.trim() : "" };
  };
}

// The picker's line in a page's keyboard help (help.js): its keys, and the reasons by their keys.
// `then`: what a rejection leads to, where the page has more to say.
export function reasonShortcut(dialog, then = "") {
  const reasons = [...dialog.querySelectorAll("button.reason")].map((b) => `${b.dataset.key} ${b.value}`);
  return [`\`r\` or \`x\`, then \`1\`–\`${reasons.length}\``, `reject: ${reasons.join(", ")}${then}`];
}
