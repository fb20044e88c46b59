// How a frame leaves the annotator's hands, and the next one comes from the queue: submitted once
// every plane used has an illusion and a type, or deleted with a reason.
import { choose } from "../dialogs.js";
import { call } from "../request.js";
import { sayFailure } from "../session_ended.js";
import { editable, pickType, selectPair } from "./editing.js";
import { checkQueue, fromQueue, navigate } from "./lifecycle.js";
import { planeName, say, saveState } from "./messages.js";
import { $, API, page, ui } from "./page.js";
import { masksArrived } from "./segment.js";
import * as S from "./state.js";

// Enter. Read-only, or with no frame, Enter just takes the next frame.
export async function submit() {
  if (!page.frame) return checkQueue();
  if (!page.session) return navigate(fromQueue);
  await masksArrived();
  const doc = page.history.doc;
  const used = doc.pairs.filter((p) => p.illusion?.area || p.support?.area);
  if (!used.length) return say("Click the illusion first: there is nothing to submit yet.", "error");
  const noIllusion = used.find((p) => !p.illusion?.area);
  if (noIllusion) {
    selectPair(noIllusion.id, "illusion");
    return say(`${planeName(noIllusion.id)} has a support region but no illusion: click the illusion.`, "error");
  }
  const untyped = used.find((p) => !p.type);
  if (untyped) {
    selectPair(untyped.id, ui.kind);
    if (!await pickType(untyped.id)) {
      return say(`Not submitted: ${planeName(untyped.id)} needs an illusion type (T, or Enter again to choose).`, "error");
    }
    return submit();
  }
  const noSupport = used.filter((p) => !p.support?.area);
  if (noSupport.length) {
    $("confirm-title").textContent = `${noSupport.map((p) => planeName(p.id)).join(", ").replace(/^p/, "P")} `
      + `${noSupport.length === 1 ? "has" : "have"} no support region — submit anyway?`;
    if (await choose($("confirm-dialog")) !== "yes") return say("Not submitted: add the support, or submit anyway.");
  }
  say("Submitting…");
  const res = await page.session.submit(page.history.doc);
  if (!res.ok) {
    // Refused because the frame cannot become a sample: the regions were saved as a draft, so the
    // page goes on from the version that draft got.
    if (res.status === 409 && res.data.sample_blocker) {
      page.session.version = res.data.annotation_version;
      page.session.saved = page.history.doc;
      saveState("Draft saved", "");
      return say(res.error.message, "error");
    }
    if (res.status === 409) page.session.hooks.conflict(res.error.message);
    return sayFailure(say)(res.error);
  }
  S.dropDraft(page.frame.id);
  const done = page.frame.id;
  page.session = null;
  await navigate(fromQueue);
  if (page.frame && page.frame.id !== done) say(`Submitted frame #${done}. This is the next one.`, "ok");
}

// Delete, with a reason: the frame leaves the pipeline, and the next one comes from the queue.
export async function deleteFrame() {
  if (!editable()) return;
  const { frame, session } = page;
  const reason = await choose($("delete-dialog"));
  if (!reason) return;
  const res = await call(`${API}/frames/${frame.id}/delete`, { body: { reason } });
  if (!res.ok) return sayFailure(say)(res.error);
  S.dropDraft(frame.id);
  session.close();
  page.session = null;
  await navigate(fromQueue);
  say(`Deleted frame #${frame.id} (${reason}).`, "ok");
}
