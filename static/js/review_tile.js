// One frame's tile in the review grid: thumbnail with its state and VLM verdict, the last review,
// the twelve answers as chips and the prefilter's measurements.
import { el } from "./api.js";
import { framePlace } from "./labels.js";
import { answerOf, metricList, verdictOf } from "./review_labels.js";

const MARK = { yes: "✓", no: "✗", unknown: "?" };

// Fills `node` for `item`; `settled`: it has left the filter (kept in place, dimmed).
export function frameTile(node, item, { media, questions, settled }) {
  const image = node.querySelector("img") ?? el("img", {
    src: media + item.thumb, loading: "lazy", alt: "", width: 320, height: Math.round(320 * item.height / item.width),
  });
  node.dataset.id = item.id;
  node.dataset.state = item.state;
  node.classList.toggle("settled", settled);
  node.ariaLabel = `${framePlace(item)}, ${item.state}, VLM ${verdictOf(item.prefilter_keep)}`;
  node.replaceChildren(
    el("div", { className: "thumb" }, image,
       el("span", { className: `badge state ${item.state}` }, item.state),
       el("span", { className: `badge verdict ${verdictOf(item.prefilter_keep).replace(" ", "-")}`,
                    title: item.prefilter?.reason ?? "" }, `VLM ${verdictOf(item.prefilter_keep)}`)),
    el("div", { className: "meta" }, framePlace(item), lastReview(item)),
    // An approval would send the frame to annotators for nothing: say why before anyone works on it.
    item.sample_blocker ? el("p", { className: "sample-blocker", role: "note", title: item.sample_blocker },
                             "No samples: ", item.sample_blocker) : "",
    answerChips(questions, item.prefilter?.answers),
    metricList(item.prefilter?.metrics ?? {}),
  );
  return node;
}

function lastReview(item) {
  const last = item.last_review;
  if (!last || item.state === "prefiltered") return "";
  return el("span", { className: "reviewed", title: `${last.decision} by ${last.user ?? "?"} at ${last.at}` },
            last.reason ? `${last.reason} · ${last.user ?? ""}` : last.user ?? "");
}

function answerChips(questions, answers) {
  return el("ol", { className: "answers" }, ...questions.map((question, i) => {
    const answer = answerOf(answers?.[i]);
    return el("li", { className: answer, title: `${i + 1}. ${question}: ${answer}` }, MARK[answer]);
  }));
}
