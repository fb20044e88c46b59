// Every JSON request of a page goes through here (api() in api.js throws on top of call()), so the
// CSRF header and what a refusal means are decided once.
import { showSessionEnded } from "./session_banner.js";

const csrf = document.querySelector('meta[name="csrf-token"]')?.content ?? "";

// What the server needs of a request from a page: a JSON answer, and the form's CSRF token.
export const HEADERS = Object.freeze({ "Accept": "application/json", "X-CSRFToken": csrf });

// The Error for a failed response. Pages send no tokens, so a 401 means the session ended: the
// page-wide notice says so, and `sessionEnded` tells the page to leave out a message of its own.
export function failure(status, data = {}, statusText = "") {
  const err = new Error(data.error ?? `${status} ${statusText}`);
  // A launch form's refusal names its field and the reason alone (launch_form.js shows it there).
  err.field = data.field;
  err.reason = data.reason;
  if (status === 401) {
    err.sessionEnded = true;
    showSessionEnded();
  }
  return err;
}

// A request whose refusal can be an answer (a 404 or 409 that the page acts on) rather than a
// failure: it resolves to { ok, status, data, error }; `error` is failure()'s Error for a refusal,
// or one saying the server could not be reached (status 0).
export async function call(url, { method = "POST", body, keepalive = false } = {}) {
  try {
    const response = await fetch(url, {
      method, keepalive, credentials: "same-origin",
      headers: { ...HEADERS, "Content-Type": "application/json" },
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    const data = await response.json().catch(() => ({}));
    const error = response.ok ? undefined : failure(response.status, data, response.statusText);
    return { ok: response.ok, status: response.status, data, error };
  } catch (err) {
    return { ok: false, status: 0, data: {}, error: new Error(`no connection to the server (${err.message})`) };
  }
}
