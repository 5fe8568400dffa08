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

/**
 * Where the lattice square (left, top, side) and the colour bar (top, height) are, in device
 * pixels: the fields of the core's `Layout`, as plain numbers.
 * @typedef {{ x: number, y: number, side: number, bar_y: number, bar_h: number }} CanvasGeometry
 */

export class Canvas2DRenderer {
  /** @param {HTMLCanvasElement} canvas */
  constructor(canvas) {
    const ctx = canvas.getContext('2d');
    if (!ctx) throw new Error('this canvas cannot be drawn on with Canvas 2D');
    this.canvas = canvas;
    this.ctx = ctx;
    this.sites = document.createElement('canvas'); // the lattice, one pixel per site
    this.bar = document.createElement('canvas'); // the colour bar, 256 pixels
    this.bar.width = 256;
    this.bar.height = 1;
    /** @type {number | null} */
    this.barKind = null;
    /** @type {CanvasGeometry} */
    this.g = { x: 0, y: 0, side: 1, bar_y: 0, bar_h: 0 };
    /** What was drawn last: the browser tests compare the canvas as shown with it. */
    /** @type {{ rgba: Uint8Array, tissue: Float32Array } | null} */
    this.last = null;
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

  // Where the lattice square and the colour bar are, in device pixels, as last drawn.
  /** @returns {CanvasGeometry} */
  layout() {
    return this.g;
  }

  free() {}

  // Draws `view` (a WebView); `dpr` is the device pixels per CSS pixel.
  /** @param {import('../pkg/monolayer.js').WebView} view @param {number} dpr @param {boolean} substrate */
  draw(view, dpr, substrate) {
    const { canvas, ctx } = this;
    const l = view.l();
    const kind = view.kind();
    const withBar = kind !== 0; // FieldKind.Tissue draws no colour bar
    const g = canvasLayout(canvas.width, canvas.height, dpr, withBar);
    this.g = { x: g.x, y: g.y, side: g.side, bar_y: g.bar_y, bar_h: g.bar_h };
    g.free();
    const { x: x0, y: y0, side, bar_y: barY, bar_h: barH } = this.g;
    if (this.sites.width !== l) {
      this.sites.width = l;
      this.sites.height = l;
    }
    // The bindings copy the core's Vec<u8> into an ArrayBuffer of its own (never shared memory).
    const rgba = /** @type {Uint8Array<ArrayBuffer>} */ (view.rgba(substrate));
    /** @type {CanvasRenderingContext2D} */ (this.sites.getContext('2d')).putImageData(new ImageData(new Uint8ClampedArray(rgba.buffer), l, l), 0, 0);
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
        /** @type {CanvasRenderingContext2D} */ (this.bar.getContext('2d')).putImageData(new ImageData(new Uint8ClampedArray(/** @type {ArrayBuffer} */ (barColours(kind, 256).buffer)), 256, 1), 0, 0);
        this.barKind = kind;
      }
      ctx.imageSmoothingEnabled = true;
      ctx.drawImage(this.bar, x0, barY, side, barH);
    }
  }

  // Segments as round-capped lines, at least 1.5 device pixels wide (as segments.wgsl).
  /** @param {Float32Array} s @param {number} l @param {number} x0 @param {number} y0 @param {number} side */
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
