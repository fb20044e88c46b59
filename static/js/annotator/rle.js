// COCO run-length encoding, as pycocotools writes it: runs over the mask in column-major order,
// alternating background/foreground starting with background, as a compact string (LEB-like
// 5-bit groups, each run stored as the difference to the run two before it).
// Masks here are Uint8Array(height * width) in row-major order (1 = inside).

export function decodeCounts(text) {
  const counts = [];
  let p = 0;
  while (p < text.length) {
    let x = 0, k = 0, more = true;
    while (more) {
      const c = text.charCodeAt(p) - 48;
      x |= (c & 0x1f) << (5 * k);
      more = (c & 0x20) !== 0;
      p += 1;
      k += 1;
      if (!more && (c & 0x10)) x |= -1 << (5 * k);
    }
    if (counts.length > 2) x += counts[counts.length - 2];
    counts.push(x);
  }
  return counts;
}

export function encodeCounts(counts) {
  let text = "";
  for (let i = 0; i < counts.length; i++) {
    let x = counts[i];
    if (i > 2) x -= counts[i - 2];
    let more = true;
    while (more) {
      let c = x & 0x1f;
      x >>= 5;
      more = (c & 0x10) ? x !== -1 : x !== 0;
      if (more) c |= 0x20;
      text += String.fromCharCode(c + 48);
    }
  }
  return text;
}

export function rleToMask(rle) {
  const [height, width] = rle.size;
  const mask = new Uint8Array(height * width);
  const counts = typeof rle.counts === "string" ? decodeCounts(rle.counts) : rle.counts;
  let pos = 0, value = 0;
  for (const run of counts) {
    if (value) {
      for (let i = pos; i < pos + run; i++) {
        const x = Math.floor(i / height), y = i - x * height;
        mask[y * width + x] = 1;
      }
    }
    pos += run;
    value ^= 1;
  }
  return mask;
}

export function maskToRle(mask, height, width) {
  const counts = [];
  let value = 0, run = 0;
  for (let x = 0; x < width; x++) {
    for (let y = 0; y < height; y++) {
      if (mask[y * width + x] !== value) {
        counts.push(run);
        run = 0;
        value ^= 1;
      }
      run += 1;
    }
  }
  counts.push(run);
  return { size: [height, width], counts: encodeCounts(counts) };
}

export function area(mask) {
  let n = 0;
  for (let i = 0; i < mask.length; i++) n += mask[i];
  return n;
}
