// The canvas: the frame at full resolution under a zoom/pan transform, the masks as a coloured
// overlay (recomposed only when a mask changes), and the clicks and the box drawn on top.

export const PAIR_COLOURS = [[255, 0, 200], [0, 200, 255], [255, 170, 0], [120, 220, 60], [170, 110, 255],
  [255, 80, 80], [0, 220, 170], [230, 230, 0], [255, 120, 180]];

export class View {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.image = null;
    this.overlay = document.createElement("canvas");
    this.scale = 1;
    this.tx = 0;
    this.ty = 0;
    this.opacity = 0.5;
    new ResizeObserver(() => this.resize()).observe(canvas.parentElement);
  }

  setImage(image) {
    this.image = image;
    this.overlay.width = image.naturalWidth;
    this.overlay.height = image.naturalHeight;
    this.resize();
    this.fit();
  }

  resize() {
    const box = this.canvas.parentElement.getBoundingClientRect();
    this.canvas.width = Math.max(1, Math.floor(box.width));
    this.canvas.height = Math.max(1, Math.floor(box.height));
    this.draw();
  }

  fit() {
    if (!this.image) return;
    const { width, height } = this.canvas;
    this.scale = Math.min(width / this.image.naturalWidth, height / this.image.naturalHeight);
    this.tx = (width - this.image.naturalWidth * this.scale) / 2;
    this.ty = (height - this.image.naturalHeight * this.scale) / 2;
    this.draw();
  }

  zoomAt(clientX, clientY, factor) {
    const [cx, cy] = this.canvasPoint(clientX, clientY);
    const next = Math.min(40, Math.max(0.05, this.scale * factor));
    this.tx = cx - (cx - this.tx) * (next / this.scale);
    this.ty = cy - (cy - this.ty) * (next / this.scale);
    this.scale = next;
    this.draw();
  }

  pan(dx, dy) {
    this.tx += dx;
    this.ty += dy;
    this.draw();
  }

  canvasPoint(clientX, clientY) {
    const r = this.canvas.getBoundingClientRect();
    return [(clientX - r.left) * (this.canvas.width / r.width), (clientY - r.top) * (this.canvas.height / r.height)];
  }

  // Client (page) coordinates ↔ image pixels (x right, y down; pixel centres at integers).
  clientToImage(clientX, clientY) {
    const [cx, cy] = this.canvasPoint(clientX, clientY);
    return [(cx - this.tx) / this.scale - 0.5, (cy - this.ty) / this.scale - 0.5];
  }

  imageToClient(x, y) {
    const r = this.canvas.getBoundingClientRect();
    const cx = (x + 0.5) * this.scale + this.tx, cy = (y + 0.5) * this.scale + this.ty;
    return [r.left + cx * (r.width / this.canvas.width), r.top + cy * (r.height / this.canvas.height)];
  }

  // regions: [{pair, kind, mask: Uint8Array}] → one RGBA overlay at image resolution.
  compose(regions) {
    const { width, height } = this.overlay;
    const ctx = this.overlay.getContext("2d");
    const data = ctx.createImageData(width, height);
    const px = data.data;
    for (const { pair, kind, mask } of regions) {
      const [r, g, b] = PAIR_COLOURS[pair % PAIR_COLOURS.length];
      // Support regions are drawn lighter and striped, so an illusion and its wall never look alike.
      const alpha = kind === "illusion" ? 255 : 150;
      for (let i = 0; i < mask.length; i++) {
        if (!mask[i]) continue;
        if (kind === "support" && ((i % width) + Math.floor(i / width)) % 8 < 3) continue;
        const o = i * 4;
        px[o] = r; px[o + 1] = g; px[o + 2] = b; px[o + 3] = alpha;
      }
    }
    ctx.putImageData(data, 0, 0);
    this.draw();
  }

  draw(marks = this.marks) {
    this.marks = marks;
    const { ctx } = this;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#1b1f27";
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    if (!this.image) return;
    ctx.setTransform(this.scale, 0, 0, this.scale, this.tx, this.ty);
    ctx.imageSmoothingEnabled = this.scale < 2;
    ctx.drawImage(this.image, 0, 0);
    ctx.globalAlpha = this.opacity;
    ctx.drawImage(this.overlay, 0, 0);
    ctx.globalAlpha = 1;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    for (const [x, y, label] of marks?.points ?? []) {
      const cx = (x + 0.5) * this.scale + this.tx, cy = (y + 0.5) * this.scale + this.ty;
      ctx.beginPath();
      ctx.arc(cx, cy, 6, 0, 2 * Math.PI);
      ctx.fillStyle = label ? "#22c55e" : "#ef4444";
      ctx.fill();
      ctx.lineWidth = 2;
      ctx.strokeStyle = "#fff";
      ctx.stroke();
    }
    const box = marks?.box;
    if (box) {
      ctx.strokeStyle = "#fde047";
      ctx.lineWidth = 2;
      ctx.setLineDash([6, 4]);
      ctx.strokeRect(box[0] * this.scale + this.tx, box[1] * this.scale + this.ty,
        (box[2] - box[0]) * this.scale, (box[3] - box[1]) * this.scale);
      ctx.setLineDash([]);
    }
    if (marks?.brush) {
      const [x, y, radius] = marks.brush;
      ctx.beginPath();
      ctx.arc((x + 0.5) * this.scale + this.tx, (y + 0.5) * this.scale + this.ty, radius * this.scale, 0, 2 * Math.PI);
      ctx.strokeStyle = "#fff";
      ctx.lineWidth = 1.5;
      ctx.stroke();
    }
  }
}
