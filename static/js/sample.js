// One sample's page: accept/reject (curators), and the 3D preview, viser's client playing the
// sample's scene in a dialog, with a before/after rectification switch.
import { reasonPicker } from "./dialogs.js";
import { keyboardHelp } from "./help.js";
import { isShortcut } from "./keys.js";
import { decisionShortcuts, review } from "./sample_review.js";
import { sayFailure } from "./session_ended.js";

const $ = (id) => document.getElementById(id);
const root = $("sample");
const picker = $("reason-picker");
const pickReason = reasonPicker(picker);
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

async function decide(decision) {
  if (root.dataset.canReview !== "true") return say("Only curators accept or reject samples.", "error");
  if (busy) return;
  const reason = decision === "reject" ? await pickReason("this sample") : "";
  if (decision === "reject" && !reason) return;
  busy = true;
  try {
    const sample = await review(root.dataset.api, decision, reason);
    const badge = $("sample-state");
    badge.textContent = sample.state;
    badge.className = `badge state ${sample.state}`;
    say(decision === "accept" ? "Accepted: its frame is in the dataset now."
                              : `Rejected (${reason}): the annotation went back to the annotators.`);
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

function open3d() {
  if (!stage) return;
  if (!frame.src) show(stage);  // the scene is made on first request: only when someone looks
  viewer.showModal();
  history.replaceState(null, "", root.dataset.preview);
}

function toggleStage() {
  const stages = stageButtons.map((b) => b.dataset.stage);
  show(stages[(stages.indexOf(stage) + 1) % stages.length]);
}

viewer.addEventListener("close", () => history.replaceState(null, "", root.dataset.page));
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

const COMMANDS = { a: () => decide("accept"), r: () => decide("reject"), x: () => decide("reject"), v: open3d,
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
$("open-3d")?.addEventListener("click", open3d);
if (root.dataset.openViewer === "true") open3d();
