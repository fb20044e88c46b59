// Accept/reject of one sample, shared by the samples grid and the sample page.
import { api } from "./api.js";
import { reasonShortcut } from "./dialogs.js";
import { formatNumber } from "./labels.js";

// POSTs the decision to the sample's API URL (a rejection with its reason and optional note);
// resolves to the updated sample.
export function review(sampleUrl, decision, { reason = "", note = "" } = {}) {
  return api(`${sampleUrl}/review`, { method: "POST", body: { decision, reason, note } });
}

// "surface not flat — the left edge bends", as pages quote a rejection.
export const rejectionText = ({ reason, note }) => (note ? `${reason} — ${note}` : reason);

// The keyboard help's lines for a decision (help.js), `picker` being the reason picker.
export const decisionShortcuts = (picker) => [
  ["`a`", "accept the sample: its frame joins the dataset"],
  reasonShortcut(picker, " — the frame's annotation goes back to the annotators"),
];

// The few QA figures a curator scans first, formatted: [[label, value, title, flagged]].
export function keyFigures(sample) {
  const qa = sample.qa ?? {};
  const flags = qa.flags ?? [];
  const flagged = (prefix) => flags.some((f) => f.startsWith(prefix));
  const pct = (v) => (v == null ? "–" : `${(100 * v).toFixed(1)} %`);
  const num = (v, unit = "") => (v == null ? "–" : `${formatNumber(v, 3)}${unit}`);
  const inliers = (qa.pairs ?? []).map((p) => p.inlier_ratio).filter((v) => v != null);
  return [
    ["holes", pct(qa.hole_fraction), "share of the right view inpainted", flagged("holes")],
    ["EPE", num(qa.stereo_epe, " px"), "SGBM end-point error on the synthesized pair", flagged("SGBM EPE")],
    ["inliers", inliers.length ? pct(Math.min(...inliers)) : "–", "lowest share of plane-fit inliers over the pairs",
     flagged("pair ")],
    ["scale", num(qa.scale ?? sample.params?.scale), "px per unit of monocular disparity", false],
  ];
}

// The decisions a sample's state still allows (the review service's rule): a generated sample can
// be accepted or rejected; an accepted one rejected (it leaves the dataset); a rejected one
// neither — its frame went back to the annotators and comes back as a new sample.
export function allowedDecisions(state) {
  return { generated: ["accept", "reject"], accepted: ["reject"] }[state] ?? [];
}

// What this tab's decisions left each sample in, kept in sessionStorage so that a reload or a
// visit to a sample's page keeps the count; per user (a tab can change hands at the login page).
const SESSION_KEY = `sample-decisions:${document.querySelector(".who .user")?.textContent.trim() ?? ""}`;

function decisions() {
  try {
    return JSON.parse(sessionStorage.getItem(SESSION_KEY) ?? "{}");
  } catch {
    return {};
  }
}

// Records the state a decision left `sample` in; returns {accepted, rejected}: this tab's counts.
export function rememberDecision(sample) {
  const all = { ...decisions(), [sample.id]: sample.state };
  sessionStorage.setItem(SESSION_KEY, JSON.stringify(all));
  return sessionCounts();
}

export function sessionCounts() {
  const states = Object.values(decisions());
  return { accepted: states.filter((s) => s === "accepted").length, rejected: states.filter((s) => s === "rejected").length };
}
