// How pages name things, so that a count, a video or a frame reads the same everywhere.

export const plural = (n, word, many = `${word}s`) => `${n} ${n === 1 ? word : many}`;

// A video by its name; a frame by its id (the number in its address, never its index in the
// video); where it is in the video by time: "synthetic-0000 · frame #4 · 1.5 s".
export function framePlace(item, frameId = item.id) {
  return `${item.video ?? `video #${item.video_id}`} · frame #${frameId} · ${item.time_s.toFixed(1)} s`;
}
