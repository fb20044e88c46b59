// Small helpers every page shares: a JSON request that throws when refused, polling, elements.
import { call } from "./request.js";
import { sessionEnded } from "./session_ended.js";

// Resolves to the JSON answer; a refusal or a lost connection throws request.js's Error.
export async function api(url, { method = "GET", body } = {}) {
  const { ok, data, error } = await call(url, { method, body });
  if (!ok) throw error;
  return data;
}

// Call `fn` now and every `ms` while the tab is visible; stop when the session has ended.
export function poll(fn, ms) {
  let timer;
  const tick = async () => {
    try {
      await fn();
    } catch (err) {
      if (sessionEnded(err)) return;  // nothing will load until the person logs in again
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
