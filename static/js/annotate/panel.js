// The side panel: region and tool switches, brush and opacity sliders, the machine's proposals, the
// planes with their regions and types, and the frame's actions. Its controls act like their keys.
import { el } from "../api.js";
import { addPair, removePair, selectKind, selectPair, setType } from "./editing.js";
import { checkQueue, stepFrame } from "./lifecycle.js";
import { regionName } from "./messages.js";
import { $, page, prefs, root, ui } from "./page.js";
import { propagate } from "./propagate.js";
import {
  acceptProposal, highlighted, highlightProposal, proposalsNote, rejectProposal, showingAll, shownProposals, toggleShowAll,
} from "./proposals.js";
import * as S from "./state.js";
import { deleteFrame, submit } from "./submit.js";
import { setBrush, setOpacity, setTool, view } from "./tools.js";

export function renderPanel(doc) {
  for (const b of document.querySelectorAll(".segmented [data-kind]")) b.setAttribute("aria-pressed", b.dataset.kind === ui.kind);
  for (const b of document.querySelectorAll(".tools [data-tool]")) b.setAttribute("aria-pressed", b.dataset.tool === view.tool);
  $("brush-size").value = prefs.brush;
  $("brush-size-value").textContent = `${prefs.brush} px`;
  $("opacity").value = prefs.opacity;
  $("opacity-value").textContent = ui.hidden ? "hidden" : `${Math.round(prefs.opacity * 100)}%`;
  const locked = !page.session;
  for (const id of ["add-pair", "propagate", "delete"]) $(id).disabled = locked;
  $("submit").replaceChildren(page.frame && locked ? "Next from the queue " : "Submit ", el("kbd", {}, "Enter"));
  $("submit").disabled = !page.frame && root.dataset.state !== "empty";
  $("pairs").replaceChildren(...(doc?.pairs ?? []).map((p, i) => pairRow(p, i + 1)));
  const shown = shownProposals(), chosen = highlighted(shown);
  $("proposals-section").hidden = locked;
  $("proposals-note").textContent = proposalsNote(shown);
  $("show-all-proposals").checked = showingAll();
  $("proposals").replaceChildren(...shown.map((p) => proposalRow(p, p === chosen)));
}

// A proposal's row: where it comes from, its score and type guess, and its two decisions (with their
// keys on the highlighted one, which the keys act on).
function proposalRow(p, chosen) {
  const key = (k) => (chosen ? el("kbd", {}, k) : "");
  return el("li", { className: "proposal", dataset: { proposal: p.id, hidden: String(Boolean(p.hidden)) },
                    ariaCurrent: String(chosen),
                    title: chosen ? "Highlighted: the keys act on it (Tab: the next one)" : "Click to highlight it" },
  el("span", { className: "source" }, p.source),
  el("span", { className: "score", title: p.hidden ? `The proposer's confidence, 0–1: under the threshold ${p.threshold.toFixed(2)}, `
                + "shown because Show all is on (V)" : "The proposer's confidence, 0–1" }, p.score.toFixed(2)),
  el("span", { className: "type", dataset: { guessed: p.illusion_type ? "yes" : "no" } }, p.illusion_type ?? "type?"),
  el("span", { className: "decide" },
    el("button", { type: "button", dataset: { decide: "accept" }, title: "Accept: a plane with its masks, to correct with clicks (a)" },
       "Accept", key("A")),
    el("button", { type: "button", className: "ghost", dataset: { decide: "reject" }, title: "Reject: not an illusion (r)" },
       "Reject", key("R"))));
}

// A plane's row: its number (see planeName), its two regions as chips, its own type, remove.
function pairRow(pair, n) {
  const chip = (kind) => {
    const area = pair[kind]?.area ?? 0;
    const stale = pair[kind]?.stale;
    return el("button", {
      type: "button", className: `chip ${kind}`, dataset: { chip: kind, done: area ? "yes" : "no" },
      title: `${regionName(kind, pair.id)}: ${area ? `${area.toLocaleString()} px` : "none yet"}`,
      ariaPressed: String(pair.id === ui.pair && kind === ui.kind),
    }, el("span", { className: "mark" }, stale ? "…" : area ? "✓" : "○"), ` ${kind}`);
  };
  return el("li", {
    className: "pair", dataset: { pair: pair.id }, ariaCurrent: pair.id === ui.pair ? "true" : "false",
    style: `--pair: ${S.colourOf(pair.id)}`,
  },
  el("span", { className: "swatch", ariaHidden: "true" }),
  el("span", { className: "name" }, `Plane ${n}`, n <= 9 ? el("kbd", {}, String(n)) : ""),
  el("span", { className: "chips" }, chip("illusion"), chip("support")),
  pairType(pair, n),
  el("button", { type: "button", className: "remove", title: "Remove this plane (Backspace)",
                 ariaLabel: `Remove plane ${n}` }, "×"));
}

// The plane's illusion type, the types being the type dialog's choices.
function pairType(pair, n) {
  const options = [...$("type-dialog").querySelectorAll("button.choice")]
    .map((b) => el("option", { value: b.value, selected: b.value === pair.type }, b.value));
  return el("select", {
    className: "pair-type", ariaLabel: `Illusion type of plane ${n}`, disabled: !page.session,
    title: "This plane's illusion type (T)", dataset: { chosen: pair.type ? "yes" : "no" },
    onclick: (event) => event.stopPropagation(),  // choosing a type is not selecting the plane
    onchange: (event) => setType(event.target.value || null, pair.id),
  }, el("option", { value: "", selected: !pair.type }, "type…"), ...options);
}

// Panel controls act like their keys, then hand the keyboard back to the canvas.
function onClick(target, run) {
  (typeof target === "string" ? $(target) : target).addEventListener("click", async (event) => {
    await run(event);
    if (!document.querySelector("dialog[open]")) $("canvas").focus({ preventScroll: true });
  });
}

export function listenPanel() {
  onClick("prev-frame", () => stepFrame(-1));
  onClick("next-frame", () => stepFrame(1));
  onClick("add-pair", addPair);
  onClick("propagate", propagate);
  onClick("submit", submit);
  onClick("delete", deleteFrame);
  onClick("check-again", checkQueue);
  onClick("show-all-proposals", toggleShowAll);
  onClick("proposals", (event) => {
    const row = event.target.closest("[data-proposal]");
    if (!row) return;
    const id = Number(row.dataset.proposal);
    const decide = event.target.closest("[data-decide]")?.dataset.decide;
    if (decide === "accept") return acceptProposal(id);
    if (decide === "reject") return rejectProposal(id);
    highlightProposal(id);
  });
  onClick("pairs", (event) => {
    const row = event.target.closest("[data-pair]");
    if (!row) return;
    const id = Number(row.dataset.pair);
    if (event.target.closest(".remove")) {
      selectPair(id);
      return removePair();
    }
    selectPair(id, event.target.closest("[data-chip]")?.dataset.chip ?? ui.kind);
  });
  for (const b of document.querySelectorAll(".segmented [data-kind]")) onClick(b, () => selectKind(b.dataset.kind));
  for (const b of document.querySelectorAll(".tools [data-tool]")) onClick(b, () => setTool(b.dataset.tool));
  $("opacity").addEventListener("input", (event) => setOpacity(Number(event.target.value)));
  $("brush-size").addEventListener("input", (event) => setBrush(Number(event.target.value)));
}
