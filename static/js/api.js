// Small helpers every page shares: JSON fetch with the CSRF header, failures as Errors, and polling.
import { showSessionEnded } from "./session_banner.js";

const csrf = document.querySelector('meta[name="csrf-token"]')?.content ?? "";

export async function api(url, { method = "GET", body } = {}) {
  const response = await fetch(url, {
    method,
    headers: { "Accept": "application/json", "Content-Type": "application/json", "X-CSRFToken": csrf },
    body: body === undefined ? undefined : JSON.stringify(body),
    credentials: "same-origin",
  });
  const data = await response.json().catch(() => ({}));
  if (!response.ok) throw failure(response.status, data, response.statusText);
  return data;
}

// The Error for a failed response. Pages send no tokens, so a 401 means the session ended: the
// page-wide notice says so, and `sessionEnded` tells the page to leave out a message of its own.
export function failure(status, data = {}, statusText = "") {
  const err = new Error(data.error ?? `${status} ${statusText}`);
  if (status === 401) {
    err.sessionEnded = true;
    showSessionEnded();
  }
  return err;
}

// Call `fn` now and every `ms` while the tab is visible; stop when the session has ended.
export function poll(fn, ms) {
  let timer;
  const tick = async () => {
    try {
      await fn();
    } catch (err) {
      if (err.sessionEnded) return;  // nothing will load until the person logs in again
      console.warn(err);
    }
    timer = setTimeout(tick, document.hidden ? ms * 4 : ms);
  };
  tick();
  return () => clearTimeout(timer);
}

export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (key === "dataset") Object.assign(node.dataset, value);
    else if (key in node) node[key] = value;
    else node.setAttribute(key, value);
  }
  node.append(...children);
  return node;
}
