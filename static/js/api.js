// Small helpers every page shares: JSON fetch with the CSRF header, and polling.

const csrf = document.querySelector('meta[name="csrf-token"]')?.content ?? "";

export async function api(url, { method = "GET", body } = {}) {
  const response = await fetch(url, {
    method,
    headers: { "Accept": "application/json", "Content-Type": "application/json", "X-CSRFToken": csrf },
    body: body === undefined ? undefined : JSON.stringify(body),
    credentials: "same-origin",
  });
  const data = await response.json().catch(() => ({}));
  if (!response.ok) throw new Error(data.error ?? `${response.status} ${response.statusText}`);
  return data;
}

// Call `fn` now and every `ms` while the tab is visible.
export function poll(fn, ms) {
  let timer;
  const tick = async () => {
    try { await fn(); } catch (err) { console.warn(err); }
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
