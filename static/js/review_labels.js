// How the review page words a frame and its prefilter result, on the tiles and in the large view.
import { el } from "./api.js";

// The default (heuristic) prefilter's measurements: short names that fit a tile, the meaning on hover.
// Other backends' figures show under their own names.
const METRICS = {
  laplacian_var: ["sharpness", "variance of the Laplacian over the whole frame"],
  laplacian_var_p90: ["sharpest parts", "90th percentile of the Laplacian variance over a grid of tiles"],
  brightness: ["brightness", "mean grey level, 0–1"],
  contrast: ["contrast", "standard deviation of the grey level, 0–1"],
  text_area_fraction: ["text area", "share of the frame inside detected text lines"],
  caption_band_fraction: ["caption band", "share of the frame's height in caption rows at the top or bottom"],
  corner_text_count: ["corner text", "text lines in a corner (watermarks, logos)"],
};

export const answerOf = (value) => (value === true ? "yes" : value === false ? "no" : "unknown");
export const verdictOf = (keep) => (keep === true ? "keep" : keep === false ? "drop" : "no verdict");
const formatNumber = (v) => (typeof v === "number" ? String(Number(v.toPrecision(3))) : String(v));

// The prefilter's measurements as a definition list; every entry's tooltip says what it measures.
export function metricList(metrics) {
  return el("dl", { className: "metrics" }, ...Object.entries(metrics).map(([name, value]) => {
    const [label, meaning] = METRICS[name] ?? [name.replaceAll("_", " "), ""];
    const title = `${label}: ${formatNumber(value)}${meaning ? ` — ${meaning}` : ""} (${name})`;
    return el("div", { title }, el("dt", {}, label), el("dd", {}, formatNumber(value)));
  }));
}
