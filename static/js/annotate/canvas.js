// The frame at full resolution on one canvas: wheel zoom at the cursor, pan with Space+drag or the
// middle button, clicks, boxes and brush strokes reported in image pixels. Everything is drawn in
// one pass per animation frame, whatever asked for it in between.
//
// Image pixel (x, y) covers [x, x + 1) × [y, y + 1); clicks are reported as the integer pixel they hit.

const DRAG_PX = 5;       // screen px a press must travel before it is a box, not a click
const MAX_SCALE = 32;
const FIT_MARGIN = 12;   // screen px around a fitted frame
const GREEN = "#22c55e", RED = "#ef4444";
const LABEL_FONT = "600 12px system-ui, sans-serif";

export class View {
  constructor(canvas, handlers) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.handlers = handlers;  // {point(x, y, label), box([x0, y0, x1, y1]), strokeStart() → Layer | null, strokeEnd(), zoomed(scale)}
    this.image = null;
    this.scale = 1;
    this.tx = 0;
    this.ty = 0;
    this.fitted = true;
    this.tool = "click";
    this.brush = 8;           // radius, image px
    // proposals: [{ illusion: outline.js's outline, support: its outline | null, label, highlighted }]
    this.scene = { layers: [], proposals: [], points: [], box: null, colour: "#fff", opacity: 0.5, hidden: false };
    this.drag = null;
    this.hover = null;        // last pointer position, client px
    this.space = false;
    this.queued = false;
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.listen();
  }

  // ---- geometry ---------------------------------------------------------------------------------

  imageToClient(x, y) {
    const rect = this.canvas.getBoundingClientRect();
    return [rect.left + this.tx + (x + 0.5) * this.scale, rect.top + this.ty + (y + 0.5) * this.scale];
  }

  clientToImage(cx, cy) {
    const rect = this.canvas.getBoundingClientRect();
    return { x: (cx - rect.left - this.tx) / this.scale, y: (cy - rect.top - this.ty) / this.scale };
  }

  inside({ x, y }) {
    return this.image && x >= 0 && y >= 0 && x < this.image.naturalWidth && y < this.image.naturalHeight;
  }

  setImage(image) {
    this.image = image;
    this.fit();
  }

  fit() {
    if (!this.image) return;
    const { clientWidth: w, clientHeight: h } = this.canvas;
    const { naturalWidth: iw, naturalHeight: ih } = this.image;
    this.scale = Math.max(0.01, Math.min((w - 2 * FIT_MARGIN) / iw, (h - 2 * FIT_MARGIN) / ih));
    this.tx = (w - iw * this.scale) / 2;
    this.ty = (h - ih * this.scale) / 2;
    this.fitted = true;
    this.changed();
  }

  zoomAt(cx, cy, factor) {
    if (!this.image) return;
    const rect = this.canvas.getBoundingClientRect();
    const fitScale = Math.min(rect.width / this.image.naturalWidth, rect.height / this.image.naturalHeight);
    const scale = Math.min(MAX_SCALE, Math.max(fitScale / 4, this.scale * factor));
    const px = cx - rect.left, py = cy - rect.top;
    this.tx = px - (px - this.tx) * (scale / this.scale);
    this.ty = py - (py - this.ty) * (scale / this.scale);
    this.scale = scale;
    this.fitted = false;
    this.changed();
  }

  zoomCentre(factor) {
    const rect = this.canvas.getBoundingClientRect();
    this.zoomAt(rect.left + rect.width / 2, rect.top + rect.height / 2, factor);
  }

  resize() {
    const dpr = window.devicePixelRatio || 1;
    this.canvas.width = Math.round(this.canvas.clientWidth * dpr);
    this.canvas.height = Math.round(this.canvas.clientHeight * dpr);
    if (this.fitted) this.fit();
    else this.render();
  }

  changed() {
    this.handlers.zoomed?.(this.scale);
    this.render();
  }

  // ---- input ------------------------------------------------------------------------------------

  listen() {
    const c = this.canvas;
    c.addEventListener("contextmenu", (e) => e.preventDefault());
    c.addEventListener("mousedown", (e) => e.button === 1 && e.preventDefault());  // no autoscroll
    c.addEventListener("wheel", (e) => {
      e.preventDefault();
      this.zoomAt(e.clientX, e.clientY, Math.exp(-e.deltaY * (e.deltaMode ? 0.05 : 0.002)));
    }, { passive: false });
    c.addEventListener("pointerdown", (e) => this.down(e));
    c.addEventListener("pointermove", (e) => this.move(e));
    c.addEventListener("pointerup", (e) => this.up(e));
    c.addEventListener("pointercancel", () => { this.drag = null; this.render(); });
    c.addEventListener("pointerleave", () => { this.hover = null; this.render(); });
    const typing = (e) => e.target.closest?.("input, select, textarea, button, dialog[open]");
    window.addEventListener("keydown", (e) => {
      if (e.key !== " " || typing(e)) return;
      e.preventDefault();  // no page scroll
      this.space = true;
      this.cursor();
    });
    window.addEventListener("keyup", (e) => {
      if (e.key !== " ") return;
      this.space = false;
      this.cursor();
    });
    window.addEventListener("blur", () => { this.space = false; this.cursor(); });
  }

  down(e) {
    this.canvas.focus({ preventScroll: true });
    const at = { cx: e.clientX, cy: e.clientY };
    if (e.button === 1 || (e.button === 0 && this.space)) {
      this.drag = { kind: "pan", ...at, tx: this.tx, ty: this.ty };
    } else if (this.tool !== "click" && (e.button === 0 || e.button === 2)) {
      // the other button does the opposite tool, so fixing a slip needs no key
      const value = (this.tool === "brush") === (e.button === 0) ? 1 : 0;
      const layer = this.handlers.strokeStart();
      if (!layer) return;
      const p = this.clientToImage(e.clientX, e.clientY);
      layer.dab(p.x, p.y, this.brush, value);
      this.drag = { kind: "stroke", layer, value, last: p };
    } else if (e.button === 0 || e.button === 2) {
      this.drag = { kind: "press", ...at, button: e.button, alt: e.altKey };
    } else {
      return;
    }
    this.canvas.setPointerCapture(e.pointerId);
    this.cursor();
    this.render();
  }

  move(e) {
    this.hover = { cx: e.clientX, cy: e.clientY };
    const d = this.drag;
    if (d?.kind === "pan") {
      this.tx = d.tx + e.clientX - d.cx;
      this.ty = d.ty + e.clientY - d.cy;
      this.fitted = false;
    } else if (d?.kind === "stroke") {
      const p = this.clientToImage(e.clientX, e.clientY);
      d.layer.stroke(d.last, p, this.brush, d.value);
      d.last = p;
    } else if (d?.kind === "press" && d.button === 0 && Math.hypot(e.clientX - d.cx, e.clientY - d.cy) > DRAG_PX) {
      d.kind = "box";
    }
    if (d?.kind === "box") d.to = { cx: e.clientX, cy: e.clientY };
    this.render();
  }

  up(e) {
    const d = this.drag;
    this.drag = null;
    if (d?.kind === "stroke") this.handlers.strokeEnd();
    if (d?.kind === "press") {
      const p = this.clientToImage(e.clientX, e.clientY);
      if (this.inside(p)) this.handlers.point(Math.floor(p.x), Math.floor(p.y), d.button === 2 || d.alt ? 0 : 1);
    }
    if (d?.kind === "box") {
      const box = this.boxOf(d);
      if (box[2] > box[0] && box[3] > box[1]) this.handlers.box(box);
    }
    this.cursor();
    this.render();
  }

  // The dragged rectangle in image pixels, clipped to the image.
  boxOf(d) {
    const a = this.clientToImage(d.cx, d.cy), b = this.clientToImage(d.to.cx, d.to.cy);
    const { naturalWidth: w, naturalHeight: h } = this.image;
    const clip = (v, max) => Math.min(max, Math.max(0, Math.round(v)));
    return [clip(Math.min(a.x, b.x), w), clip(Math.min(a.y, b.y), h), clip(Math.max(a.x, b.x), w), clip(Math.max(a.y, b.y), h)];
  }

  cursor() {
    const panning = this.drag?.kind === "pan";
    this.canvas.dataset.tool = this.tool;
    this.canvas.style.cursor = panning ? "grabbing" : this.space ? "grab" : this.tool === "click" ? "crosshair" : "none";
  }

  // ---- drawing ----------------------------------------------------------------------------------

  render() {
    if (this.queued) return;
    this.queued = true;
    requestAnimationFrame(() => {
      this.queued = false;
      this.draw();
    });
  }

  draw() {
    const { ctx, canvas, scene, scale } = this;
    const dpr = window.devicePixelRatio || 1;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    if (!this.image) return;
    ctx.setTransform(dpr * scale, 0, 0, dpr * scale, dpr * this.tx, dpr * this.ty);
    ctx.imageSmoothingEnabled = scale < 2;  // close up, the annotator wants to see the pixels
    ctx.drawImage(this.image, 0, 0);
    if (!scene.hidden) {
      for (const { layer, active } of scene.layers) {
        if (!layer.box) continue;
        ctx.globalAlpha = scene.opacity * (active ? 1 : 0.7);
        ctx.drawImage(layer.fill, layer.box.x, layer.box.y);
        if (scale >= 4) continue;  // close up the fill's own pixel edges are sharper than a fat outline
        ctx.globalAlpha = active ? 1 : 0.75;
        ctx.drawImage(layer.outline, layer.box.x, layer.box.y);
      }
      ctx.globalAlpha = 1;
      for (const p of scene.proposals) this.proposal(p);
    }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    const at = (x, y) => [this.tx + x * scale, this.ty + y * scale];
    if (!scene.hidden) for (const p of scene.proposals) this.label(at(p.illusion.box[0], p.illusion.box[1]), p);
    if (scene.box) this.rect(at(scene.box[0], scene.box[1]), at(scene.box[2], scene.box[3]), scene.colour);
    if (this.drag?.kind === "box") {
      const [x0, y0, x1, y1] = this.boxOf(this.drag);
      this.rect(at(x0, y0), at(x1, y1), "#fff");
    }
    for (const p of scene.points) this.dot(...at(p.x + 0.5, p.y + 0.5), p.label ? GREEN : RED, p.label);
    if (this.tool !== "click" && this.hover && !this.space) {
      const rect = canvas.getBoundingClientRect();
      ctx.beginPath();
      ctx.arc(this.hover.cx - rect.left, this.hover.cy - rect.top, Math.max(2, this.brush * scale), 0, 2 * Math.PI);
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = "#000";
      ctx.stroke();
      ctx.setLineDash([4, 4]);
      ctx.strokeStyle = this.tool === "brush" ? "#fff" : "#fca5a5";
      ctx.stroke();
      ctx.setLineDash([]);
    }
  }

  // A proposal, in image coordinates: its illusion's outline dashed, white over a dark line so it
  // reads on any image; the highlighted one bolder, faintly filled, with its support dashed lighter.
  proposal({ illusion, support, highlighted }) {
    const { ctx } = this;
    if (highlighted) {
      ctx.fillStyle = "rgba(255, 255, 255, .16)";
      ctx.fill(illusion.path, "evenodd");
      if (support) this.dashed(support.path, 1.5, [3, 4], 0.75);
    }
    this.dashed(illusion.path, highlighted ? 2.5 : 1.5, highlighted ? [9, 5] : [5, 5], highlighted ? 1 : 0.8);
  }

  // Strokes `path` (image px) `width` screen px wide, dashed `dash` (screen px).
  dashed(path, width, dash, alpha) {
    const { ctx, scale } = this;
    ctx.globalAlpha = alpha;
    ctx.lineJoin = "round";
    ctx.lineWidth = (width + 2) / scale;
    ctx.strokeStyle = "rgba(15, 20, 32, .75)";
    ctx.stroke(path);
    ctx.lineWidth = width / scale;
    ctx.setLineDash(dash.map((d) => d / scale));
    ctx.strokeStyle = "#fff";
    ctx.stroke(path);
    ctx.setLineDash([]);
    ctx.globalAlpha = 1;
  }

  // A proposal's label, in screen px, just above the top-left corner of its outline (inside it at the
  // top of the canvas); the highlighted one dark on white, the others white on dark.
  label([x, y], { label, highlighted }) {
    const { ctx } = this;
    ctx.font = LABEL_FONT;
    const w = ctx.measureText(label).width + 12, h = 19;
    const left = Math.max(2, Math.min(x, this.canvas.clientWidth - w - 2));
    const top = y - h - 4 >= 2 ? y - h - 4 : y + 4;
    ctx.beginPath();
    ctx.roundRect(left, top, w, h, 5);
    ctx.fillStyle = highlighted ? "#fff" : "rgba(15, 20, 32, .82)";
    ctx.fill();
    if (highlighted) {
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = "#0f1420";
      ctx.stroke();
    }
    ctx.fillStyle = highlighted ? "#0f1420" : "#fff";
    ctx.textBaseline = "middle";
    ctx.fillText(label, left + 6, top + h / 2 + 0.5);
  }

  rect([x0, y0], [x1, y1], colour) {
    const { ctx } = this;
    ctx.lineWidth = 2;
    ctx.setLineDash([6, 4]);
    ctx.strokeStyle = colour;
    ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
    ctx.setLineDash([]);
  }

  dot(x, y, colour, positive) {
    const { ctx } = this;
    ctx.beginPath();
    ctx.arc(x, y, 6.5, 0, 2 * Math.PI);
    ctx.fillStyle = colour;
    ctx.fill();
    ctx.lineWidth = 2;
    ctx.strokeStyle = "#fff";
    ctx.stroke();
    // a sign as well as a colour, for red-green colour blindness
    ctx.beginPath();
    ctx.moveTo(x - 3, y);
    ctx.lineTo(x + 3, y);
    if (positive) {
      ctx.moveTo(x, y - 3);
      ctx.lineTo(x, y + 3);
    }
    ctx.lineWidth = 1.8;
    ctx.stroke();
  }
}
