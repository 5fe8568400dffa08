// The page: starts the simulation's worker (worker.js, where the WebAssembly core steps) and the
// renderer (the same core's wgpu drawing, instantiated here, or Canvas 2D where the browser has
// no GPU API: canvas2d.js), and ties the frame loop (loop.js), the controls (controls.js) and the
// readouts (readouts.js) to them. Every change of state goes through the actions below, which
// keep the worker, the controls and the URL in step.

import init, { Renderer, WebView, FieldKind, Layout, codeVersion } from '../pkg/monolayer.js';
import { PARAMS, MODEL_PARAMS, PRESETS, FIELDS, SIZES, parseUrl, toUrl, shippedStateFor, fieldName } from './state.js';
import { FrameLoop } from './loop.js';
import { Controls } from './controls.js';
import { Readouts, formatSeconds } from './readouts.js';
import { Recorder } from './recorder.js';
import { Viewer } from './viewer.js';
import { Canvas2DRenderer } from './canvas2d.js';
import { Tour, TOUR_SPF } from './tour.js';
import { WhatIf } from './whatif.js';

/** @typedef {import('./worker.js').Stats} Stats */
/** @typedef {import('./worker.js').WorkerIn} WorkerIn */
/** @typedef {import('./worker.js').WorkerOut} WorkerOut */
/** @typedef {import('./worker.js').Calls} Calls */
/** @typedef {import('./worker.js').FrameParts} FrameParts */
/** @typedef {import('./state.js').PageState} PageState */
/** @typedef {Renderer | Canvas2DRenderer} AnyRenderer */

const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));
// The canvas drawn on; a new renderer gets a new one (renderers below).
let canvas = /** @type {HTMLCanvasElement} */ ($('view'));
const message = $('message');

/**
 * Everything the tests read lives here too (window.demo); `demo.call` reaches the simulation.
 * @type {Record<string, any>}
 */
const demo = { ready: false, error: null, notices: [], progress: [], firstHole: null, loadedAt: performance.now(), worker: true };
/** @type {any} */ (window).demo = demo;

/**
 * The renderer, the state (what the URL carries), the pending screenshot, the last stats the
 * worker sent and the spiral cores its frame marks, and, while "What if?" replays the tissue's
 * past, the live tissue's parameters to return to.
 * @type {{ renderer: AnyRenderer | null, state: PageState, screenshot: boolean, stats: Stats | null, cores: number,
 *   version: string | undefined, aside: { zeta: number, chi: number, gamma: number, preset: string | null } | null }}
 */
const page = {
  renderer: null, state: /** @type {PageState} */ (/** @type {unknown} */ (null)), screenshot: false, stats: null, cores: 0,
  version: undefined, aside: null,
};

/** @param {string} text */
function showMessage(text, isError = false) {
  message.textContent = text;
  message.classList.toggle('error', isError);
  message.hidden = false;
}

// console_error_panic_hook writes a Rust panic's message to console.error before the trap: the
// fatal message quotes it.
let lastConsoleError = '';
const consoleError = console.error.bind(console);
console.error = (...args) => {
  lastConsoleError = args.map(String).join(' ');
  consoleError(...args);
};

// A fatal error (no GPU, a Rust panic, a lost device): stop and say so on the canvas.
/** @param {string} what @param {unknown} err */
function fatal(what, err) {
  const detail = String(/** @type {{ message?: unknown }} */ (err)?.message || err);
  const panic = lastConsoleError.includes('panicked') ? `\n\n${lastConsoleError}` : '';
  demo.error = `${what}: ${detail}${panic}`;
  loop.stopped = true;
  showMessage(demo.error, true);
}
window.addEventListener('error', (e) => fatal('Unexpected error', e.error ?? e.message));
window.addEventListener('unhandledrejection', (e) => fatal('Unexpected error', e.reason));

/** @param {string[]} lines */
function notify(lines) {
  if (!lines.length) return;
  demo.notices.push(...lines);
  $('notice').textContent = demo.notices.join(' ');
  $('notice').hidden = false;
}

