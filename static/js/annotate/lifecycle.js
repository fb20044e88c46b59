// A frame's way onto the page: from the queue, a link or the arrows; held with a lease (or shown
// read-only when it can't be), its draft restored and its proposals offered; the queue watched while
// it is empty.
// Navigation runs one step at a time.
import { api, el } from "../api.js";
import { framePlace, plural } from "../labels.js";
import { call } from "../request.js";
import { rejectionText } from "../sample_review.js";
import { sayFailure, sessionEnded } from "../session_ended.js";
import { commit } from "./editing.js";
import { banner, say, saveState } from "./messages.js";
import { $, API, page, root, sleep, ui } from "./page.js";
import { render } from "./render.js";
import { awaitingProposals, offerProposals, proposalsHint } from "./proposals.js";
import { FrameSession } from "./session.js";
import * as S from "./state.js";
import { setTool, view } from "./tools.js";

const LEASE_S = Number(root.dataset.leaseS) || 600;
const EDITABLE = ["approved", "annotated"];
const QUEUE_RECHECK_MS = 8000;
const READY_RECHECK_MS = 2000;
const PROPOSAL_LOOKS = 90;  // × READY_RECHECK_MS: the proposals computed later come when the frame next opens
const OTHER_ANNOTATOR = "another annotator is working on it";

let nav = Promise.resolve();

// `target` is read when the step starts, so two quick → presses move two frames. `keep`: the frame
// left keeps its lease (it is still this annotator's, for after the frame opened now).
export function navigate(target, how = "push", { keep = false } = {}) {
  nav = nav.then(async () => {
    const id = await target();
    if (id == null) return;
    await leave({ keep });
    await open(id, how);
  }).catch(sayFailure(say));
  return nav;
}

// The previous (-1) or next (1) frame of the video.
export const stepFrame = (direction) => navigate(() => (direction < 0 ? page.frame?.prev_id : page.frame?.next_id));

// The first frame: the one in the address, else the queue's; and the browser's history from then on.
export function start(frameId) {
  window.addEventListener("popstate", (event) => {
    if (event.state?.id) navigate(async () => event.state.id, "none");
  });
  // Leaving: the lease goes back at once (keepalive outlives the page); the draft is in localStorage.
  window.addEventListener("pagehide", () => page.session?.release());
  // Back from the back/forward cache with the lease given away: take the frame up again.
  window.addEventListener("pageshow", (event) => {
    if (event.persisted && page.frame) navigate(async () => page.frame.id, "replace");
  });
  document.addEventListener("visibilitychange", () => { if (document.hidden) page.session?.flush(); });
  navigate(frameId ? async () => frameId : fromQueue, "replace");
}

async function leave({ keep = false } = {}) {
  if (!page.session) return;
  const leaving = page.session;
  page.session = null;
  await leaving.flush();
  if (keep) leaving.close();
  else leaving.release();
}

export async function fromQueue() {
  const res = await call(`${API}/queue/annotate/next`);
  if (res.status === 404) {
    showEmpty();
    return null;
  }
  if (!res.ok) throw res.error;
  return res.data.frame_id;
}

async function open(id, how) {
  root.dataset.state = "loading";
  const detail = await api(`${API}/frames/${id}`);
  const image = new Image();
  image.src = root.dataset.media + detail.image;
  const loaded = image.decode();

  let reason = null;
  if (!EDITABLE.includes(detail.state)) reason = `this frame is ${detail.state}`;
  else if (detail.lease.held_by_other) reason = OTHER_ANNOTATOR;
  else if (detail.submitted && !detail.lease.mine) reason = "it is submitted";
  else if (!detail.lease.mine) {
    const res = await call(`${API}/frames/${id}/lease`);
    if (sessionEnded(res.error)) throw res.error;
    if (res.ok) detail.lease = { ...detail.lease, mine: true, expires: res.data.lease_expires };
    else reason = res.error.message;  // the server says why: someone else holds it, or it left the queue
  }
  await loaded;

  page.frame = detail;
  offerProposals(detail);
  const serverDoc = S.fromServer(detail);
  page.history = new S.History(serverDoc);
  ui.pair = serverDoc.pairs[0].id;
  ui.kind = "illusion";
  if (how === "push") window.history.pushState({ id }, "", `/annotate/${id}`);
  else window.history.replaceState({ id }, "", `/annotate/${id}`);
  $("frame-title").textContent = `Frame #${detail.id}`;
  $("preview-link").href = `/frames/${detail.id}/preview`;
  $("preview-link").hidden = detail.state === "approved";  // a sample exists only after a submit
  $("frame-info").textContent = `${framePlace(detail)} · ${detail.width}×${detail.height}`;
  $("prev-frame").disabled = detail.prev_id == null;
  $("next-frame").disabled = detail.next_id == null;
  $("empty").hidden = true;
  $("timing").textContent = "";
  view.setImage(image);
  banner(null);
  showReturned(detail.returned);
  showSampleNote(detail);
  showFailedElsewhere(detail.failed_elsewhere);
  showWaiting(detail.returned_waiting);
  if (reason) readOnly(reason);
  else {
    const draft = `Draft loaded: ${plural(serverDoc.pairs.length, "plane")}`;
    if (detail.returned) say(`${draft}, sent back by ${detail.returned.by}: fix it and submit again.`);
    else say(detail.regions.length ? `${draft}.` : proposalsHint() ?? "Click inside the illusion: the flat thing that looks 3D.");
    hold(serverDoc);
  }
  render();
  watchWorkers(detail);
  preloadNext(detail);
  root.dataset.state = "ready";
}

