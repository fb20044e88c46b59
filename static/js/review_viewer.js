// The review page's large view: one frame at full resolution beside everything the prefilter said
// about it. It is modal and hides the page's status line, so it has a status line of its own.
import { el } from "./api.js";
import { framePlace } from "./labels.js";
import { answerOf, metricList, verdictOf } from "./review_labels.js";

const $ = (id) => document.getElementById(id);

// Shows `item` in the dialog `viewer` (opened or not).
export function show(viewer, item, { media, questions }) {
  const result = item.prefilter;
  const image = $("viewer-image");
  image.src = media + item.image;
  image.alt = `Frame ${item.id}, full resolution`;
  viewer.ariaLabel = `Frame ${item.id}`;
  $("viewer-info").replaceChildren(
    el("h2", {}, `Frame #${item.id}`, el("span", { className: `badge state ${item.state}` }, item.state)),
    el("p", { className: "muted" }, `${framePlace(item)} · ${item.width}×${item.height}`),
    item.last_review && item.state !== "prefiltered"
      ? el("p", {}, `${item.last_review.decision === "approve" ? "Approved" : "Rejected"}`,
           item.last_review.reason ? ` (${item.last_review.reason})` : "", ` by ${item.last_review.user ?? "?"}`)
      : "",
    result ? el("p", {}, el("strong", {}, `VLM ${verdictOf(result.keep)}`), result.reason ? ` — ${result.reason}` : "")
           : el("p", { className: "muted" }, "No VLM result yet."),
    result ? el("p", { className: "muted" }, `${result.backend} · ${result.model_id} · prompt ${result.prompt_version}`) : "",
    el("table", { className: "questions" }, ...questions.map((question, i) => {
      const answer = answerOf(result?.answers?.[i]);
      return el("tr", {}, el("td", { className: "n" }, `${i + 1}`), el("td", {}, question),
                el("td", { className: `answer ${answer}` }, answer));
    })),
    metricList(result?.metrics ?? {}),
    result?.raw ? el("details", {}, el("summary", {}, "Raw VLM answer"), el("pre", {}, result.raw)) : "",
  );
}

// Opens the dialog on `item`, with its status line cleared; the keyboard goes to the dialog itself,
// not its first button, where Enter or Space would press it.
export function open(viewer, item, context) {
  $("viewer-status").textContent = "";
  show(viewer, item, context);
  viewer.showModal();
  viewer.focus();
}

// The dialog's buttons (data-action) run `actions[action]`; a click on the backdrop closes it.
export function listen(viewer, actions) {
  viewer.addEventListener("click", (event) => {
    const action = event.target.closest("[data-action]")?.dataset.action;
    if (action === "close") viewer.close();
    else actions[action]?.();
    if (event.target === viewer) viewer.close();
  });
}
