// Accept/reject of one sample, shared by the samples grid and the sample page.
import { api } from "./api.js";
import { reasonShortcut } from "./dialogs.js";

// POSTs the decision to the sample's API URL; resolves to the updated sample.
export function review(sampleUrl, decision, reason = "") {
  return api(`${sampleUrl}/review`, { method: "POST", body: { decision, reason } });
}

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
  const num = (v, unit = "") => (v == null ? "–" : `${Number(v.toPrecision(3))}${unit}`);
  const inliers = (qa.pairs ?? []).map((p) => p.inlier_ratio).filter((v) => v != null);
  return [
    ["holes", pct(qa.hole_fraction), "share of the right view inpainted", flagged("holes")],
    ["EPE", num(qa.stereo_epe, " px"), "SGBM end-point error on the synthesized pair", flagged("SGBM EPE")],
    ["inliers", inliers.length ? pct(Math.min(...inliers)) : "–", "lowest share of plane-fit inliers over the pairs",
     flagged("pair ")],
    ["scale", num(qa.scale ?? sample.params?.scale), "px per unit of monocular disparity", false],
  ];
}