// Why this frame will not (or did not) become a sample, above the stage: said before the work, not after
// the submit. A failed generate job links to its page, where a curator retries it once the cause is fixed.
function showSampleNote(detail) {
  const failed = detail.generate_failed;
  const reason = detail.sample_blocker ?? failed?.error;
  $("sample-note").hidden = !reason;
  if (!reason) return;
  $("sample-note-title").textContent = detail.sample_blocker
    ? "This frame cannot become a sample in this workspace; a submit is refused (your planes stay a draft):"
    : `Its sample could not be made (generate job ${failed.job_id} failed):`;
  $("sample-note-reason").textContent = reason;
  const more = $("sample-note-more");
  more.replaceChildren();
  if (failed) {
    more.append(el("a", { href: `/jobs/${failed.job_id}` }, `Job ${failed.job_id}`),
                ": a curator retries it there once the cause is fixed.");
  }
}

// Frames this annotator submitted whose sample could not be made: named on the next page, so a failure
// after the submit does not go unseen. The link opens the job, whose page says why and offers the retry.
function showFailedElsewhere(failed) {
  const first = failed?.[0];
  $("failed-elsewhere").hidden = !first;
  if (!first) return;
  const others = failed.length > 1 ? ` (${plural(failed.length - 1, "other frame")} too)` : "";
  $("failed-elsewhere-text").textContent = `Frame #${first.frame_id}, which you submitted, got no sample${others}: `
    + `${first.error ?? "its generate job failed"}.`;
  const link = $("failed-elsewhere-link");
  link.href = `/jobs/${first.job_id}`;
  link.textContent = `Job ${first.job_id}`;
}

// A frame a curator sent back: who, when and why, above the stage.
function showReturned(returned) {
  $("returned").hidden = !returned;
  if (!returned) return;
  const to = returned.annotator === root.dataset.user || !returned.annotator ? "you" : returned.annotator;
  const when = returned.at ? ` on ${new Date(returned.at).toLocaleString()}` : "";
  $("returned-title").textContent = `Sent back to ${to} by ${returned.by}${when}, who rejected its sample:`;
  $("returned-reason").textContent = rejectionText(returned) || "(no reason given)";
}

// Frames a curator sent back to this annotator while another one is on the page (`returned_waiting`
// of the frame's detail and of each lease renewal): the oldest named above the stage, with a link.
// Opening it leaves this frame's lease as it is: the frame stays this annotator's, and the queue
// hands it back once the returned one is submitted.
export function showWaiting(waiting) {
  const first = waiting?.frames?.[0];
  $("came-back").hidden = !first;
  if (!first) return;
  const when = first.at ? ` on ${new Date(first.at).toLocaleString()}` : "";
  const others = waiting.count > 1 ? ` ${plural(waiting.count - 1, "other frame")} came back too.` : "";
  $("came-back-text").textContent = `Frame #${first.frame_id} came back to you: ${first.by} rejected its sample${when} `
    + `(${rejectionText(first) || "no reason given"}).${others} You keep this frame meanwhile.`;
  const link = $("came-back-link");
  link.href = `/annotate/${first.frame_id}`;
  link.textContent = `Open frame #${first.frame_id}`;
  link.onclick = (event) => {
    if (event.button !== 0 || event.ctrlKey || event.metaKey || event.shiftKey || event.altKey) return;  // a new tab
    event.preventDefault();
    navigate(async () => first.frame_id, "push", { keep: true });
  };
}