// --- the simulation's worker ------------------------------------------------------------------------
// The threaded core's start (wasm-bindgen-rayon: a Worker per thread, then rayon's pool) now and
// then never ends in Firefox: the worker stays blocked at "starting the threaded core's threads".
// The page does not wait on it for ever. A worker still starting them after this long is replaced
// by one told everything the first was told, to step on the single-thread build (the same bits,
// slower). A normal start takes well under a second (`demo.threadStartMs`).
const THREAD_START_LIMIT_MS = 20_000;
const threadStart = {
  /** @type {ReturnType<typeof setTimeout> | undefined} */ timer: undefined,
  startedAt: 0,
  /** What the worker was told until its first 'ready', to tell a replacement; null after it.
   * @type {WorkerIn[] | null} */
  told: [],
};
const newWorker = () => new Worker(new URL('./worker.js', import.meta.url), { type: 'module' });
let worker = newWorker();
/** @param {WorkerIn} m */
const tell = (m) => {
  threadStart.told?.push(m);
  worker.postMessage(m);
};

// Follows the worker's stages: a start of the threaded core's threads is timed, and the worker
// replaced if it does not end in THREAD_START_LIMIT_MS.
/** @param {boolean} starting */
function watchThreadStart(starting) {
  if (threadStart.timer !== undefined) {
    clearTimeout(threadStart.timer);
    threadStart.timer = undefined;
    demo.threadStartMs = performance.now() - threadStart.startedAt;
  }
  if (!starting) return;
  threadStart.startedAt = performance.now();
  threadStart.timer = setTimeout(replaceStalledWorker, THREAD_START_LIMIT_MS);
}

function replaceStalledWorker() {
  threadStart.timer = undefined;
  const why = `the threaded core's threads did not start within ${THREAD_START_LIMIT_MS / 1000} s`;
  worker.terminate();
  worker = newWorker();
  listen(worker);
  for (const m of threadStart.told ?? []) worker.postMessage(m.type === 'new' ? { ...m, singleThread: why } : m);
  notify([`${why[0].toUpperCase()}${why.slice(1)}: the page steps on one thread instead (the same results, slower).`]);
}

/** @type {Map<number, { resolve: (v: any) => void, reject: (e: Error) => void }>} */
const calls = new Map();
let nextCall = 0;
/** @type {(() => void) | null} */
let onReady = null;
/** @type {(() => void) | null} */
let onEngine = null;

/**
 * Runs one of the worker's CALLS on the simulation; resolves with its value.
 * @template {keyof Calls} K
 * @param {K} method
 * @param {Parameters<Calls[K]>} args
 * @returns {Promise<Awaited<ReturnType<Calls[K]>>>}
 */
function call(method, ...args) {
  return new Promise((resolve, reject) => {
    const id = ++nextCall;
    calls.set(id, { resolve, reject });
    tell({ type: 'call', id, method, args });
  });
}
demo.call = call;

// Whether the message over the view is the worker's progress (hidden once it is done).
let progressShown = false;
function hideProgress() {
  if (progressShown) message.hidden = true;
  progressShown = false;
}

/** @param {Worker} w */
function listen(w) {
  w.onerror = (/** @type {ErrorEvent} */ e) => {
    watchThreadStart(false);
    fatal('The simulation worker failed', e.message ?? e);
  };
  w.onmessage = onWorkerMessage;
}
listen(worker);

/** @param {MessageEvent<WorkerOut>} e */
function onWorkerMessage(e) {
  const m = e.data;
  if (m.type === 'frame') {
    page.stats = m.stats;
    page.cores = m.cores;
    showSpeed(m.stats);
    loop.receive(m);
  } else if (m.type === 'result') {
    const c = calls.get(m.id);
    calls.delete(m.id);
    if (m.error !== undefined) c?.reject(new Error(m.error));
    else c?.resolve(m.value);
  } else if (m.type === 'stage') {
    watchThreadStart(m.threadStart === true);
    demo.stage = `worker: ${m.text}`;
  } else if (m.type === 'progress') {
    // The GPU engine's kernels compiling (once per device): shown over the view until the
    // engine is chosen.
    demo.progress.push({ text: m.text, at: performance.now() });
    showMessage(`${m.text[0].toUpperCase()}${m.text.slice(1)}…`);
    progressShown = true;
  } else if (m.type === 'engine') {
    hideProgress();
    page.stats = m.stats;
    showEngine(m.stats);
    if (m.lost) notify([`${m.lost[0].toUpperCase()}${m.lost.slice(1)}.`]);
    onEngine?.();
  } else if (m.type === 'ready') {
    watchThreadStart(false);
    threadStart.told = null;
    hideProgress();
    page.stats = m.stats;
    showEngine(m.stats);
    showOrigin(m.stats);
    readouts.reset(m.stats.timeUnitSeconds);
    onReady?.();
  } else if (m.type === 'stopped') {
    setPlaying(false);
    const hint = m.active
      ? 'Activity stretched a cell past the stable range: lower ζ or raise χ, then press Reset.'
      : 'The random start of this seed placed two cells too close to relax them: try another seed and press Reset.';
    showMessage(`The simulation stopped: ${m.why}\n\n${hint}`, true);
    demo.simError = m.why;
  } else if (m.type === 'fatal') {
    watchThreadStart(false);
    fatal('The simulation stopped', m.message);
  }
}

