// The record button: the canvas as drawn, with the time and the parameters burnt in, recorded to
// WebM by MediaRecorder. Each drawn frame is copied, in the task that drew it (a WebGPU canvas is
// only readable then), onto a 2D canvas of fixed size whose stream is recorded.

const TYPES = ['video/webm;codecs=vp9', 'video/webm;codecs=vp8', 'video/webm'];
const MAX_SIDE = 960;

export class Recorder {
  /** @param {HTMLCanvasElement} source */
  constructor(source) {
    this.source = source;
    /** @type {HTMLCanvasElement | null} */
    this.canvas = null;
    /** @type {MediaRecorder | null} */
    this.recorder = null;
    /** @type {Blob[]} */
    this.chunks = [];
    this.type = TYPES[0];
  }

  get recording() {
    return this.recorder !== null;
  }

  static supported() {
    return typeof MediaRecorder !== 'undefined' && TYPES.some((t) => MediaRecorder.isTypeSupported(t));
  }

  start() {
    // The size at the start, from the canvas's CSS size (its backing size follows the render
    // scale, which may change while recording).
    const dpr = window.devicePixelRatio || 1;
    const w = this.source.clientWidth * dpr;
    const h = this.source.clientHeight * dpr;
    const k = Math.min(1, MAX_SIDE / Math.max(w, h));
    this.canvas = document.createElement('canvas');
    // Even sizes: some encoders reject odd ones.
    this.canvas.width = 2 * Math.round((w * k) / 2);
    this.canvas.height = 2 * Math.round((h * k) / 2);
    this.type = TYPES.find((t) => MediaRecorder.isTypeSupported(t)) ?? TYPES[0];
    this.recorder = new MediaRecorder(this.canvas.captureStream(30), { mimeType: this.type, videoBitsPerSecond: 4e6 });
    this.chunks = [];
    this.recorder.ondataavailable = (e) => {
      if (e.data.size) this.chunks.push(e.data);
    };
    this.recorder.start(500);
  }

  // Copies the frame just drawn, with `lines` of caption in its top-left corner.
  /** @param {string[]} lines */
  frame(lines) {
    const c = this.canvas;
    if (!this.recording || !c) return;
    const g = /** @type {CanvasRenderingContext2D} */ (c.getContext('2d'));
    g.fillStyle = '#0f1115';
    g.fillRect(0, 0, c.width, c.height);
    g.drawImage(this.source, 0, 0, c.width, c.height);
    const px = Math.max(12, Math.round(c.height / 40));
    g.font = `${px}px system-ui, sans-serif`;
    g.textBaseline = 'top';
    const width = Math.max(...lines.map((l) => g.measureText(l).width));
    g.fillStyle = 'rgba(15, 17, 21, 0.7)';
    g.fillRect(0, 0, width + px, (lines.length + 0.5) * px * 1.25);
    g.fillStyle = '#e6e9ef';
    lines.forEach((l, i) => g.fillText(l, px / 2, px / 2 + i * px * 1.25));
  }

  // Stops; resolves with the WebM file.
  /** @returns {Promise<Blob>} */
  stop() {
    const r = this.recorder;
    this.recorder = null;
    return new Promise((resolve) => {
      if (!r) return resolve(new Blob([], { type: this.type.split(';')[0] }));
      r.onstop = () => resolve(new Blob(this.chunks, { type: this.type.split(';')[0] }));
      r.stop();
    });
  }
}
