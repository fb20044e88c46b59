// What the Models pages share: how a run's figures are written.
import { formatNumber } from "./labels.js";

export function runUrl(template, id) {
  return template.replace(/0$/, String(id));
}

export function duration(seconds) {
  if (seconds == null) return "—";
  const s = Math.round(seconds);
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s`;
  return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min`;
}

export function fixed(value, digits = 3) {
  return value == null ? "—" : Number(value).toFixed(digits);
}

export const short = (value) => formatNumber(value, 3);

export const LIVE = new Set(["queued", "running"]);