// Which engine steps the tissue, said plainly: the CPU core compiled to WebAssembly gives the
// native program's bits for the same parameters and seed; the GPU engine steps the same model
// in f32 on WebGPU compute (src/gpu/; natively within 10⁻⁴ of the CPU over 100 full-size steps).
/** @param {Stats} s */
function showEngine(s) {
  const size = `${s.cells} cells on ${s.l}²`;
  let text;
  if (s.engine === 'gpu') {
    text = `Engine: GPU (WebGPU compute, f32; ${s.engineNote}), ${size}. Not bit-identical to native (f32): the native tests keep it within 10⁻⁴ of the CPU core over 100 full-size steps.`;
  } else {
    const why = s.engineNote && s.engineNote !== 'chosen' ? ` GPU engine not used: ${s.engineNote}.` : '';
    // From the relaxation, not from a shipped state further on (showOrigin).
    const slow = s.l >= SIZES.paper.box && s.startedAt <= s.relaxSteps
      ? ' At the paper\'s size the CPU engine takes minutes from the relaxation to the first hole.' : '';
    const threads = ` The core runs on ${s.threads} thread${s.threads === 1 ? '' : 's'} (${s.coreNote}).`;
    text = `Engine: CPU (WebAssembly), bit-identical to native, ${size}.${why}${slow}${threads}`;
  }
  $('engine').textContent = text;
  demo.engine = s.engine;
  demo.engineNote = s.engineNote;
  demo.threads = s.threads;
  demo.coreNote = s.coreNote;
}

// The engine's speed as measured in this page (steps and their time since the engine was
// chosen, hand-offs and checks included), beside the engine's name.
/** @param {Stats} s */
function showSpeed(s) {
  const v = s.stepsPerSecond;
  $('speed').textContent = v ? `Measured here: ${v < 10 ? v.toFixed(2) : v.toFixed(0)} steps/s on the ${s.engine === 'gpu' ? 'GPU' : 'CPU'} engine.` : '';
  demo.stepsPerSecond = v ?? null;
}

// Where a tissue from a shipped state further on than its relaxation came from: its seed and
// step, and the step its first hole opens (found natively; tests/relaxed_state.rs holds it).
/** @param {Stats} s */
function showOrigin(s) {
  const shipped = shippedStateFor(page.state);
  const step = shipped?.step;
  const later = s.startedFrom === 'snapshot' && step !== undefined && s.startedAt === step;
  const origin = $('origin');
  origin.hidden = !later;
  if (!shipped || !later) return;
  const n = (/** @type {number | undefined} */ v) => (v ?? NaN).toLocaleString('en-US');
  origin.textContent = `Seed ${shipped.seed}, from step ${n(step)} of the native run (${n(step - s.relaxSteps)} active steps): its first hole opens at step ${n(shipped.firstHole)}. The forecast (key 7) shades where.`;
}

// --- drawing and readouts ---------------------------------------------------------------------------
const readouts = new Readouts();

const loop = new FrameLoop(canvas, {
  check: checkRenderer,
  draw,
  request: (dpr) => tell({ type: 'frame', field: page.state.field, dpr }),
  readouts: updateReadouts,
  fatal: (e) => fatal('The page stopped', e),
});

