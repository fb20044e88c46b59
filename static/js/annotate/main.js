// The click-annotation page: clicks become masks for illusion/support pairs (planes), brush
// touch-ups, drafts saved on the server and in this browser, submit → the next frame from the queue,
// propagation, delete. A click shows its dot at once and the mask when the server answers; the page
// never blocks on it. This module maps the keys to what they do and starts the page.
// Its parts: lifecycle.js and submit.js (a frame onto the page and off it), editing.js (changes to
// the annotation), segment.js (clicks → masks), tools.js (the canvas and its tools), panel.js,
// render.js, messages.js, propagate.js and proposals.js (the machine's proposals to accept or reject);
// page.js holds the state they share.
import { keyChoices } from "../dialogs.js";
import { keyboardHelp } from "../help.js";
import { addPair, clearRegion, pickType, removePair, selectKind, selectPair, undoRedo } from "./editing.js";
import { helpRows, shortcutFor } from "./keys.js";
import { start, stepFrame } from "./lifecycle.js";
import { $, page, prefs, root } from "./page.js";
import { listenPanel } from "./panel.js";
import { propagate } from "./propagate.js";
import {
  acceptProposal, cycleProposal, highlighted, rejectProposal, shownProposals, toggleShowAll, wantsTab,
} from "./proposals.js";
import { render } from "./render.js";
import { deleteFrame, submit } from "./submit.js";
import { setBrush, setOpacity, setTool, toggleMasks, view } from "./tools.js";

// By the command names of keys.js; `key` is the key that chose the command.
const COMMANDS = {
  illusion: () => selectKind("illusion"),
  support: () => selectKind("support"),
  addPair,
  selectPair: (key) => {
    const pair = page.history?.doc.pairs[Number(key) - 1];
    if (pair) selectPair(pair.id);
  },
  removePair,
  clear: clearRegion,
  acceptProposal: () => acceptProposal(),
  rejectProposal: () => rejectProposal(),
  highlightProposal: (key) => cycleProposal(key === "Tab" ? 1 : -1),
  showAllProposals: toggleShowAll,
  clickTool: () => setTool("click"),
  brush: () => setTool("brush"),
  eraser: () => setTool("eraser"),
  brushSize: (key) => setBrush(key === "]" ? prefs.brush * 1.25 + 1 : prefs.brush / 1.25 - 1),
  undo: () => undoRedo("undo"),
  redo: () => undoRedo("redo"),
  zoom: (key) => view.zoomCentre(key === "-" ? 1 / 1.25 : 1.25),
  fit: () => view.fit(),
  opacity: (key) => setOpacity(prefs.opacity + (key === "o" ? 0.1 : -0.1)),
  hide: toggleMasks,
  pickType: () => pickType(),
  submit,
  step: (key) => stepFrame(key === "ArrowLeft" ? -1 : 1),
  propagate,
  deleteFrame,
};
// Keys that keep their usual job where their command has nothing to act on: Tab moves the focus.
const WANTED = { highlightProposal: wantsTab };

document.querySelectorAll("dialog.choices").forEach(keyChoices);  // 1–9 choose a type or a reason

document.addEventListener("keydown", (event) => {
  if (event.defaultPrevented) return;  // a dialog's choice
  if (document.querySelector("dialog[open]")) return;
  if (event.target.closest("input, select, textarea")) {
    if (event.key === "Escape") $("canvas").focus();
    return;
  }
  if (["Enter", " "].includes(event.key) && event.target.closest("button, a")) return;  // let them press
  const shortcut = shortcutFor(event);
  if (!shortcut || (!page.history && shortcut.command !== "submit")) return;
  if (WANTED[shortcut.command]?.(event) === false) return;
  event.preventDefault();
  COMMANDS[shortcut.command](shortcut.key);
});

// Tests and the curious may look, read-only.
window.annotator = {
  get frame() { return root.dataset.state === "ready" ? page.frame : null; },
  get pairs() {
    return (page.history?.doc.pairs ?? []).map((p) => ({ id: p.id, illusion: p.illusion?.area ?? 0,
                                                        support: p.support?.area ?? 0, type: p.type ?? null }));
  },
  get proposals() {
    const shown = shownProposals(), chosen = highlighted(shown);
    return shown.map((p) => ({ id: p.id, source: p.source, score: p.score, type: p.illusion_type,
                               highlighted: p === chosen }));
  },
  get dirty() { return Boolean(page.session && page.history.doc !== page.session.saved); },
  imageToClient: (x, y) => view.imageToClient(x, y),
};

listenPanel();
keyboardHelp(helpRows(),
             { note: "Work is saved as a draft two seconds after each change and kept in this browser until then." });
render();
start(Number(root.dataset.frameId));
