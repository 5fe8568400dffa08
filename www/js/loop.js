// The frame loop of the main thread. The simulation steps in its own worker (worker.js); each
// animation frame here draws the latest state the worker sent, if it is new, and asks for the
// next one, so that drawing never holds back stepping. The GPU renders in its own process:
// where it is the bottleneck (a software GPU such as SwiftShader shades every pixel on the CPU),
// the canvas is drawn at a lower resolution until frames fit 30 fps again, and scaled up by the
// browser.

const FRAME_MS = 1000 / 30;
const MIN_SCALE = 0.3;
// Animation frames missing this long on a visible page: the watchdog draws instead.
const WATCHDOG_MS = 500;

/** @typedef {{ parts: import('./worker.js').FrameParts, stats: import('./worker.js').Stats }} Frame */

export class FrameLoop {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {{ check(): void, draw(frame: Frame, dpr: number): void, request(dpr: number): void, readouts(): void,
   *   fatal(e: unknown): void }} hooks check() before each frame (the renderer still has its device);
   *   draw(frame, dpr); request(dpr) asks the worker for a frame; readouts(); fatal(error).
   */
  constructor(canvas, hooks) {
    this.canvas = canvas;
    this.hooks = hooks;
    this.stopped = false;
    /** @type {Frame | null} */
    this.latest = null; // the worker's last frame
    this.fresh = false; // `latest` not drawn yet
    this.dirty = true; // redraw `latest` (resized, screenshot)
    this.requested = false; // a frame request is with the worker
    this.drawMs = 5; // running estimate of a drawn frame's main-thread work
    this.intervalMs = FRAME_MS; // running estimate of the time from a drawn frame to the next
    this.renderScale = 1; // backing pixels per device pixel (≤ 1)
    this.scaleCooldownUntil = 0; // ms: let the estimates settle between changes
    /** @type {number | null} */
    this.drewAt = null; // when the last frame was drawn, until the next animation frame
    this.frameAt = performance.now(); // when the last frame (drawn or not) ran
    this.rafPending = false; // an animation frame is asked for
    /** @type {number | undefined} */
    this.watchdog = undefined;
    // Steps the worker took and frames drawn here, per second.
    /** @type {{ steps: number, frames: number, t0: number, sps: number, fps: number, lastStep: number | null }} */
    this.rate = { steps: 0, frames: 0, t0: performance.now(), sps: 0, fps: 0, lastStep: null };
  }

  // Frames come from requestAnimationFrame; a watchdog draws them from a timer when animation
  // frames stop while the page is visible (Firefox stops them for the whole page once a WebGPU
  // canvas's device is destroyed, and does not start them again for a new canvas).
  start() {
    this.request();
    this.watchdog ??= setInterval(() => {
      if (!this.stopped && !document.hidden && performance.now() - this.frameAt > WATCHDOG_MS) this.frame(performance.now());
    }, FRAME_MS);
  }

  request() {
    if (this.rafPending) return;
    this.rafPending = true;
    requestAnimationFrame((t) => {
      this.rafPending = false;
      this.frame(t);
    });
  }

  // A frame from the worker.
  /** @param {Frame} frame */
  receive(frame) {
    const r = this.rate;
    if (r.lastStep !== null && frame.stats.step > r.lastStep) r.steps += frame.stats.step - r.lastStep;
    r.lastStep = frame.stats.step;
    this.latest = frame;
    this.fresh = true;
    this.requested = false;
  }

  // A new simulation: its step count starts over.
  restart() {
    this.rate.lastStep = null;
    this.requested = false;
    this.latest = null;
  }

  // Lower the resolution when the GPU, not this thread, holds frames back; raise it again when
  // there is room. Only the time from a drawn frame to the next one counts: an idle page (paused,
  // or waiting for the worker) says nothing about the GPU, and must not start a cycle of resizes
  // and redraws that would take the CPU from the worker.
  /** @param {number} now */
  adaptResolution(now) {
    const drewAt = this.drewAt;
    const drew = drewAt !== null;
    if (drew) this.intervalMs = 0.9 * this.intervalMs + 0.1 * (now - drewAt);
    this.drewAt = null;
    if (!drew || now < this.scaleCooldownUntil) return;
    if (this.intervalMs > 1.15 * FRAME_MS && this.drawMs < 0.75 * this.intervalMs && this.renderScale > MIN_SCALE) {
      this.renderScale = Math.max(MIN_SCALE, this.renderScale * 0.85);
      this.scaleCooldownUntil = now + 400;
    } else if (this.intervalMs < 0.8 * FRAME_MS && this.renderScale < 1) {
      this.renderScale = Math.min(1, this.renderScale * 1.1);
      this.scaleCooldownUntil = now + 1000;
    }
  }

  // The canvas's backing size follows its CSS size × devicePixelRatio × the render scale.
  resizeCanvas() {
    const c = this.canvas;
    const dpr = (window.devicePixelRatio || 1) * this.renderScale;
    const w = Math.max(1, Math.round(c.clientWidth * dpr));
    const h = Math.max(1, Math.round(c.clientHeight * dpr));
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
      this.dirty = true;
    }
    return dpr;
  }

  /** @param {number} now */
  frame(now) {
    if (this.stopped) return;
    this.frameAt = performance.now();
    this.request();
    try {
      this.hooks.check();
      this.adaptResolution(now);
      const t0 = performance.now();
      const dpr = this.resizeCanvas();
      const latest = this.latest;
      const draw = latest !== null && (this.fresh || this.dirty);
      if (draw) {
        this.hooks.draw(latest, dpr);
        this.drewAt = now;
        this.rate.frames++;
        this.fresh = false;
        this.dirty = false;
        this.drawMs = 0.9 * this.drawMs + 0.1 * (performance.now() - t0);
      }
      if (!this.requested) {
        this.hooks.request(dpr);
        this.requested = true;
      }
      // The readouts change with a frame or with the rates, not in between.
      if (this.countRate(performance.now()) || draw) this.hooks.readouts();
    } catch (e) {
      this.hooks.fatal(e);
    }
  }

  // Steps and frames per second over the last half second; whether they were updated.
  /** @param {number} now */
  countRate(now) {
    const r = this.rate;
    if (now - r.t0 < 500) return false;
    const s = (now - r.t0) / 1000;
    r.sps = r.steps / s;
    r.fps = r.frames / s;
    r.steps = 0;
    r.frames = 0;
    r.t0 = now;
    return true;
  }
}
