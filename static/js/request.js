// A JSON request whose refusal can be an answer (a 404 or 409 that the page acts on) rather than a
// failure: like api() from api.js, but it resolves with the status and the body either way.
import { failure } from "./api.js";

const csrf = document.querySelector('meta[name="csrf-token"]')?.content ?? "";

// Resolves to { ok, status, data, error }; `error` is api.js's Error for a refusal (sessionEnded and
// all), or one saying the server could not be reached (status 0).
export async function call(url, { method = "POST", body, keepalive = false } = {}) {
  try {
    const response = await fetch(url, {
      method, keepalive, credentials: "same-origin",
      headers: { "Accept": "application/json", "Content-Type": "application/json", "X-CSRFToken": csrf },
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    const data = await response.json().catch(() => ({}));
    const error = response.ok ? undefined : failure(response.status, data, response.statusText);
    return { ok: response.ok, status: response.status, data, error };
  } catch (err) {
    return { ok: false, status: 0, data: {}, error: new Error(`no connection to the server (${err.message})`) };
  }
}