// Stops or restarts asking the worker for frames, as a hidden tab does (no animation frames)
// while the worker steps on: the browser tests check that the readouts miss no row then.
demo.drawing = (/** @type {boolean} */ on) => {
  if (loop.stopped === !on) return;
  loop.stopped = !on;
  if (on) loop.start();
};

/** @param {{ parts: FrameParts }} frame @param {number} dpr */
function draw(frame, dpr) {
  // Between a lost renderer and its replacement (which redraws the latest frame).
  if (!page.renderer) return;
  const p = frame.parts;
  const view = new WebView(p.l, p.kind, p.tissue, p.field, p.segments, p.range);
  try {
    page.renderer.draw(view, dpr, true);
  } finally {
    view.free();
  }
  demo.drawn = (demo.drawn ?? 0) + 1;
  // Since the page's navigation began (performance.now's origin): the load's measure.
  demo.firstFrameMs ??= performance.now();
  if (p.kind === FieldKind.Tissue) readouts.hideColourBar();
  else readouts.colourBar(p.kind, p.range, layoutNow(), dpr);
  if (recorder.recording) recorder.frame(caption());
  if (page.screenshot) saveScreenshot();
}

// What a recording shows burnt in: the time and the parameters.
function caption() {
  const s = /** @type {Stats} */ (page.stats);
  const st = page.state;
  const t = s.active ? `t = ${s.time.toFixed(0)} (${formatSeconds(s.time * s.timeUnitSeconds)})` : 'relaxing';
  return [
    `${t}, step ${s.step.toLocaleString('en')}`,
    `ζ = ${s.zeta}, χ = ${Number(s.chi.toPrecision(3))}, γ = ${s.gamma}, seed ${viewer.active ? viewer.seed : st.seed}, L = ${s.l}, N = ${s.cells}`,
    FIELDS.get(st.field)?.label ?? '',
  ];
}

// The record button: starts, or stops and saves the WebM.
const recorder = new Recorder(canvas);
async function toggleRecording() {
  if (!recorder.recording) {
    if (!Recorder.supported()) {
      notify(['This browser cannot record WebM video (MediaRecorder).']);
      return;
    }
    recorder.start();
    loop.dirty = true;
  } else {
    const step = page.stats?.step ?? 0;
    const blob = /** @type {Blob} */ (await recorder.stop());
    const a = document.createElement('a');
    a.href = URL.createObjectURL(blob);
    a.download = `monolayer-seed${page.state.seed}-step${step}.webm`;
    a.click();
    setTimeout(() => URL.revokeObjectURL(a.href), 60000);
    const head = new Uint8Array(await blob.slice(0, 4).arrayBuffer());
    demo.lastRecording = { size: blob.size, type: blob.type, head: [...head].map((b) => b.toString(16).padStart(2, '0')).join('') };
  }
  controls.showRecording(recorder.recording);
}

function updateReadouts() {
  const s = page.stats;
  if (!s) return;
  readouts.update(s, loop, page.state.spf, isPlaying());
  tour.update(s, page.cores);
  whatIf.update(s);
  if (s.active && s.holes > 0 && demo.firstHole === null) {
    demo.firstHole = { seconds: (performance.now() - demo.loadedAt) / 1000, step: s.step, sinceNavigationMs: performance.now() };
  }
  demo.stats = {
    ...s, sps: loop.rate.sps, fps: loop.rate.fps, playing: isPlaying(), drawMs: loop.drawMs,
    renderScale: loop.renderScale,
  };
}

// Saves `blob` under `name` (the browser's download; nothing leaves the machine).
/** @param {Blob} blob @param {string} name */
function saveBlob(blob, name) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = name;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 60000);
}

// The Download button: the readouts since the last reset as CSV (its last row the state now),
// and the state now as a frame file in the native format with a run.json, so that
// `mkdir -p run/frames`, the frame into run/frames and run.json into run/ make a run that
// `monolayer analyze run` reads (docs/demo.md, "Data out").
async function download() {
  const d = await call('download');
  const stem = `monolayer-seed${page.state.seed}-step${d.step}`;
  saveBlob(new Blob([d.csv], { type: 'text/csv' }), `${stem}.csv`);
  // The core's Vec<u8>, copied into its own ArrayBuffer by the bindings.
  saveBlob(new Blob([/** @type {Uint8Array<ArrayBuffer>} */ (d.npz)], { type: 'application/octet-stream' }), d.frameName);
  saveBlob(new Blob([d.runJson], { type: 'application/json' }), 'run.json');
  demo.lastDownload = { step: d.step, csvName: `${stem}.csv`, frameName: d.frameName, npzBytes: d.npz.length };
}

