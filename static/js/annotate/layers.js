// A mask drawn over the image: a filled canvas (drawn at the overlay opacity; hatched for support
// regions) and an outline canvas (always crisp), both covering only the mask's bounding box, so a
// small region on a 4K frame costs a small canvas. A layer being brushed covers the whole frame
// and is updated in place around each dab.

const HATCH = 10;       // px period of the support hatching
const OUTLINE = 2;      // px; an outline one pixel wide vanishes when a 1080p frame is shown at half size
const LIGHT = 90;       // alpha of the light part of a hatched fill, of 255

function rgb(hex) {
  const n = parseInt(hex.slice(1), 16);
  return [n >> 16, (n >> 8) & 255, n & 255];
}

function bounds(mask, width, height) {
  let x0 = width, y0 = height, x1 = -1, y1 = -1;
  for (let y = 0, i = 0; y < height; y++) {
    for (let x = 0; x < width; x++, i++) {
      if (mask[i]) {
        if (x < x0) x0 = x;
        if (x > x1) x1 = x;
        if (y < y0) y0 = y;
        y1 = y;
      }
    }
  }
  return x1 < 0 ? null : { x: x0, y: y0, w: x1 - x0 + 1, h: y1 - y0 + 1 };
}

export class Layer {
  constructor(mask, width, height, colour, hatched, whole = false) {
    Object.assign(this, { mask, width, height, hatched, colour: rgb(colour) });
    this.box = whole ? { x: 0, y: 0, w: width, h: height } : bounds(mask, width, height);
    if (!this.box) return;
    const { w, h } = this.box;
    this.fill = new OffscreenCanvas(w, h);
    this.outline = new OffscreenCanvas(w, h);
    this.fillData = new ImageData(w, h);
    this.outlineData = new ImageData(w, h);
    this.paint(this.box);
  }

  // Recomputes both canvases inside `rect` (image coordinates). Pixels are written as one 32-bit
  // word each (RGBA bytes read little-endian, as on every platform browsers run on).
  paint(rect) {
    const { mask, width, height, box, colour: [r, g, b] } = this;
    const x0 = Math.max(rect.x, box.x), y0 = Math.max(rect.y, box.y);
    const x1 = Math.min(rect.x + rect.w, box.x + box.w), y1 = Math.min(rect.y + rect.h, box.y + box.h);
    if (x1 <= x0 || y1 <= y0) return;
    const fill = new Uint32Array(this.fillData.data.buffer), line = new Uint32Array(this.outlineData.data.buffer);
    const rgb = (b << 16) | (g << 8) | r;
    const solid = (255 << 24 | rgb) >>> 0, light = (LIGHT << 24 | rgb) >>> 0;
    for (let y = y0; y < y1; y++) {
      for (let x = x0, i = y * width + x0, o = (y - box.y) * box.w + (x0 - box.x); x < x1; x++, i++, o++) {
        if (!mask[i]) {
          fill[o] = line[o] = 0;
          continue;
        }
        fill[o] = this.hatched && (x + y) % HATCH >= HATCH / 2 ? light : solid;
        let edge = false;
        for (let d = 1; d <= OUTLINE && !edge; d++) {
          edge = x < d || !mask[i - d] || x + d >= width || !mask[i + d]
            || y < d || !mask[i - d * width] || y + d >= height || !mask[i + d * width];
        }
        line[o] = edge ? solid : 0;
      }
    }
    const dx = x0 - box.x, dy = y0 - box.y;
    this.fill.getContext("2d").putImageData(this.fillData, 0, 0, dx, dy, x1 - x0, y1 - y0);
    this.outline.getContext("2d").putImageData(this.outlineData, 0, 0, dx, dy, x1 - x0, y1 - y0);
  }

  // One round brush dab at (cx, cy), radius r, setting the mask to `value`.
  dab(cx, cy, r, value) {
    const { mask, width, height } = this;
    const x0 = Math.max(0, Math.floor(cx - r)), x1 = Math.min(width - 1, Math.ceil(cx + r));
    const y0 = Math.max(0, Math.floor(cy - r)), y1 = Math.min(height - 1, Math.ceil(cy + r));
    for (let y = y0; y <= y1; y++) {
      for (let x = x0; x <= x1; x++) {
        if ((x - cx) ** 2 + (y - cy) ** 2 <= r * r) mask[y * width + x] = value;
      }
    }
    // the outline of neighbours up to OUTLINE px away changes too
    this.paint({ x: x0 - OUTLINE, y: y0 - OUTLINE, w: x1 - x0 + 1 + 2 * OUTLINE, h: y1 - y0 + 1 + 2 * OUTLINE });
  }

  // Dabs along a drag segment, close enough together to make a solid stroke.
  stroke(from, to, r, value) {
    const steps = Math.max(1, Math.ceil(Math.hypot(to.x - from.x, to.y - from.y) / Math.max(1, r / 3)));
    for (let s = 1; s <= steps; s++) {
      this.dab(from.x + (to.x - from.x) * s / steps, from.y + (to.y - from.y) * s / steps, r, value);
    }
  }
}