function readOnly(reason) {
  page.session = null;
  setTool("click");
  const submitted = reason === "it is submitted";
  say(`This frame is read-only: ${reason}.`);
  saveState(submitted ? "Submitted" : "Read-only", submitted ? "ok" : "");
  if (submitted) banner("Submitted — shown read-only.", "Edit this frame", takeOver);
  else banner(`Read-only: ${reason}.`, "Next frame from the queue ⏎", () => navigate(fromQueue));
  render();
}

async function takeOver() {
  const res = await call(`${API}/frames/${page.frame.id}/lease`);
  if (sessionEnded(res.error)) return;
  if (!res.ok) return readOnly(res.error.message);
  hold(page.history.doc);
  say("You hold this frame now; changes are saved as drafts until you submit again.");
  render();
}

function hold(serverDoc) {
  const held = page.frame;
  const here = (hook) => (...args) => page.frame === held && hook(...args);  // the page may have moved on
  page.session = new FrameSession(API, held, serverDoc, {
    saving: here(() => saveState("Saving…")),
    saved: here((doc, version) => {
      const latest = page.history.doc;
      if (doc === latest) S.dropDraft(held.id);
      else S.storeDraft(held.id, version, latest, held.height, held.width);
      saveState(doc === latest ? "Draft saved" : "Unsaved changes", doc === latest ? "ok" : "");
    }),
    conflict: here((message) => {
      saveState("Not saved", "error");
      say(message, "error");
      banner("Someone else saved this frame since you opened it. Your changes are kept in this browser.",
             "Reload the frame", () => navigate(async () => held.id, "replace"));
    }),
    failed: here((err) => {
      saveState("Not saved — retrying", "error");
      if (sessionEnded(err)) return;
      say(`Could not save the draft (${err.message}); it is kept in this browser and retried.`, "error");
    }),
    leaseKept: here((renewal) => showWaiting(renewal.returned_waiting)),
    leaseLost: here((message) => {  // another annotator took it while the lease had run out, or it left the queue
      readOnly(message);
      say(`This frame is read-only: ${message}. Your changes are kept in this browser.`, "error");
    }),
  });
  page.session.keepLease(LEASE_S);
  if (held.submitted) saveState("Submitted", "ok");
  else saveState(held.annotation_version ? "Draft saved" : "New frame", held.annotation_version ? "ok" : "");
  restoreDraft();
}

// A crash or a closed tab leaves the latest changes in localStorage; bring them back.
function restoreDraft() {
  const draft = S.loadDraft(page.frame.id);
  if (!draft) return;
  const mine = S.fromServer(draft);
  if (draft.base === page.frame.annotation_version) {
    commit(mine);
    say("Restored your unsaved changes from this browser.");
  } else {
    banner(`This browser kept changes you made to an older version of this frame (${new Date(draft.savedAt)
      .toLocaleString()}).`, "Use my changes", () => commit(mine));
  }
}

// What workers compute for an open frame: its embedding (said until it is there) and its proposals
// (shown as they come). Looked up again while either is missing and the frame is on screen.
async function watchWorkers(detail) {
  $("preparing").hidden = detail.embedding_ready || !page.session;
  const missing = (looks) => !$("preparing").hidden || (awaitingProposals() && looks < PROPOSAL_LOOKS);
  for (let looks = 0; page.frame === detail && missing(looks); looks++) {
    await sleep(READY_RECHECK_MS);
    const now = await api(`${API}/frames/${detail.id}`).catch(() => null);
    if (!now || page.frame !== detail) continue;
    if (now.embedding_ready) $("preparing").hidden = true;
    offerProposals(now);
    render();
  }
}

// The next frame of the video is the likely next one: have its image in the browser cache already.
function preloadNext(detail) {
  if (detail.next_id == null) return;
  setTimeout(() => api(`${API}/frames/${detail.next_id}`)
    .then((next) => { new Image().src = root.dataset.media + next.image; })
    .catch(() => {}), 500);
}

async function showEmpty() {
  page.frame = null;
  page.history = null;
  root.dataset.state = "empty";
  $("empty").hidden = false;
  $("frame-title").textContent = "Annotate";
  $("frame-info").textContent = "";
  $("preparing").hidden = true;
  $("returned").hidden = true;
  $("came-back").hidden = true;
  banner(null);
  saveState("");
  say("All caught up: no approved frames are waiting.");
  view.setImage(null);
  render();
  while (root.dataset.state === "empty") {
    await sleep(QUEUE_RECHECK_MS);
    if (root.dataset.state === "empty" && !document.hidden) await checkQueue();
  }
}

export async function checkQueue() {
  const res = await call(`${API}/queue/annotate/next`);
  if (res.ok) navigate(async () => res.data.frame_id);
}
