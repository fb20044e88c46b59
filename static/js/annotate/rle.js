// COCO run-length encoding as pycocotools writes it. Runs go over the pixels in column-major order
// and alternate background/foreground, starting with a (possibly empty) background run. The
// compressed string packs each run, after the third one delta-coded against the run two before,
// into 5-bit little-endian groups offset by 48 ('0'), bit 0x20 meaning "more groups follow".
// Masks on the page are Uint8Array(height * width) in row-major order, 1 inside.

// Plain arithmetic instead of bit operators: 32-bit shifts would wrap for long runs.
export function decodeCounts(text) {
  const runs = [];
  let p = 0;
  while (p < text.length) {
    let value = 0;
    let scale = 1;
    let c;
    do {
      c = text.charCodeAt(p++) - 48;
      if (c < 0 || c > 63) throw new Error(`RLE counts: bad character ${text[p - 1]}`);
      value += (c & 0x1f) * scale;
      scale *= 32;
    } while (c & 0x20);
    if (c & 0x10) value -= scale;  // sign bit of the last group
    if (runs.length > 2) value += runs[runs.length - 2];
    runs.push(value);
  }
  return runs;
}

export function encodeCounts(runs) {
  let text = "";
  for (let i = 0; i < runs.length; i++) {
    let x = i > 2 ? runs[i] - runs[i - 2] : runs[i];
    let more = true;
    while (more) {
      let c = ((x % 32) + 32) % 32;  // the low 5 bits, also for negative x
      x = (x - c) / 32;              // floor division, like C's arithmetic shift
      more = (c & 0x10) ? x !== -1 : x !== 0;
      if (more) c |= 0x20;
      text += String.fromCharCode(c + 48);
    }
  }
  return text;
}

// Row-major mask → column-major runs.
export function toRuns(mask, height, width) {
  const runs = [];
  let current = 0;
  let length = 0;
  for (let x = 0; x < width; x++) {
    for (let i = x; i < mask.length; i += width) {
      if (mask[i] !== current) {
        runs.push(length);
        current = mask[i];
        length = 0;
      }
      length++;
    }
  }
  runs.push(length);
  return runs;
}

// Walks down the columns keeping (x, y), as a division per pixel costs more than the whole fill.
export function fromRuns(runs, height, width) {
  const mask = new Uint8Array(height * width);
  let x = 0, y = 0;
  for (let r = 0; r < runs.length; r++) {
    let n = runs[r];
    if (r % 2 === 0) {
      y += n;
      x += Math.floor(y / height);
      y %= height;
      continue;
    }
    for (; n > 0; n--) {
      mask[y * width + x] = 1;
      if (++y === height) {
        y = 0;
        x++;
      }
    }
  }
  return mask;
}

// The runs of a COCO RLE in either form the server may send.
export function runsOf(rle) {
  return typeof rle.counts === "string" ? decodeCounts(rle.counts) : rle.counts;
}

export function areaOf(runs) {
  let area = 0;
  for (let r = 1; r < runs.length; r += 2) area += runs[r];
  return area;
}