// Right after drawing, in the same task: the canvas still holds this frame.
function saveScreenshot() {
  page.screenshot = false;
  const url = canvas.toDataURL('image/png');
  const a = document.createElement('a');
  a.href = url;
  a.download = `monolayer-step${page.stats?.step ?? 0}.png`;
  a.click();
  demo.lastScreenshot = url;
}

// --- renderers ------------------------------------------------------------------------------------

// Where the renderer drew the lattice square and the colour bar, as plain numbers (the wgpu
// renderer's `Layout` is a core object, freed here once read).
/** @returns {import('./canvas2d.js').CanvasGeometry} */
function layoutNow() {
  const g = /** @type {AnyRenderer} */ (page.renderer).layout();
  const out = { x: g.x, y: g.y, side: g.side, bar_y: g.bar_y, bar_h: g.bar_h };
  if (g instanceof Layout) g.free();
  return out;
}
// The page draws with wgpu on WebGPU, else on WebGL2, else with Canvas 2D (canvas2d.js), in
// that order. A lost device or context (a driver update, sleep, a crash of the browser's GPU
// process: normal events) gets a new renderer of the same kind on a new canvas, and drawing goes
// on from the next frame; the simulation, in its worker, loses nothing. After
// LOSSES_BEFORE_FALLBACK losses within LOSS_WINDOW_MS, the page falls back to the next kind and
// says why.
const RENDERERS = ['WebGPU', 'WebGL2', 'Canvas 2D'];
const LOSSES_BEFORE_FALLBACK = 3;
const LOSS_WINDOW_MS = 60_000;
// The kind in use (an index of RENDERERS), the times of its recent losses, and why the page
// draws with a later kind than the first (shown beside the renderer's name).
/** @type {{ level: number, losses: number[], lostOnes: AnyRenderer[], recovering: boolean, glLost: string | null, why: string }} */
const renderers = { level: 0, losses: [], lostOnes: [], recovering: false, glLost: null, why: '' };
demo.rendererLosses = [];

// A fresh canvas in place of the old one: a canvas keeps the kind of context it was first given
// (a WebGPU canvas cannot become a 2D one), and a lost WebGL2 context stays lost on its canvas.
function freshCanvas() {
  const old = canvas;
  const c = /** @type {HTMLCanvasElement} */ (old.cloneNode(false));
  c.width = old.width;
  c.height = old.height;
  old.replaceWith(c);
  canvas = c;
  loop.canvas = c;
  recorder.source = c;
  return c;
}

// A renderer of kind RENDERERS[from] or a later one, on a fresh canvas: { renderer, level }.
// wgpu asked for WebGPU may come back on WebGL2 (no adapter): its level says which it is.
/** @param {number} from @param {boolean} fresh @returns {Promise<{ renderer: AnyRenderer, level: number, why: string }>} */
async function makeRenderer(from, fresh) {
  let why = '';
  for (let level = from; level < RENDERERS.length; level++) {
    const c = fresh || level === RENDERERS.length - 1 ? freshCanvas() : canvas;
    fresh = true;
    renderers.glLost = null;
    c.addEventListener('webglcontextlost', () => {
      if (c === canvas) renderers.glLost = 'the WebGL2 context was lost';
    });
    try {
      if (level === RENDERERS.length - 1) return { renderer: new Canvas2DRenderer(c), level, why };
      const r = await Renderer.create(c, level === 0);
      return { renderer: r, level: r.backend().startsWith('WebGPU') ? 0 : 1, why };
    } catch (e) {
      why = String(/** @type {Error} */ (e).message ?? e);
    }
  }
  throw new Error(why);
}

function showBackend() {
  const r = /** @type {AnyRenderer} */ (page.renderer);
  demo.backend = r.backend();
  demo.renderer = r;
  $('backend').textContent = `Drawing with ${r.backend()}${renderers.why ? ` (${renderers.why})` : ''}.`;
}

