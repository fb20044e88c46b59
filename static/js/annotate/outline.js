// A mask's outline as closed loops along its pixels' edges, for dashed strokes: a dash pattern runs on
// along one subpath, so each loop is one, not a heap of pixel sides. Image pixel (x, y) covers
// [x, x + 1) × [y, y + 1), so the loops' corners are whole numbers. Masks are Uint8Array(height × width),
// row-major, 1 inside.

// { path: Path2D in image px (fill it with "evenodd" to keep the holes), box: [x0, y0, x1, y1] pixel
// corners around the mask } | null for an empty mask.
export function outlineOf(mask, width, height) {
  const across = width + 1;  // corner (x, y) is vertex y × across + x
  const next = new Map();    // vertex → the vertices its boundary edges lead to (two where pixels touch diagonally)
  const edge = (a, b) => {
    const ends = next.get(a);
    if (ends) ends.push(b);
    else next.set(a, [b]);
  };
  let x0 = width, y0 = height, x1 = -1, y1 = -1;
  for (let y = 0, i = 0; y < height; y++) {
    for (let x = 0; x < width; x++, i++) {
      if (!mask[i]) continue;
      x0 = Math.min(x0, x); x1 = Math.max(x1, x); y1 = y;
      if (y0 === height) y0 = y;
      // each side facing the outside, clockwise round the pixel: every corner has as many edges in as
      // out, so a walk from any edge comes back to where it began
      const v = y * across + x;
      if (y === 0 || !mask[i - width]) edge(v, v + 1);
      if (x === width - 1 || !mask[i + 1]) edge(v + 1, v + 1 + across);
      if (y === height - 1 || !mask[i + width]) edge(v + 1 + across, v + across);
      if (x === 0 || !mask[i - 1]) edge(v + across, v);
    }
  }
  if (x1 < 0) return null;
  const path = new Path2D();
  const to = (v, move) => (move ? path.moveTo : path.lineTo).call(path, v % across, Math.floor(v / across));
  for (const [start, ends] of next) {
    while (ends.length) {
      to(start, true);
      let at = ends.pop(), step = at - start;
      while (at !== start) {
        const after = next.get(at).pop();
        if (after - at !== step) to(at);  // corners only: a straight run is one segment
        step = after - at;
        at = after;
      }
      path.closePath();
    }
  }
  return { path, box: [x0, y0, x1 + 1, y1 + 1] };
}
