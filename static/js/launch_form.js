// The launch forms (Models, Evaluation): post the body to the API and, when it is refused, show the
// reason under the field the API names ({error, field, reason}), else above the submit button.
import { api } from "./api.js";
import { sessionEnded } from "./session_ended.js";

function clear(form) {
  for (const note of form.querySelectorAll("[data-error-for]")) note.hidden = true;
  form.querySelector("[aria-invalid]")?.removeAttribute("aria-invalid");
}

// "init.run" is reported under "init", "data.path" under "data": the form's own fields.
function noteFor(form, field) {
  return form.querySelector(`[data-error-for="${CSS.escape(field.split(".")[0])}"]`);
}

// `reason` under the field's note; the field marked and brought into view.
function refuse(note, reason) {
  delete note.dataset.fromEstimate;  // the launch's own refusal: the estimate's next answer leaves it
  note.textContent = reason;
  note.hidden = false;
  const input = note.closest("label")?.querySelector("input, select");
  input?.setAttribute("aria-invalid", "true");
  (input ?? note).scrollIntoView({ block: "center" });
}

// A number field holding text the browser cannot read as a number ("1e", "--2") has the value "", as an
// empty one has, which would launch with the preset's value: refused under the field instead.
function refuseMalformed(form) {
  const bad = [...form.querySelectorAll("input[type=number]")].find((input) => input.validity.badInput);
  const note = bad && noteFor(form, bad.name);
  if (note) refuse(note, "not a number: write it like 2000, 0.0004 or 4e-4 (empty: the preset's value)");
  return Boolean(note);
}

// Resolves to the API's answer, or to null when refused (the reason is then on the form).
export async function launch(form, body) {
  const summary = form.querySelector(".flash.error");
  const button = form.querySelector("button[type=submit]");
  clear(form);
  summary.hidden = true;
  if (refuseMalformed(form)) return null;
  button.disabled = true;
  try {
    return await api(form.dataset.src, { method: "POST", body });
  } catch (err) {
    const note = err.field ? noteFor(form, err.field) : null;
    if (note) {
      refuse(note, err.reason ?? err.message);
    } else {
      summary.textContent = err.message;
      summary.hidden = sessionEnded(err);
    }
    return null;
  } finally {
    button.disabled = false;
  }
}

// A number field's value, or null when empty (the preset's default); text stays text, so the API
// says what is wrong with it rather than the browser guessing.
export function numberOrNull(input) {
  const text = input.value.trim();
  if (text === "") return null;
  const value = Number(text);
  return Number.isFinite(value) && /^-?[0-9.eE+-]+$/.test(text) ? value : text;
}