// Called by the frame loop before each frame, and every half second besides (Firefox stops
// animation frames altogether once a WebGPU canvas's device is destroyed): a lost renderer is
// replaced.
setInterval(() => checkRenderer(), 500);
function checkRenderer() {
  const r = page.renderer;
  if (!r || renderers.recovering) return;
  const why = r.lost() ?? renderers.glLost;
  if (!why) return;
  renderers.recovering = true;
  replaceRenderer(why).finally(() => {
    renderers.recovering = false;
  });
}

/** @param {string} why */
async function replaceRenderer(why) {
  const now = performance.now();
  const losses = renderers.losses.filter((t) => now - t < LOSS_WINDOW_MS);
  losses.push(now);
  const level = renderers.level;
  const fallBack = losses.length >= LOSSES_BEFORE_FALLBACK;
  renderers.losses = fallBack ? [] : losses;
  const old = page.renderer;
  page.renderer = null;
  // Kept, never freed: freeing a wgpu renderer whose device was destroyed crashed the page in
  // Chromium (SwiftShader) on the second such loss. A few per minute at most: after
  // LOSSES_BEFORE_FALLBACK the page falls back to a renderer that is not lost like this.
  if (old) renderers.lostOnes.push(old);
  let made;
  try {
    made = await makeRenderer(fallBack ? level + 1 : level, true);
  } catch (e) {
    fatal('The page cannot draw any more', e);
    return;
  }
  page.renderer = made.renderer;
  renderers.level = made.level;
  const record = { at: now, why, from: RENDERERS[level], to: RENDERERS[made.level] };
  demo.rendererLosses.push(record);
  if (fallBack) {
    renderers.why = `${RENDERERS[level]} lost its device ${LOSSES_BEFORE_FALLBACK} times within a minute, the last time because ${why}`;
    notify([`Drawing with ${RENDERERS[made.level]} now: ${renderers.why}.`]);
  }
  showBackend();
  loop.dirty = true;
}

// --- actions: the only writers of the state -------------------------------------------------------
const isPlaying = () => !page.state.paused;

function changed() {
  controls.refresh(page.state, isPlaying());
  history.replaceState(null, '', toUrl(page.state, page.version));
}

// Another field drawn. The frame asked for before was of the old field: the worker holds such a
// request until the state changes, so a paused tissue would never be drawn in the new field
// without asking again.
/** @param {import('../pkg/monolayer.js').FieldKind} kind */
function showField(kind) {
  page.state.field = kind;
  loop.requested = false;
  changed();
}

// A new tissue from the state's parameters and seed; resolves once the worker has it.
function newSim() {
  if (viewer.active && page.renderer) showBackend();
  viewer.close();
  // A replay of "What if?" is gone with the tissue it replayed.
  page.aside = null;
  const s = page.state;
  /** @type {Promise<void>} */
  const ready = new Promise((resolve) => {
    onReady = resolve;
  });
  tell({
    type: 'new', size: SIZES[s.size], params: { zeta: s.zeta, chi: s.chi, gamma: s.gamma }, seed: s.seed, shipped: shippedStateFor(s)?.file ?? null,
    engine: s.engine, threads: s.threads,
  });
  demo.size = SIZES[s.size];
  tellWorkerToPlay();
  loop.restart();
  demo.firstHole = null;
  demo.loadedAt = performance.now();
  demo.simError = null;
  message.hidden = true;
  return ready;
}

// Another engine for the same tissue (the Engine chooser): it goes on from the state it has.
/** @param {import('./worker.js').EngineChoice} engine */
function setEngine(engine) {
  page.state.engine = engine;
  changed();
  /** @type {Promise<void>} */
  const done = new Promise((resolve) => {
    onEngine = resolve;
  });
  tell({ type: 'engine', engine });
  return done;
}
demo.setEngine = setEngine;

/** @param {boolean} on */
function setPlaying(on) {
  page.state.paused = !on;
  tellWorkerToPlay();
  changed();
}

// A hidden page does not step: a forgotten background tab should not hold a core.
function tellWorkerToPlay() {
  tell({ type: 'play', on: isPlaying() && !document.hidden });
}
document.addEventListener('visibilitychange', tellWorkerToPlay);

