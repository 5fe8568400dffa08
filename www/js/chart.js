// The hole-area time series: a small 2D-canvas line chart of void area against active time
// (time in the core's units; the axis label in seconds, `secondsPerUnit` of them per unit).

export class HoleChart {
  /** @param {HTMLCanvasElement} canvas */
  constructor(canvas, capacity = 600) {
    this.canvas = canvas;
    this.capacity = capacity;
    /** @type {number[]} */
    this.t = [];
    /** @type {number[]} */
    this.area = [];
    this.secondsPerUnit = 1;
  }

  clear() {
    this.t = [];
    this.area = [];
    this.draw();
  }

  // Adds a point; false (and nothing added) unless time has moved on.
  /** @param {number} time @param {number} area */
  push(time, area) {
    if (this.t.length && time <= this.t[this.t.length - 1]) return false;
    this.t.push(time);
    this.area.push(area);
    // Keep the whole run in view: halve the resolution when full.
    if (this.t.length > this.capacity) {
      this.t = this.t.filter((_, i) => i % 2 === 0);
      this.area = this.area.filter((_, i) => i % 2 === 0);
    }
    return true;
  }

  draw() {
    const c = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(c.clientWidth * dpr));
    const h = Math.max(1, Math.round(c.clientHeight * dpr));
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    const g = /** @type {CanvasRenderingContext2D} */ (c.getContext('2d'));
    g.clearRect(0, 0, w, h);
    g.font = `${10 * dpr}px system-ui, sans-serif`;
    g.fillStyle = '#9aa3b2';
    const n = this.t.length;
    const maxA = Math.max(10, ...this.area);
    const t0 = n ? this.t[0] : 0;
    const t1 = n ? Math.max(this.t[n - 1], t0 + 1) : 1;
    const pad = 4 * dpr;
    g.fillText(`${Math.round(maxA)} µm²`, pad, 11 * dpr);
    g.fillText(`${Math.round(t1 * this.secondsPerUnit)} s`, w - 44 * dpr, h - pad);
    g.strokeStyle = '#3a4150';
    g.beginPath();
    g.moveTo(pad, h - pad);
    g.lineTo(w - pad, h - pad);
    g.stroke();
    if (n < 2) return;
    g.strokeStyle = '#f0b44c';
    g.lineWidth = 1.5 * dpr;
    g.beginPath();
    for (let i = 0; i < n; i++) {
      const x = pad + ((this.t[i] - t0) / (t1 - t0)) * (w - 2 * pad);
      const y = h - pad - (this.area[i] / maxA) * (h - 16 * dpr);
      if (i === 0) g.moveTo(x, y);
      else g.lineTo(x, y);
    }
    g.stroke();
  }
}
