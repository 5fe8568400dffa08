// The renderer of last resort: Canvas 2D, for a browser that offers neither WebGPU nor WebGL2
// (a blocklisted GPU driver, a locked-down school computer, a GPU lost again and again). It
// draws the same view as the wgpu renderer (src/web/render.rs), with the same layout: each
// field is an image of one pixel per lattice site (its colours computed by the core,
// src/web/raster.rs), scaled up to the lattice square; the overlays (elongation axes, arrows,
// the director, defects, the spiral cores' crosses and rings) are the view's segments, drawn as
// round-capped lines (so a +½ defect's short thick stroke is a dot, a spiral core's twelve
// chords a ring); the colour bar is an image under the square.

import { barColours, canvasLayout } from '../pkg/monolayer.js';

// Floats per segment in a view (`Segment` of src/web/view.rs: a, b, colour, width, padding).
const SEGMENT_FLOATS = 12;
const BACKGROUND = 'rgb(15, 17, 21)';

export class Canvas2DRenderer {
  constructor(canvas) {
    const ctx = canvas.getContext('2d');
    if (!ctx) throw new Error('this canvas cannot be drawn on with Canvas 2D');
    this.canvas = canvas;
    this.ctx = ctx;
    this.sites = document.createElement('canvas'); // the lattice, one pixel per site
    this.bar = document.createElement('canvas'); // the colour bar, 256 pixels
    this.bar.width = 256;
    this.bar.height = 1;
    this.barKind = null;
    this.g = [0, 0, 1, 0, 0];
  }

  backend() {
    return 'Canvas 2D';
  }

  // A Canvas 2D context is never lost.
  lost() {
    return undefined;
  }

  take_errors() {
    return undefined;
  }

  // [left, top, side, bar top, bar height] in device pixels, as last drawn.
  layout() {
    return this.g;
  }

  free() {}

  // Draws `view` (a WebView); `dpr` is the device pixels per CSS pixel.
  draw(view, dpr, substrate) {
    const { canvas, ctx } = this;
    const l = view.l();
    const kind = view.kind();
    const withBar = kind !== 0; // FieldKind.Tissue draws no colour bar
    this.g = Array.from(canvasLayout(canvas.width, canvas.height, dpr, withBar));
    const [x0, y0, side, barY, barH] = this.g;
    if (this.sites.width !== l) {
      this.sites.width = l;
      this.sites.height = l;
    }
    const rgba = view.rgba(substrate);
    this.sites.getContext('2d').putImageData(new ImageData(new Uint8ClampedArray(rgba.buffer), l, l), 0, 0);
    // The browser tests compare the canvas as shown with the image and the cells it came from.
    this.last = { rgba, tissue: view.tissue() };
    ctx.fillStyle = BACKGROUND;
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    // Sites as squares, as the lattice is: no smoothing between them.
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(this.sites, x0, y0, side, side);
    ctx.save();
    ctx.beginPath();
    ctx.rect(x0, y0, side, side);
    ctx.clip();
    this.segments(view.segments(), l, x0, y0, side);
    ctx.restore();
    if (withBar && barY + barH <= canvas.height) {
      if (this.barKind !== kind) {
        this.bar.getContext('2d').putImageData(new ImageData(new Uint8ClampedArray(barColours(kind, 256).buffer), 256, 1), 0, 0);
        this.barKind = kind;
      }
      ctx.imageSmoothingEnabled = true;
      ctx.drawImage(this.bar, x0, barY, side, barH);
    }
  }

  // Segments as round-capped lines, at least 1.5 device pixels wide (as segments.wgsl).
  segments(s, l, x0, y0, side) {
    const { ctx } = this;
    const k = side / l;
    ctx.lineCap = 'round';
    for (let i = 0; i < s.length; i += SEGMENT_FLOATS) {
      const [ax, ay, bx, by, r, g, b, a, width] = s.subarray(i, i + 9);
      ctx.strokeStyle = `rgba(${Math.round(255 * r)}, ${Math.round(255 * g)}, ${Math.round(255 * b)}, ${a})`;
      ctx.lineWidth = Math.max(width, 1.5);
      ctx.beginPath();
      ctx.moveTo(x0 + ax * k, y0 + ay * k);
      ctx.lineTo(x0 + bx * k, y0 + by * k);
      ctx.stroke();
    }
  }
}
