// The frame loop: each animation frame takes some steps, then draws once, both on the main
// thread. The main thread's other work per frame (drawing commands, readouts) is measured, and
// the steps get what is left of 33 ms (30 fps), up to the "steps per frame" slider. The GPU
// renders in its own process: where it is the bottleneck (a software GPU such as SwiftShader
// shades every pixel on the CPU), the canvas is drawn at a lower resolution until frames fit
// 30 fps again, and scaled up by the browser.

const FRAME_MS = 1000 / 30;
const MIN_SCALE = 0.3;

export class FrameLoop {
  // hooks: step(n) → whether the steps were taken; draw(dpr) (every frame where `dirty` or a
  // draw is requested); readouts(); fatal(error). `playing` and `maxSteps()` are read each frame.
  constructor(canvas, hooks) {
    this.canvas = canvas;
    this.hooks = hooks;
    this.playing = true;
    this.dirty = true;
    this.stopped = false;
    this.msPerStep = 5; // running estimate of one step's cost
    this.drawMs = 5; // running estimate of the rest of a frame's main-thread work
    this.intervalMs = FRAME_MS; // running estimate of the time between frames
    this.renderScale = 1; // backing pixels per device pixel (≤ 1)
    this.scaleCooldownUntil = 0; // ms: let the estimates settle between changes
    this.lastFrameAt = 0;
    this.stepsThisFrame = 0;
    this.stepMs = 0;
    this.rate = { steps: 0, frames: 0, t0: performance.now(), sps: 0, fps: 0 };
  }

  start() {
    requestAnimationFrame((t) => this.frame(t));
  }

  // Where the GPU holds frames back anyway (interval > 33 ms with this thread idle), stepping
  // may use most of the interval: that does not lower the fps. If stepping itself becomes the
  // bottleneck, the interval it causes shrinks this budget back towards 33 ms (0.8 < 1).
  stepsForFrame() {
    const frame = Math.max(FRAME_MS, 0.8 * this.intervalMs);
    const budget = Math.max(2, frame - this.drawMs - 4);
    const affordable = Math.max(1, Math.floor(budget / Math.max(this.msPerStep, 0.01)));
    return Math.min(this.hooks.maxSteps(), affordable);
  }

  // Lower the resolution when the GPU, not this thread, holds frames back; raise it again when
  // there is room.
  adaptResolution(now) {
    if (this.lastFrameAt) this.intervalMs = 0.9 * this.intervalMs + 0.1 * (now - this.lastFrameAt);
    this.lastFrameAt = now;
    if (now < this.scaleCooldownUntil) return;
    const mainMs = this.stepMs + this.drawMs;
    if (this.intervalMs > 1.15 * FRAME_MS && mainMs < 0.75 * this.intervalMs && this.renderScale > MIN_SCALE) {
      this.renderScale = Math.max(MIN_SCALE, this.renderScale * 0.85);
      this.scaleCooldownUntil = now + 400;
    } else if (this.intervalMs < 0.8 * FRAME_MS && this.renderScale < 1) {
      this.renderScale = Math.min(1, this.renderScale * 1.1);
      this.scaleCooldownUntil = now + 1000;
    }
  }

  // Steps now (a frame's batch, or the Step button's), timed for the budget.
  runSteps(n) {
    const t0 = performance.now();
    if (!this.hooks.step(n)) return;
    const dt = performance.now() - t0;
    this.msPerStep = 0.8 * this.msPerStep + 0.2 * (dt / n);
    this.stepMs = dt;
    this.stepsThisFrame = n;
    this.rate.steps += n;
    this.dirty = true;
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

  frame(now) {
    if (this.stopped) return;
    requestAnimationFrame((t) => this.frame(t));
    try {
      this.adaptResolution(now);
      this.stepsThisFrame = 0;
      this.stepMs = 0;
      if (this.playing) this.runSteps(this.stepsForFrame());
      const t0 = performance.now();
      const dpr = this.resizeCanvas();
      if (this.dirty || this.hooks.wantsDraw()) {
        this.hooks.draw(dpr);
        this.dirty = false;
      }
      this.rate.frames++;
      this.countRate(performance.now());
      this.hooks.readouts();
      this.drawMs = 0.9 * this.drawMs + 0.1 * (performance.now() - t0);
    } catch (e) {
      this.hooks.fatal(e);
    }
  }

  // Steps and frames per second over the last half second.
  countRate(now) {
    const r = this.rate;
    if (now - r.t0 < 500) return;
    const s = (now - r.t0) / 1000;
    r.sps = r.steps / s;
    r.fps = r.frames / s;
    r.steps = 0;
    r.frames = 0;
    r.t0 = now;
  }
}
