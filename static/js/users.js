// The Users page: Deactivate and Revoke tokens ask first, a new password is typed in a dialog, and
// `?` says what each action does to a user's sessions and API tokens.
import { choose } from "./dialogs.js";
import { keyboardHelp } from "./help.js";

const $ = (id) => document.getElementById(id);
// What a change does to the user's tokens, from the row's count (data-tokens).
const revoked = (n) => ({ 0: "they have no API token to revoke", 1: "their API token is revoked for good" }[n]
  ?? `their ${n} API tokens are revoked for good`);

// Title, text and button of the confirmation before each guarded form posts; `user` is the form's data-*.
const CONFIRM = {
  deactivate: (user) => [`Deactivate ${user.name}?`,
    `Their sessions end now and ${revoked(user.tokens)}. Reactivating lets them log in again but brings no ` +
    "token back.", "Deactivate"],
  revoke: (user) => [`Revoke the API tokens of ${user.name}?`,
    `Their scripts stop working: ${revoked(user.tokens)}. Issue a new one with ` +
    `illusion-studio users token ${user.name}.`, "Revoke tokens"],
};

for (const form of document.querySelectorAll("form[data-confirm]")) {
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    const [title, text, action] = CONFIRM[form.dataset.confirm](form.dataset);
    $("confirm-title").textContent = title;
    $("confirm-text").textContent = text;
    $("confirm-yes").textContent = action;
    if (await choose($("confirm-dialog")) === "yes") form.submit();  // submit() skips this handler
  });
}

const passwordDialog = $("password-dialog");
for (const button of document.querySelectorAll("[data-password]")) {
  button.addEventListener("click", () => {
    const form = passwordDialog.querySelector("form");
    form.reset();
    form.action = button.dataset.password;
    $("password-title").textContent = `New password for ${button.dataset.name}`;
    $("password-text").textContent = `Their sessions end and ${revoked(button.dataset.tokens)}.`;
    passwordDialog.showModal();
  });
}

keyboardHelp([["`Esc`", "close a dialog: nothing changes"], ["`Enter`", "in the password dialog: set the password"]],
             { note: $("token-policy").textContent.replace(/\s+/g, " ").trim() });