// Sets a parameter in the state and, for the model's, in the core (a preset sets them together).
/** @param {import('./state.js').ParamName} name @param {number} value */
function setParam(name, value, fromPreset = false) {
  const state = page.state;
  state[name] = value;
  if (name === 'zeta' || name === 'chi' || name === 'gamma') {
    if (!fromPreset) state.preset = null;
    call('set_param', name, value).catch((e) => notify([`${name} = ${value}: ${e.message ?? e}`]));
  }
  if (name === 'spf') tell({ type: 'spf', n: value });
  changed();
}

// Pointer → lattice site, through the layout the renderer drew.
/** @param {PointerEvent} ev @returns {[number, number] | null} */
function latticeAt(ev) {
  if (!page.stats || !page.renderer) return null;
  const rect = canvas.getBoundingClientRect();
  const scale = canvas.width / rect.width; // backing pixels per CSS pixel
  const { x: x0, y: y0, side } = layoutNow();
  const l = page.stats.l;
  const x = (((ev.clientX - rect.left) * scale - x0) / side) * l;
  const y = (((ev.clientY - rect.top) * scale - y0) / side) * l;
  demo.lastPointer = [x, y];
  return x >= 0 && y >= 0 && x < l && y < l ? [x, y] : null;
}

// A brush or the laser: an invalid stroke is reported, not fatal.
/** @param {Promise<unknown>} done */
const reported = (done) => done.catch((e) => notify([String(e.message ?? e)]));

const controls = new Controls({
  setParam,
  applyPreset(name) {
    const resize = PRESETS[name].size !== page.state.size;
    page.state.size = PRESETS[name].size;
    for (const k of MODEL_PARAMS) setParam(k, PRESETS[name][k], true);
    page.state.preset = name;
    changed();
    // Another size is another tissue: a new one, from the shipped relaxed state if there is one.
    if (resize) newSim();
  },
  setField: (kind) => showField(kind),
  setSeed(raw) {
    const p = PARAMS.seed;
    let v = Math.round(Number(raw));
    if (!Number.isFinite(v) || v < p.min || v > p.max) {
      v = Math.min(p.max, Math.max(p.min, Number.isFinite(v) ? v : p.def));
      notify([`Seed must be an integer in [0, ${p.max}]: using ${v}.`]);
    }
    page.state.seed = v;
    changed();
  },
  togglePlay: () => (viewer.active ? viewer.toggle() : setPlaying(!isPlaying())),
  stepOnce() {
    if (viewer.active) {
      viewer.setPlaying(false);
      viewer.show((viewer.index + 1) % viewer.frames.length);
      return;
    }
    setPlaying(false);
    call('step', page.state.spf);
  },
  reset() {
    // Out of a replay: the live tissue's parameters, then a new tissue.
    if (page.aside) Object.assign(page.state, page.aside);
    newSim();
  },
  setEngine: (engine) => setEngine(engine),
  screenshot() {
    page.screenshot = true;
    loop.dirty = true;
  },
  record: () => toggleRecording(),
  download: () => download().catch((e) => notify([`Download: ${e.message ?? e}`])),
  brush: (x, y, radius, multiplier) => reported(call('paint_substrate', x, y, radius, multiplier)),
  ablate: (x, y) => reported(call('remove_cell_at', x, y)),
  latticeAt,
});

// The guided tour (tour.js): the paper's tissue from its shipped state, captions at its events.
const tour = new Tour({
  async begin(playing) {
    const s = page.state;
    Object.assign(s, { preset: 'paper', size: PRESETS.paper.size, seed: 1, tour: true, paused: !playing });
    for (const k of MODEL_PARAMS) s[k] = PRESETS.paper[k];
    // The tour's pace, unless the link set one (a test, or a visitor who wants it faster).
    if (!new URLSearchParams(location.search).has('spf')) s.spf = TOUR_SPF;
    tell({ type: 'spf', n: s.spf });
    changed();
    await newSim();
    return /** @type {Stats} */ (page.stats);
  },
  setField: (name) => {
    const kind = [...FIELDS.keys()].find((k) => fieldName(k) === name);
    if (kind !== undefined) showField(kind);
  },
  setPlaying: (on) => setPlaying(on),
  end() {
    page.state.tour = false;
    changed();
  },
});
demo.tour = tour;
$('tour-start').addEventListener('click', () => tour.start());

