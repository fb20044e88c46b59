// Line charts in inline SVG: several series against step, redrawn whole on every update (a few
// thousand points at most, so there is nothing to gain from patching the DOM).
import { formatNumber } from "./labels.js";

const NS = "http://www.w3.org/2000/svg";
const W = 640, H = 230, PAD = { left: 56, right: 12, top: 22, bottom: 38 };
export const COLORS = ["#4f46e5", "#dc2626", "#059669", "#d97706", "#0891b2", "#7c3aed", "#be185d", "#4b5563"];

function svg(tag, attrs = {}, text) {
  const node = document.createElementNS(NS, tag);
  for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, value);
  if (text !== undefined) node.textContent = text;
  return node;
}

// A round step for about n ticks between lo and hi; whole when `integer` (steps).
function tickStep(lo, hi, n, integer) {
  const raw = (hi - lo) / n;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const nice = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) ?? raw;
  return integer ? Math.max(1, Math.round(nice)) : nice;
}

// Round values between lo and hi, about n of them; whole numbers only when `integer` (steps).
export function ticks(lo, hi, n = 4, { integer = false } = {}) {
  if (!(hi > lo)) return [lo];
  const step = tickStep(lo, hi, n, integer);
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(v);
  return out;
}

// A value axis over [lo, hi] widened to the round ticks around it: ticks at both ends, and at least
// three (the range spans at least 1.6 steps, so the widened ends are two or more steps apart).
export function niceAxis(lo, hi, n = 4) {
  if (!(hi > lo)) return { lo, hi, ticks: [lo] };
  const step = tickStep(lo, hi, n, false);
  const [first, last] = [Math.floor(lo / step), Math.ceil(hi / step)];
  const ticks = Array.from({ length: last - first + 1 }, (_, i) => (first + i) * step);
  return { lo: ticks[0], hi: ticks.at(-1), ticks };
}

const label = (v) => formatNumber(v, 3);

// A chart in `container`; `update(series)` draws [{name, color, points: [[step, value], …]}] against
// the x axis named `xLabel`.
export function lineChart(container, { title, yLabel = "", xLabel = "step" }) {
  const root = svg("svg", { viewBox: `0 0 ${W} ${H}`, class: "chart", role: "img", "aria-label": title });
  container.append(root);
  return {
    element: root,
    update(series) {
      const finite = series.map((s) => ({ ...s, points: s.points.filter(([x, y]) => Number.isFinite(x) && Number.isFinite(y)) }));
      const all = finite.flatMap((s) => s.points);
      root.replaceChildren(svg("text", { x: PAD.left, y: 14, class: "chart-title" }, title + (yLabel ? ` (${yLabel})` : "")));
      root.dataset.points = String(all.length);
      if (!all.length) {
        root.append(svg("text", { x: W / 2, y: H / 2, "text-anchor": "middle", class: "chart-empty" }, "no points yet"));
        return;
      }
      let [x0, x1] = [Math.min(...all.map((p) => p[0])), Math.max(...all.map((p) => p[0]))];
      let [y0, y1] = [Math.min(...all.map((p) => p[1])), Math.max(...all.map((p) => p[1]))];
      if (x1 === x0) { x0 -= 1; x1 += 1; }
      if (y1 === y0) { const d = Math.abs(y0) * 0.1 || 1; y0 -= d; y1 += d; }
      const yAxis = niceAxis(y0, y1);
      [y0, y1] = [yAxis.lo, yAxis.hi];
      const sx = (x) => PAD.left + ((x - x0) / (x1 - x0)) * (W - PAD.left - PAD.right);
      const sy = (y) => H - PAD.bottom - ((y - y0) / (y1 - y0)) * (H - PAD.top - PAD.bottom);
      for (const t of yAxis.ticks) {
        root.append(svg("line", { x1: PAD.left, x2: W - PAD.right, y1: sy(t), y2: sy(t), class: "chart-grid" }),
                    svg("text", { x: PAD.left - 6, y: sy(t) + 4, "text-anchor": "end", class: "chart-tick" }, label(t)));
      }
      for (const t of ticks(x0, x1, 6, { integer: true })) {
        root.append(svg("text", { x: sx(t), y: H - PAD.bottom + 14, "text-anchor": "middle", class: "chart-tick" }, label(t)));
      }
      root.append(svg("text", { x: (PAD.left + W - PAD.right) / 2, y: H - 4, "text-anchor": "middle", class: "chart-axis" },
                      xLabel));
      finite.forEach((s, i) => {
        const color = s.color ?? COLORS[i % COLORS.length];
        const d = s.points.map(([x, y], k) => `${k ? "L" : "M"}${sx(x).toFixed(1)},${sy(y).toFixed(1)}`).join("");
        root.append(svg("path", { d, fill: "none", stroke: color, "stroke-width": 1.6, class: "chart-line",
                                  "data-series": s.name }));
        if (s.points.length <= 40) {
          for (const [x, y] of s.points) root.append(svg("circle", { cx: sx(x), cy: sy(y), r: 2.2, fill: color }));
        }
      });
      if (finite.length > 1) {
        finite.forEach((s, i) => {
          const x = W - PAD.right - 130, y = PAD.top + 4 + i * 14;
          root.append(svg("rect", { x, y: y - 8, width: 10, height: 3, fill: s.color ?? COLORS[i % COLORS.length] }),
                      svg("text", { x: x + 14, y: y - 4, class: "chart-tick" }, s.name));
        });
      }
    },
  };
}
