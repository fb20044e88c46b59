// One sample's page: accept/reject (curators, what the sample's state allows), and the 3D preview,
// viser's client playing the sample's scene in a dialog, with a before/after rectification switch.
// The open preview is an entry of the tab's history (…/preview): Back closes it to this page.
import { notedReasonPicker } from "./dialogs.js";
import { keyboardHelp } from "./help.js";
import { isShortcut } from "./keys.js";
import { allowedDecisions, decisionShortcuts, rejectionText, rememberDecision, review } from "./sample_review.js";
import { sayFailure } from "./session_ended.js";

const $ = (id) => document.getElementById(id);
const root = $("sample");
const picker = $("reason-picker");
const pickReason = notedReasonPicker(picker);
const viewer = $("viewer3d");
const frame = $("viser-frame");
const stageButtons = [...viewer.querySelectorAll("[data-stage]")];
let stage = stageButtons.some((b) => b.dataset.stage === "after") ? "after" : stageButtons[0]?.dataset.stage;
let busy = false;

function say(text, kind = "info") {
  const line = $("sample-status");
  line.textContent = text;
  line.dataset.kind = kind;
}

// Who rejected the sample, when and why ({reason, note, by, at}; none: not rejected).
function showRejection(rejection) {
  const line = $("rejection");
  line.hidden = !rejection;
  if (!rejection) return;
  const when = rejection.at ? ` on ${new Date(rejection.at).toLocaleString()}` : "";
  line.textContent = `Rejected by ${rejection.by}${when}: ${rejectionText(rejection) || "(no reason given)"}`;
}

// The state's badge, and only the buttons its state allows.
function showState(state) {
  root.dataset.state = state;
  const badge = $("sample-state");
  badge.textContent = state;
  badge.className = `badge state ${state}`;
  const allowed = allowedDecisions(state);
  for (const decision of ["accept", "reject"]) {
    const button = $(decision);
    if (button) button.hidden = !allowed.includes(decision);
  }
  const note = $("decision-note");
  if (note) {
    // The badge names the state: the note says only what it means.
    note.textContent = { accepted: "In the dataset. Reject takes it out and sends its frame back to the annotators.",
                         rejected: "Its frame went back to the annotators; it comes back as a new sample." }[state] ?? "";
    note.hidden = !note.textContent;
  }
}

async function decide(decision) {
  if (root.dataset.canReview !== "true") return say("Only curators accept or reject samples.", "error");
  if (busy) return;
  if (!allowedDecisions(root.dataset.state).includes(decision)) {
    return say(root.dataset.state === "accepted" ? "This sample is already accepted." : "This sample is rejected: nothing to decide.");
  }
  const said = decision === "reject" ? await pickReason("this sample") : {};
  if (decision === "reject" && !said.reason) return;
  busy = true;
  try {
    const sample = await review(root.dataset.api, decision, said);
    showState(sample.state);
    showRejection(sample.rejection);
    rememberDecision(sample);
    say(decision === "accept" ? "Accepted: its frame is in the dataset now."
                              : "Rejected: the annotation went back to the annotators.");
  } catch (err) {
    sayFailure(say)(err);
  } finally {
    busy = false;
  }
}

// ---- 3D preview -------------------------------------------------------------------------------

function show(next) {
  stage = next;
  stageButtons.forEach((b) => b.setAttribute("aria-pressed", String(b.dataset.stage === stage)));
  const scene = `${root.dataset.scene}?stage=${stage}`;
  frame.src = `${root.dataset.viser}?${new URLSearchParams({ playbackPath: scene })}`;
}

function open3d({ push = true } = {}) {
  if (!stage) return;
  if (!frame.src) show(stage);  // the scene is made on first request: only when someone looks
  if (!viewer.open) viewer.showModal();
  if (push && !history.state?.preview) history.pushState({ preview: true }, "", root.dataset.preview);
}

function toggleStage() {
  const stages = stageButtons.map((b) => b.dataset.stage);
  show(stages[(stages.indexOf(stage) + 1) % stages.length]);
}

// Closing the preview (Esc, Close) takes its history entry back; Back (popstate) closes it.
viewer.addEventListener("close", () => {
  if (history.state?.preview) history.back();
});
window.addEventListener("popstate", () => {
  if (history.state?.preview) open3d({ push: false });
  else if (viewer.open) viewer.close();
});
viewer.addEventListener("click", (event) => {
  const button = event.target.closest("button");
  if (button?.dataset.stage) show(button.dataset.stage);
  if (button?.dataset.action === "close") viewer.close();
});

// ---- input ------------------------------------------------------------------------------------

function back() {
  // Back to the grid as it was left (its filters and focus are in its address), else to the grid.
  const list = new URL(root.dataset.list, location.href);
  if (document.referrer.startsWith(list.href)) history.back();
  else location.assign(list);
}

const COMMANDS = { a: () => decide("accept"), r: () => decide("reject"), x: () => decide("reject"), v: () => open3d(),
                   Backspace: back };

document.addEventListener("keydown", (event) => {
  const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
  if (viewer.open && key === "b" && !(event.ctrlKey || event.metaKey || event.altKey)) return toggleStage();
  const run = COMMANDS[key];
  if (!run || !isShortcut(event)) return;
  event.preventDefault();
  run();
});

keyboardHelp([
  ...(root.dataset.canReview === "true" ? decisionShortcuts(picker) : []),
  ...(stage ? [
    ["`v`", "open the 3D preview"],
    ["`b`", "in the 3D preview: before ↔ after rectification"],
    ["`Esc`", "close the 3D preview"],
  ] : []),
  ["`Backspace`", "back to the samples"],
]);

$("accept")?.addEventListener("click", () => decide("accept"));
$("reject")?.addEventListener("click", () => decide("reject"));
$("open-3d")?.addEventListener("click", () => open3d());
showState(root.dataset.state);
showRejection(JSON.parse(root.dataset.rejection));
if (root.dataset.openViewer === "true") {
  // Opened at …/preview: the sample page goes under it, so Back closes the preview to the page.
  history.replaceState(null, "", root.dataset.page);
  open3d();
}
