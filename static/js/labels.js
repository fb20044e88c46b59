// How pages name things, so that a count, a video or a frame reads the same everywhere.

export const plural = (n, word, many = `${word}s`) => `${n} ${n === 1 ? word : many}`;

// A video by its name; a frame by its id (the number in its address, never its index in the
// video); where it is in the video by time: "synthetic-0000 · frame #4 · 1.5 s".
export function framePlace(item, frameId = item.id) {
  return `${item.video ?? `video #${item.video_id}`} · frame #${frameId} · ${item.time_s.toFixed(1)} s`;
}

// A number as people read it: whole numbers whole, others to `digits` significant digits
// (61.09056854248047 → "61.09"), the very small or large with an exponent (0.0000234 → "2.34e-5");
// "—" for none. Every page shows its figures through this.
export function formatNumber(value, digits = 4) {
  if (value == null || value === "") return "—";
  const n = Number(value);
  if (!Number.isFinite(n)) return String(value);
  if (Number.isInteger(n)) return String(n);
  const a = Math.abs(n);
  if (a < 1e-3 || a >= 1e6) return n.toExponential(Math.max(0, digits - 2)).replace(/\.?0+e/, "e").replace("e+", "e");
  return String(Number(n.toPrecision(digits)));
}