// "What if?" (whatif.js): the live tissue's last hole replayed from a state saved before it,
// with activity off or halved; the ζ slider and the URL show the replay's ζ, and Back returns
// to the live tissue and its parameters.
const whatIf = new WhatIf({
  async rewind(factor) {
    const r = await call('what_if', factor).catch((e) => {
      notify([`What if?: ${e.message ?? e}`]);
      return null;
    });
    if (!r) return;
    const s = page.state;
    page.aside ??= { zeta: s.zeta, chi: s.chi, gamma: s.gamma, preset: s.preset };
    s.zeta = r.zeta;
    s.preset = null;
    whatIf.factor = factor;
    demo.whatIf = r;
    afterSwap();
    setPlaying(true);
  },
  async back() {
    const r = await call('back_to_live');
    if (page.aside) Object.assign(page.state, page.aside);
    page.aside = null;
    whatIf.factor = null;
    demo.whatIfBack = r;
    afterSwap();
  },
});
demo.whatIfControl = whatIf;

// The worker shows another tissue of the same size (a replay, or the live one again): the
// readouts start over, the controls and the URL follow.
function afterSwap() {
  readouts.reset(page.stats?.timeUnitSeconds ?? 1);
  loop.restart();
  changed();
}

// A run's frames (viewer.js): they replace the live tissue until Reset.
const viewer = new Viewer({
  open: (files) => call('open', files),
  show: (index) => call('show', index),
  opened(r) {
    // The live tissue (and a replay of it) are gone: the controls show the live parameters.
    if (page.aside) Object.assign(page.state, page.aside);
    page.aside = null;
    setPlaying(false);
    readouts.reset(page.stats?.timeUnitSeconds ?? 1);
    loop.restart();
    message.hidden = true;
    const from = r.runVersion && r.runVersion !== page.version ? ` (written by version ${r.runVersion}; this page is ${page.version})` : '';
    $('backend').textContent = `Showing ${r.frames.length} frames of a run, seed ${r.seed}${from}. Drawing with ${page.renderer?.backend()}.`;
  },
  frameShown() {
    loop.dirty = true;
  },
});
demo.playback = viewer.state;

// --- start ----------------------------------------------------------------------------------------
async function boot() {
  demo.stage = 'page: loading the core';
  try {
    await init();
  } catch (e) {
    fatal('Could not load the WebAssembly core (build it with `bash scripts/serve.sh`)', e);
    return;
  }
  // The code version goes into every share link; a link from another version says so.
  page.version = codeVersion();
  demo.version = page.version;
  $('version').textContent = `Code version ${page.version}.`;
  const parsed = parseUrl(location.search, page.version);
  page.state = parsed.state;
  notify(parsed.notices);
  document.body.classList.toggle('embed', page.state.embed);
  changed();
  tell({ type: 'spf', n: page.state.spf });
  showMessage('Looking for WebGPU or WebGL2…');
  demo.stage = 'page: looking for a renderer';
  loop.resizeCanvas();
  try {
    const made = await makeRenderer(0, false);
    page.renderer = made.renderer;
    renderers.level = made.level;
    if (made.level === RENDERERS.length - 1) renderers.why = `this browser offers neither WebGPU nor WebGL2: ${made.why}`;
  } catch (e) {
    $('engine').textContent = 'Engine: none (nothing steps without a canvas to draw the tissue on).';
    demo.engine = 'none';
    fatal('This page cannot draw on its canvas', e);
    return;
  }
  showBackend();
  // The browser tests' forced loss: the renderer's device destroyed, as a driver reset would,
  // or its WebGL2 context lost.
  demo.loseRenderer = () => {
    const r = page.renderer;
    if (r && 'destroy_device' in r) r.destroy_device();
    canvas.getContext('webgl2')?.getExtension('WEBGL_lose_context')?.loseContext();
  };
  demo.stage = 'page: making the tissue';
  if (page.state.tour) await tour.start();
  else await newSim();
  if (demo.error) return;
  demo.ready = true;
  loop.start();
}

boot();
