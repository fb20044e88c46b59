// The one notice a page shows when its session has ended (logged out in another tab, idle, too
// old, or an admin changed the account): what happened, and a way back to this very page once
// logged in again.

const login = document.querySelector('meta[name="login-url"]')?.content ?? "/login";
const endedUrl = document.querySelector('meta[name="session-ended-url"]')?.content;

// The login page, told to come back here (the login view refuses targets off this site).
function loginUrl() {
  return `${login}?${new URLSearchParams({ next: location.pathname + location.search + location.hash })}`;
}

// The server's words for why the session ended and what to do ({reason: "…because your password
// was changed…", then: "log in with the new password"}), or null when it cannot tell.
async function reason() {
  if (!endedUrl) return null;
  try {
    const response = await fetch(endedUrl, { credentials: "same-origin", headers: { Accept: "application/json" } });
    const data = response.ok ? await response.json() : {};
    return data.reason ? data : null;
  } catch {
    return null;  // the notice without its reason is still right
  }
}

export function showSessionEnded() {
  if (document.getElementById("session-ended")) return;  // once, however many requests fail
  const link = document.createElement("a");
  link.href = loginUrl();
  link.textContent = "log in again";
  // Pages keep their filters in the address: take the address as it is at the click.
  link.addEventListener("click", () => { link.href = loginUrl(); });
  const banner = document.createElement("div");
  banner.id = "session-ended";
  banner.className = "session-ended";
  banner.setAttribute("role", "status");
  banner.append("Your session ended — ", link, ".");
  document.body.prepend(banner);
  // The top bar's name and "Log out" speak of a session that is gone.
  document.querySelector(".topbar .who")?.replaceChildren("signed out");
  reason().then((said) => {
    if (!said) return;
    link.textContent = said.then;
    banner.replaceChildren(`${said.reason} — `, link, ".");
  });
}
