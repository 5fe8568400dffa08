// The simulation's own thread. The WebAssembly core is instantiated here and steps while the
// page plays, whatever the drawing costs; whenever the main thread is ready to draw, it asks
// for a frame and gets the latest state's view, its arrays transferred (not copied).
//
// Two engines step the tissue: the CPU core compiled to WebAssembly (`WebSim`, bit-identical to
// native), and where WebGPU compute works the GPU engine (`WebGpuEngine`, the same model in
// f32 on WebGPU compute, src/gpu/), which steps without reading back and hands its state to
// the `WebSim` only when the page draws, measures or edits: everything drawn and read out is
// measured by the same code either way.
//
// The core comes in two builds (scripts/serve.sh): the single-thread one (www/pkg, with the GPU
// engine) and a threaded one (www/pkg-threads: the core's parallel loops on a pool of Web
// Workers sharing its memory, wasm-bindgen-rayon), which needs a cross-origin isolated page
// (COOP/COEP headers) for its shared memory. The first tissue loads one of them (loadCore):
// the threaded one where the page is isolated and the CPU engine is to step, else the other.
// Both give the same bits: the parallel loops do not depend on the thread count (par.rs).
//
// Messages in (`WorkerIn` below): new, engine, play, spf, frame, call. Messages out
// (`WorkerOut`): ready, progress, engine, frame, stopped, result, fatal. A call runs one of
// `CALLS` (the page's and the tests' requests: step, download, open a run, "What if?", …).
//
// THE STATE MACHINE. Everything the worker holds is one value, `state`, whose `kind` says what
// the page shows and what steps it:
//
//   none    no tissue: before the first 'new', while one is made, after a fatal error
//   cpu     a tissue stepped by the CPU core (`tissue.sim` steps in place)
//   gpu     a tissue stepped by the GPU engine; `sync` says how `tissue.sim` stands to the
//           device: 'level' (the same state), 'ahead' (the device has stepped on: submissions
//           in `flight`, or a state not yet downloaded), 'stale' (`tissue.sim` was edited since
//           the last upload: upload before the next submission)
//   frames  a native run's frames (`playback`) instead of a live tissue
//
// A tissue is live, or a replay of its past ("What if?"): then `tissue.live` holds the live
// simulation, set aside as it was, and `tissue.sim` the replay, which steps, draws and edits
// like any tissue.
//
//   state            event                          next state        what it does
//   ---------------  -----------------------------  ----------------  --------------------------------------------
//   any              'new'                          none, then cpu    frees what it held; makes the tissue (a
//                                                                     shipped state, else random disks)
//   cpu              chooseEngine finds the GPU     gpu (level)       compiles the kernels, uploads the tissue
//   cpu / gpu        'engine'                       cpu, then cpu|gpu levels with the device first, then chooses
//   gpu (level)      a turn while playing           gpu (ahead)       uploads if stale, submits up to
//    or (stale)                                                       `in_flight_max` submissions, each ending at
//                                                                     the next row of readouts at the latest
//   gpu (ahead)      settle: checked, a download    gpu (level|ahead) the state handed to `tissue.sim` (its row
//                    queued behind it                                 of readouts, a frame if one is asked for)
//   gpu (ahead)      down (a frame paused, a call)  gpu (level)       settles every submission, downloads, adopts
//   gpu (level)      an edit (a slider, a brush,    gpu (stale)       the edit is made on `tissue.sim`
//                    a removed cell, What if, back)
//   gpu              a model fault on a check       gpu (level),      the state before the failing submission;
//                                                   paused            the page told ('stopped')
//   gpu              a device fault (lost, a GPU    cpu               on the CPU core from the last state handed
//                    error, a readback unmapped)                      over; the page told ('engine', lost)
//   cpu (live)       call what_if(factor)           cpu (replay)      the live sim set aside; a replay from the
//   gpu (live)                                      gpu (stale)       saved state before its last hole, ζ × factor
//   cpu / gpu        call what_if again (replay)    same (replay)     the replay replaced by a new one
//    (replay)
//   cpu / gpu        call back_to_live              cpu / gpu         the replay freed, the live sim back as it
//    (replay)                                       (live; gpu stale) was left
//   cpu / gpu        call open (a run's files)      frames            frees the tissue (live and replay)
//   any              a fatal error                  none              the page told ('fatal')
//
// Everything that may touch the GPU engine or replace the tissue runs as one turn of a queue
// (`inTurn`): a submission is checked before the next, a download never meets a submission, a
// call sees the tissue level with the device, and a transition never meets another half done.
// The CPU engine steps between turns, from `pump`, in batches of about BATCH_MS.

/** @typedef {import('../pkg/monolayer.js').WebSim} WebSim */
/** @typedef {import('../pkg/monolayer.js').WebPlayback} WebPlayback */
/** @typedef {import('../pkg/monolayer.js').WebGpuEngine} WebGpuEngine */
/** @typedef {import('../pkg/monolayer.js').GpuState} GpuState */
/** @typedef {import('../pkg/monolayer.js').FieldKind} FieldKind */
/** @typedef {import('../pkg/monolayer.js').Readout} Readout */
/** @typedef {import('../pkg/monolayer.js').DefectMark} DefectMark */
/** @typedef {import('../pkg/monolayer.js').SpiralMark} SpiralMark */
/** @typedef {typeof import('../pkg/monolayer.js')} SingleCore */
/**
 * The core's module: the single-thread build's exports; the GPU engine only in that build.
 * @typedef {Omit<SingleCore, 'WebGpuEngine'> & { WebGpuEngine?: SingleCore['WebGpuEngine'] }} Core
 */

/**
 * A tissue's size (state.js, SIZES), its model parameters, the engine asked for.
 * @typedef {{ box: number, cells: number, relaxSteps: number }} Size
 * @typedef {{ zeta: number, chi: number, gamma: number }} ModelParams
 * @typedef {'auto' | 'cpu' | 'gpu'} EngineChoice
 */

/**
 * The messages in.
 * `singleThread`: why this worker must not start the threaded core (the page's worker before it
 * did not finish starting its threads; main.js), said in `coreNote`.
 * @typedef {{ type: 'new', size: Size, params: ModelParams, seed: number, shipped: string | null,
 *   engine: EngineChoice, threads: number | null, singleThread?: string }} NewTissue
 * @typedef {NewTissue
 *   | { type: 'engine', engine: EngineChoice }
 *   | { type: 'play', on: boolean }
 *   | { type: 'spf', n: number }
 *   | { type: 'frame', field: FieldKind, dpr: number }
 *   | { type: 'call', id: number, method: CallName, args: unknown[] }} WorkerIn
 */

/**
 * A view's arrays (`WebView` of src/web/render.rs), transferred to the main thread.
 * @typedef {{ l: number, kind: FieldKind, tissue: Float32Array, field: Float32Array, segments: Float32Array,
 *   range: Float32Array }} FrameParts
 *
 * Where "What if?" rewinds the live tissue to: the saved state's step, and the last hole's
 * first row of readouts and where it opened.
 * @typedef {{ from: number, holeStep: number, holeX: number, holeY: number }} Rewind
 *
 * A replay's watch for the hole it was rewound before (src/web/history.rs): the verdict so far
 * ('tore': a hole opened within `radius` of where it did, at `tearStep`; 'held': none did by
 * `until`).
 * @typedef {{ from: number, savedFingerprint: string, holeStep: number, holeX: number, holeY: number,
 *   until: number, radius: number, verdict: 'watching' | 'tore' | 'held', tearStep: number | null }} Replay
 *
 * What the page shows of the tissue (main.js, readouts.js, the tests): the readout of the core
 * (`Readout`), how the tissue started and which engine steps it, and "What if?".
 * @typedef {object} Stats
 * @property {number} step steps since the random disks, relaxation included
 * @property {number} time active time, in time units
 * @property {number} holes void regions above πR²/4
 * @property {number} area void sites
 * @property {number} packing fraction of sites with Σφ ≥ ½
 * @property {boolean} active
 * @property {number} zeta
 * @property {number} chi
 * @property {number} gamma
 * @property {number} cells
 * @property {number} l the box's side
 * @property {number} relaxSteps
 * @property {number} timeUnitSeconds
 * @property {number} msPerStep
 * @property {'snapshot' | 'disks' | 'frames'} startedFrom
 * @property {number} startedAt the step the tissue started at
 * @property {'cpu' | 'gpu' | 'none'} engine which engine steps, and why (`engineNote`)
 * @property {string} engineNote
 * @property {number | null} stepsPerSecond measured here since the engine was chosen
 * @property {number | null} solveIterations the GPU engine's recorded CG iterations per solve
 * @property {number} threads the core's threads, and its build (`coreNote`)
 * @property {string} coreNote
 * @property {Rewind | null} rewind where "What if?" would rewind the live tissue to (null: nowhere yet)
 * @property {Replay | null} replay the replay shown (null: the live tissue)
 * @property {number | null} frame the frame shown of a run's (null: a live tissue)
 * @property {number | null} frames how many the run has
 */

/**
 * The messages out.
 * @typedef {{ type: 'ready', stats: Stats }
 *   | { type: 'progress', text: string }
 *   | { type: 'stage', text: string, threadStart?: boolean }
 *   | { type: 'engine', stats: Stats, lost?: string }
 *   | { type: 'frame', parts: FrameParts, stats: Stats, cores: number }
 *   | { type: 'stopped', why: string, active: boolean }
 *   | { type: 'result', id: number, value?: unknown, error?: string }
 *   | { type: 'fatal', message: string }} WorkerOut
 */

/**
 * The states.
 * @typedef {object} Tissue
 * @property {WebSim} sim the tissue shown, stepped, measured and edited
 * @property {WebSim | null} live the live tissue set aside while `sim` is a replay of its past
 * @property {'snapshot' | 'disks'} startedFrom a shipped state, or random disks relaxed here
 * @property {number} startedAt
 *
 * The GPU engine's device, made once per worker: { engine, adapter (its name), software }.
 * @typedef {{ engine: WebGpuEngine, adapter: string, software: boolean }} GpuDevice
 *
 * A GPU submission under way: its steps, and the download of the state it ends at, queued
 * behind it where it ends on a row of readouts or a frame is asked for (else null).
 * @typedef {{ k: number, down: Promise<GpuState> | null }} Submission
 *
 * @typedef {{ kind: 'none' }} NoTissue
 * @typedef {{ kind: 'cpu', tissue: Tissue, note: string }} CpuState
 * @typedef {{ kind: 'gpu', tissue: Tissue, note: string, device: GpuDevice, sync: 'level' | 'ahead' | 'stale',
 *   flight: Submission[] }} GpuEngineState
 * @typedef {{ kind: 'frames', playback: { p: WebPlayback, frames: RunFrame[], index: number } }} FramesState
 * @typedef {{ name: string, step: number, file: File }} RunFrame
 * @typedef {NoTissue | CpuState | GpuEngineState | FramesState} State
 */

/** @type {State} */
let state = { kind: 'none' };

// The worker's global scope, typed: this file is checked with the page's DOM types.
const scope = /** @type {{ postMessage(m: WorkerOut, transfer?: Transferable[]): void,
  onmessage: ((e: MessageEvent<WorkerIn>) => void) | null }} */ (/** @type {unknown} */ (globalThis));

/** @param {WorkerOut} m @param {Transferable[]} [transfer] */
const post = (m, transfer = []) => scope.postMessage(m, transfer);

/** @param {unknown} e */
const messageOf = (e) => String(/** @type {{ message?: unknown }} */ (e)?.message ?? e);

// What is loaded once per worker: the core's module and which build it is, on how many threads
// and why; WebGPU's adapter (asked once) and the GPU engine's device (made once, when it is to
// step), as promises.
const loaded = {
  /** @type {Core | null} */ core: null,
  coreNote: '',
  /** @type {Promise<{ adapter: string, software: boolean } | { error: string }> | null} */ adapter: null,
  /** @type {Promise<GpuDevice | { error: string }> | null} */ device: null,
};

// The pace: whether the tissue plays, and the "steps per frame" slider's cap of `spf` steps per
// 1/30 s, a budget that refills with time, not with frames drawn, so that drawing never holds
// stepping back. A batch of steps is sized to take about BATCH_MS (GPU_BATCH_MS for a GPU
// submission), so that messages are answered promptly; `steps` and `ms` since the engine was
// last chosen (hand-offs and checks included) are the speed the page reports as measured here.
const BATCH_MS = 12;
const GPU_BATCH_MS = 40;
const pace = {
  playing: false,
  spf: 20,
  budget: 0,
  refilledAt: performance.now(),
  msPerStep: 5,
  steps: 0,
  ms: 0,
  scheduled: false,
};

// The page's pending request for a frame, whether the state changed since the last frame sent,
// and what that frame was.
const view = {
  /** @type {{ field: FieldKind, dpr: number } | null} */ request: null,
  changed: true,
  /** @type {FieldKind | null} */ lastField: null,
  /** @type {number | null} */ lastDpr: null,
};

// The queue of turns (`inTurn`), and whether a GPU turn is in it.
/** @type {{ queue: Promise<unknown>, gpuQueued: boolean }} */
const turns = { queue: Promise.resolve(), gpuQueued: false };

/**
 * Runs fn as the next turn, after every turn queued before it (whether that one failed or not).
 * @template T
 * @param {() => T | Promise<T>} fn
 * @returns {Promise<T>}
 */
function inTurn(fn) {
  const next = turns.queue.then(fn, fn);
  turns.queue = next;
  return next;
}

/** @param {number} steps @param {number} ms */
function timed(steps, ms) {
  pace.steps += steps;
  pace.ms += ms;
}

// The core and the tissue in use, or null.
const gpuState = () => (state.kind === 'gpu' ? state : null);
const tissueOf = () => (state.kind === 'cpu' || state.kind === 'gpu' ? state.tissue : null);
const core = () => {
  if (!loaded.core) throw new Error('the core is not loaded');
  return loaded.core;
};

// The live tissue's simulation (or its replay), for the calls that need one.
function sim() {
  const t = tissueOf();
  if (!t) throw new Error("there is no live tissue: a run's frames are shown (Reset returns to it)");
  return t.sim;
}

// console_error_panic_hook writes a Rust panic's message to console.error before the trap.
let lastConsoleError = '';
const consoleError = console.error.bind(console);
console.error = (...args) => {
  lastConsoleError = args.map(String).join(' ');
  consoleError(...args);
};

// Any state → none: the page is told, and nothing steps any more.
/** @param {unknown} e */
function fatal(e) {
  const panic = lastConsoleError.includes('panicked') ? `\n\n${lastConsoleError}` : '';
  post({ type: 'fatal', message: `${messageOf(e)}${panic}` });
  state = { kind: 'none' };
}

// What the worker is waiting on while it makes a tissue, for the page's `demo.stage` (a page
// that never becomes ready says where it stopped). `threadStart` marks the start of the threaded
// core's threads, which the page watches (main.js, THREAD_START_LIMIT_MS).
/** @param {string} text @param {boolean} [threadStart] */
function stage(text, threadStart = false) {
  post({ type: 'stage', text, threadStart });
}

// Why the tissue `m` is to be stepped by the single-thread build; undefined: by the threaded one.
/** @param {NewTissue} m @returns {Promise<string | undefined>} */
async function singleThreadReason(m) {
  if (m.singleThread) return m.singleThread;
  if (!self.crossOriginIsolated) return 'the page is not cross-origin isolated';
  if (typeof SharedArrayBuffer === 'undefined') return 'this browser has no SharedArrayBuffer';
  if (m.engine === 'gpu') return 'the GPU engine is in the single-thread build';
  if (m.engine === 'auto') {
    stage('asking WebGPU for an adapter');
    const found = await gpuAdapterOnce();
    if (!('error' in found) && !found.software) return 'the GPU engine may step here, and it is in the single-thread build';
  }
  return undefined;
}

// Loads the core for the first tissue `m` (the build stays for the worker's life).
/** @param {NewTissue} m */
async function loadCore(m) {
  if (loaded.core) return;
  let why = await singleThreadReason(m);
  if (!why) {
    try {
      // A specifier the type check does not follow: the threaded build exists only where the
      // nightly toolchain built it, and its exports are the single-thread build's without the
      // GPU engine, with initThreadPool.
      const THREADED = '../pkg-threads/monolayer.js';
      stage('loading the threaded core');
      const threaded = /** @type {Core & { default(): Promise<unknown>, initThreadPool(n: number): Promise<unknown> }} */ (
        await import(THREADED));
      await threaded.default();
      stage('starting the threaded core\'s threads', true);
      await threaded.initThreadPool(Math.max(1, m.threads ?? navigator.hardwareConcurrency ?? 1));
      loaded.core = threaded;
      loaded.coreNote = 'threaded build, cross-origin isolated';
      return;
    } catch (e) {
      why = `the threaded build did not load (${messageOf(e)})`;
    }
  }
  stage('loading the single-thread core');
  const single = await import('../pkg/monolayer.js');
  await single.default();
  loaded.core = single;
  loaded.coreNote = `single-thread build: ${why}`;
}

// A zero-delay task (setTimeout would be clamped to 4 ms once nested).
const tick = new MessageChannel();
tick.port1.onmessage = () => pump();
function schedule() {
  if (!pace.scheduled) {
    pace.scheduled = true;
    tick.port2.postMessage(null);
  }
}

// Steps the CPU core; on an error of the model (the core keeps the state before the failing
// step) pauses and tells the page why.
/** @param {WebSim} s @param {number} n */
function takeSteps(s, n) {
  try {
    s.step(n);
    return true;
  } catch (e) {
    if (e instanceof WebAssembly.RuntimeError) throw e;
    pace.playing = false;
    post({ type: 'stopped', why: messageOf(e), active: s.active() });
    return false;
  }
}

function refill() {
  const now = performance.now();
  pace.budget = Math.min(pace.spf, pace.budget + ((now - pace.refilledAt) * pace.spf * 30) / 1000);
  pace.refilledAt = now;
}

// The scheduler: on the GPU engine, queues a turn (gpuTurn); on the CPU engine, a batch of
// steps now; then a frame if one is asked for.
function pump() {
  pace.scheduled = false;
  const s = state;
  if (s.kind === 'none') return;
  if (s.kind === 'gpu') {
    if (!turns.gpuQueued) {
      turns.gpuQueued = true;
      inTurn(gpuTurn).finally(() => {
        turns.gpuQueued = false;
        if (pace.playing || view.request) schedule();
      });
    }
    return;
  }
  try {
    if (pace.playing && s.kind === 'cpu') {
      refill();
      const n = Math.min(Math.floor(pace.budget), Math.max(1, Math.floor(BATCH_MS / pace.msPerStep)));
      if (n >= 1) {
        const t0 = performance.now();
        if (takeSteps(s.tissue.sim, n)) {
          const ms = performance.now() - t0;
          pace.msPerStep = 0.8 * pace.msPerStep + 0.2 * (ms / n);
          timed(n, ms);
          pace.budget -= n;
          view.changed = true;
        }
      }
    }
    if (view.request) sendFrame();
    if (pace.playing) {
      if (pace.budget >= 1) schedule();
      else setTimeout(schedule, 1000 / (30 * pace.spf));
    }
  } catch (e) {
    fatal(e);
  }
}

// --- the GPU engine --------------------------------------------------------------------------

// Whether an adapter is a software one (SwiftShader, lavapipe): there the CPU engine is faster.
/** @param {Record<string, unknown>} info */
function isSoftware(info) {
  const text = [info.vendor, info.architecture, info.description, info.device].join(' ');
  return Boolean(info.isFallbackAdapter) || /swiftshader|llvmpipe|lavapipe|software/i.test(text);
}

// What WebGPU offers here, asked once: { adapter (its name), software } or { error }. The
// adapter the engine asks for (src/gpu/context.rs: high performance), so that the name shown
// and the software test are of the one that steps.
function gpuAdapterOnce() {
  loaded.adapter ??= (async () => {
    // WebGPU's types are not among the page's (the type check knows the DOM without it).
    const gpu = /** @type {{ gpu?: { requestAdapter(o: object): Promise<{ info?: Record<string, unknown> } | null> } }} */ (
      /** @type {unknown} */ (self.navigator))?.gpu;
    if (!gpu) return { error: 'this browser has no WebGPU' };
    const adapter = await gpu.requestAdapter({ powerPreference: 'high-performance' }).catch(() => null);
    if (!adapter) return { error: 'WebGPU found no adapter' };
    const info = adapter.info ?? {};
    const name = [info.vendor, info.architecture, info.description].filter(Boolean).join(' ') || 'unnamed adapter';
    return { adapter: name, software: isSoftware(info) };
  })();
  return loaded.adapter;
}

// The GPU engine's device, made once and only when it is to step.
/** @param {{ adapter: string, software: boolean }} found */
function gpuDeviceOnce(found) {
  loaded.device ??= (async () => {
    try {
      const GpuEngine = core().WebGpuEngine;
      if (!GpuEngine) throw new Error('this build has no GPU engine');
      const engine = await GpuEngine.create();
      return { engine, adapter: found.adapter, software: found.software || engine.runs_on_cpu() };
    } catch (e) {
      return { error: `WebGPU refused a device for compute (${messageOf(e)})` };
    }
  })();
  return loaded.device;
}

// The GPU engine's kernels, compiled one at a time (once per device), the page told the
// progress before each: the browser compiles them in its GPU process before their first use,
// which would otherwise hold the first step (about 7 s on SwiftShader) with nothing shown.
/** @param {WebGpuEngine} engine */
async function compileKernels(engine) {
  const total = engine.kernels();
  for (let left = engine.kernels_left(); left > 0; ) {
    post({ type: 'progress', text: `compiling the GPU engine's kernels: ${total - left} of ${total}` });
    left = await engine.compile_next();
  }
}

// cpu or gpu → cpu, then → gpu where the GPU engine is to step: 'gpu' wherever WebGPU compute
// works, 'cpu' always, and 'auto' the GPU on a hardware adapter and the CPU on a software one,
// where it is faster. The CPU engine steps while the GPU engine's kernels compile.
/** @param {Tissue} tissue @param {EngineChoice} wanted */
async function chooseEngine(tissue, wanted) {
  /** @param {string} note */
  const onCpu = (note) => {
    state = { kind: 'cpu', tissue, note };
  };
  onCpu('chosen');
  if (wanted === 'cpu') return;
  const found = await gpuAdapterOnce();
  if ('error' in found) return onCpu(`${found.error}: stepping on the CPU engine`);
  if (wanted === 'auto' && found.software) {
    return onCpu(`WebGPU runs in software here (${found.adapter}), where the CPU engine is faster`);
  }
  if (!core().WebGpuEngine) {
    return onCpu('the threaded core has no GPU engine (?engine=gpu opens the page on the single-thread core, which has)');
  }
  const d = await gpuDeviceOnce(found);
  if ('error' in d) return onCpu(`${d.error}: stepping on the CPU engine`);
  try {
    await compileKernels(d.engine);
  } catch (e) {
    return onCpu(`the GPU engine's kernels did not compile (${messageOf(e)}): stepping on the CPU engine`);
  }
  try {
    d.engine.upload(tissue.sim);
  } catch (e) {
    return onCpu(`the GPU could not take this tissue (${messageOf(e)}): stepping on the CPU engine`);
  }
  let note = d.software ? `on a software adapter (${d.adapter}), chosen` : d.adapter;
  if (wanted === 'auto') {
    // A hardware adapter: the faster engine for this tissue, by a short trial.
    let t;
    try {
      t = await engineTrial(tissue.sim, d, TRIAL_STEPS);
    } catch (e) {
      return onCpu(`the GPU engine failed its trial (${messageOf(e)}): stepping on the CPU engine`);
    }
    const ms = `${t.gpu.toFixed(2)} ms per step against ${t.cpu.toFixed(2)} on the CPU engine in a short trial`;
    if (!(t.gpu < t.cpu)) return onCpu(`${d.adapter} took ${ms}: stepping on the CPU engine`);
    note = `${d.adapter}, ${ms}`;
  }
  state = { kind: 'gpu', tissue, note, device: d, sync: 'level', flight: [] };
}

// Steps per engine in `auto`'s trial: enough to time past the first submission's set-up,
// few enough to stay under a second on any engine worth choosing.
const TRIAL_STEPS = 5;

// Milliseconds per step of each engine on the tissue as it is, which the trial leaves as it was:
// the CPU core on a copy, the GPU engine from an upload of `s` after one warm-up step (its
// first submission compiles and sets up), then uploaded again.
/** @param {WebSim} s @param {GpuDevice} d @param {number} steps */
async function engineTrial(s, d, steps) {
  const copy = s.core_copy();
  let cpu;
  try {
    const t0 = performance.now();
    copy.step(steps);
    cpu = (performance.now() - t0) / steps;
  } finally {
    copy.free();
  }
  d.engine.upload(s);
  d.engine.submit(1);
  await d.engine.check();
  const t1 = performance.now();
  const k = d.engine.submit(steps);
  await d.engine.check();
  const gpuMs = (performance.now() - t1) / Math.max(k, 1);
  d.engine.upload(s);
  return { cpu, gpu: gpuMs };
}

// gpu (ahead) → gpu (level): the submissions under way settled, then one readback, so that
// the tissue can be drawn, measured or edited. A device fault on the way: → cpu.
async function gpuDown() {
  for (let g = gpuState(); g && g.flight.length; g = gpuState()) {
    if ((await gpuSettle(g)) === null) return;
  }
  const g = gpuState();
  if (!g || g.sync !== 'ahead') return;
  try {
    g.tissue.sim.adopt(await g.device.engine.download());
  } catch (e) {
    if (gpuFailed(g)) return;
    throw e;
  }
  g.sync = 'level';
  view.changed = true;
}

// Whether the GPU device failed (lost, a GPU error, a readback that did not map), as opposed to
// the model (φ out of range, a cell lost); if it did, gpu → cpu (gpuLost).
/** @param {GpuEngineState} g */
function gpuFailed(g) {
  const why = g.device.engine.device_fault();
  if (!why) return false;
  gpuLost(g, why);
  return true;
}

// gpu → cpu: the tissue goes on on the CPU engine from the last state `tissue.sim` holds (the
// last hand-off, at most a row of readouts behind the device), and the page says why. A later
// choice of the GPU engine asks for a new adapter and device.
/** @param {GpuEngineState} g @param {string} why */
function gpuLost(g, why) {
  if (state !== g) return;
  loaded.adapter = null;
  loaded.device = null;
  try {
    g.device.engine.free();
  } catch {
    // Already freed: nothing to release.
  }
  const note = `the GPU device failed (${why}); the tissue goes on on the CPU engine from step ${g.tissue.sim.step_count()}`;
  state = { kind: 'cpu', tissue: g.tissue, note };
  pace.steps = pace.ms = 0;
  view.changed = true;
  post({ type: 'engine', stats: stats(), lost: note });
}

/** @param {GpuEngineState} g */
const queued = (g) => g.flight.reduce((n, f) => n + f.k, 0);

// gpu (level | stale) → gpu (ahead): uploads a stale tissue, then submits GPU steps while fewer
// than the engine's limit are under way, up to `limit` steps under way in all, `batch` at most
// in one (each ends at the next row of readouts at the latest; one that ends on a row, or
// follows a request for a frame, queues the download of the state it ends at), then settles the
// oldest. Returns its steps, 0 if they were put back to be taken again (with more solve
// iterations or storage, and the submissions after it with them), or null if the model failed
// (the state before the submission, in `tissue.sim` too; the page told).
/** @param {GpuEngineState} g @param {number} limit @param {number} batch */
async function gpuAdvance(g, limit, batch) {
  const engine = g.device.engine;
  if (g.sync === 'stale') {
    engine.upload(g.tissue.sim);
    g.sync = 'level';
  }
  while (g.flight.length < engine.in_flight_max()) {
    const want = Math.min(limit - queued(g), batch);
    if (want < 1) break;
    const toRow = g.tissue.sim.steps_to_next_row(engine.submitted_to());
    const k = engine.submit(Math.min(want, toRow));
    if (k === 0) break;
    const down = k === toRow || view.request ? /** @type {Promise<GpuState>} */ (engine.download()) : null;
    // A download dropped with its submission (put back, or the device lost) is never awaited.
    down?.catch(() => {});
    g.flight.push({ k, down });
    g.sync = 'ahead';
  }
  return gpuSettle(g);
}

// Settles the oldest GPU submission under way (gpuAdvance); a download queued behind it is
// taken by `tissue.sim` (a row of readouts, a frame sent if one is asked for): gpu (ahead) →
// gpu (level) when it was the last under way.
/** @param {GpuEngineState} g @returns {Promise<number | null>} */
async function gpuSettle(g) {
  const f = g.flight.shift();
  if (!f) return 0;
  let taken;
  try {
    taken = await g.device.engine.check();
  } catch (e) {
    g.flight = [];
    if (gpuFailed(g)) return 0;
    pace.playing = false;
    g.sync = 'ahead';
    await gpuDown();
    post({ type: 'stopped', why: messageOf(e), active: g.tissue.sim.active() });
    return null;
  }
  if (!taken) {
    g.flight = [];
    return 0;
  }
  if (f.down) {
    try {
      g.tissue.sim.adopt(await f.down);
    } catch (e) {
      if (gpuFailed(g)) return 0;
      throw e;
    }
    g.sync = g.flight.length > 0 ? 'ahead' : 'level';
    view.changed = true;
    if (view.request) sendFrame();
  }
  return f.k;
}

// One turn of the GPU engine: a submission while playing, then a frame if one is asked for.
async function gpuTurn() {
  const g = gpuState();
  if (!g) return;
  try {
    if (pace.playing) {
      refill();
      if (pace.budget >= 1 || g.flight.length) {
        const t0 = performance.now();
        const k = await gpuAdvance(g, Math.floor(pace.budget), Math.max(1, Math.floor(GPU_BATCH_MS / pace.msPerStep)));
        if (k === null || state !== g) return;
        if (k) {
          const ms = performance.now() - t0;
          pace.msPerStep = 0.8 * pace.msPerStep + 0.2 * (ms / k);
          timed(k, ms);
          pace.budget -= k;
          view.changed = true;
        }
      } else {
        await new Promise((r) => setTimeout(r, 1000 / (30 * pace.spf)));
      }
    }
    // Paused, or a frame asked for with nothing under way: level with the GPU, then draw
    // (while playing, a frame comes with the next download).
    if (!pace.playing || (view.request && !g.flight.length)) await gpuDown();
    if (view.request && gpuState()?.sync !== 'ahead') sendFrame();
  } catch (e) {
    if (!(state === g && gpuFailed(g))) fatal(e);
  }
}

// --- what the page is sent ---------------------------------------------------------------------

// How many marks a view made (the core's objects freed).
/** @param {{ free(): void }[]} marks */
function count(marks) {
  for (const m of marks) m.free();
  return marks.length;
}

// The ±½ defects a view marked, as plain data: where, twice the charge, a +½'s orientation
// (NaN for a −½).
/** @param {DefectMark[]} marks */
function defectsOf(marks) {
  return marks.map((d) => {
    const out = { x: d.x, y: d.y, twiceCharge: d.twice_charge, orientation: d.orientation };
    d.free();
    return out;
  });
}

// The spiral cores a view marked, as plain data: where, and ∇·v there.
/** @param {SpiralMark[]} marks */
function spiralCoresOf(marks) {
  return marks.map((p) => {
    const out = { x: p.x, y: p.y, divergence: p.divergence };
    p.free();
    return out;
  });
}

// A binding's readout as plain data (its wasm object freed).
/** @param {Readout} r */
function readoutOf(r) {
  const out = {
    step: r.step, time: r.active_time, holes: r.holes, area: r.void_area, packing: r.packing, active: r.active,
    zeta: r.zeta, chi: r.chi, gamma: r.gamma, cells: r.cells, l: r.box_size, relaxSteps: r.relax_steps,
    timeUnitSeconds: r.time_unit_seconds,
  };
  r.free();
  return out;
}

// Where the live tissue `s` rewinds to, or null (src/web/history.rs).
/** @param {WebSim} s @returns {Rewind | null} */
function rewindOf(s) {
  const p = s.rewind_point();
  if (!p) return null;
  const out = { from: p.from, holeStep: p.hole_step, holeX: p.hole_x, holeY: p.hole_y };
  p.free();
  return out;
}

// A replay's watch, or null for a live tissue.
/** @param {WebSim} s @returns {Replay | null} */
function replayOf(s) {
  const w = s.replay_watch();
  if (!w) return null;
  const V = core().ReplayVerdict;
  const verdict = w.verdict === V.Tore ? 'tore' : w.verdict === V.Held ? 'held' : 'watching';
  const out = {
    from: w.from, savedFingerprint: w.saved_fingerprint, holeStep: w.hole_step, holeX: w.hole_x, holeY: w.hole_y,
    until: w.until, radius: w.radius, verdict, tearStep: w.tear_step ?? null,
  };
  w.free();
  return /** @type {Replay} */ (out);
}

/** @returns {Stats} */
function stats() {
  const s = state;
  const base = {
    msPerStep: pace.msPerStep,
    stepsPerSecond: pace.steps > 0 && pace.ms > 0 ? (1000 * pace.steps) / pace.ms : null,
    threads: core().coreThreads(),
    coreNote: loaded.coreNote,
  };
  if (s.kind === 'frames') {
    const r = s.playback.p.readout();
    const read = r ? readoutOf(r) : {
      step: 0, time: 0, holes: 0, area: 0, packing: 0, active: false, zeta: 0, chi: 0, gamma: 0, cells: 0, l: 0,
      relaxSteps: 0, timeUnitSeconds: 1,
    };
    return {
      ...read, ...base, startedFrom: 'frames', startedAt: 0, engine: 'none', engineNote: '', solveIterations: null,
      rewind: null, replay: null, frame: s.playback.index, frames: s.playback.frames.length,
    };
  }
  if (s.kind === 'none') throw new Error('there is no tissue yet');
  const t = s.tissue;
  return {
    ...readoutOf(t.sim.readout()),
    ...base,
    startedFrom: t.startedFrom,
    startedAt: t.startedAt,
    // Which engine steps, and why (main.js, showEngine).
    engine: s.kind,
    engineNote: s.note,
    solveIterations: s.kind === 'gpu' ? s.device.engine.solve_iterations() : null,
    rewind: t.live ? null : rewindOf(t.sim),
    replay: replayOf(t.sim),
    frame: null,
    frames: null,
  };
}

function sendFrame() {
  const req = view.request;
  const s = state;
  if (!req || s.kind === 'none') return;
  const { field, dpr } = req;
  if (!view.changed && field === view.lastField && dpr === view.lastDpr) return;
  view.request = null;
  view.changed = false;
  view.lastField = field;
  view.lastDpr = dpr;
  const source = s.kind === 'frames' ? s.playback.p : s.tissue.sim;
  const v = source.view(field, dpr);
  /** @type {FrameParts} */
  const parts = { l: v.l(), kind: v.kind(), tissue: v.tissue(), field: v.field(), segments: v.segments(), range: v.range() };
  v.free();
  // The spiral cores this view marks (the guided tour waits for one in the flow).
  const cores = count(source.spiral_cores());
  post({ type: 'frame', parts, stats: stats(), cores }, [parts.tissue.buffer, parts.field.buffer, parts.segments.buffer]);
}

// --- the calls ------------------------------------------------------------------------------

// The model parameters the sliders set, each by its own setter.
const SETTERS = {
  /** @param {WebSim} s @param {number} v */ zeta: (s, v) => s.set_zeta(v),
  /** @param {WebSim} s @param {number} v */ chi: (s, v) => s.set_chi(v),
  /** @param {WebSim} s @param {number} v */ gamma: (s, v) => s.set_gamma(v),
};

// cpu / gpu (level) → the same, an edit made: gpu (stale), uploaded before the next step.
/** @template T @param {T} value @returns {T} */
function edited(value) {
  const g = gpuState();
  if (g) g.sync = 'stale';
  view.changed = true;
  return value;
}

// cpu / gpu (live or replay) → the same (replay): a replay of the live tissue's last hole, from
// the saved state before it, with activity ζ × `factor` (0: off, ½: halved). The live tissue
// is set aside as it is; a replay shown before is dropped. Returns the replay's start as the
// core reads it right after the rewind: its step, fingerprint and ζ, and what it watches for.
/** @param {number} factor */
function toReplay(factor) {
  const t = tissueOf();
  if (!t) throw new Error("What if? rewinds a live tissue, and a run's frames are shown");
  const live = t.live ?? t.sim;
  const replay = live.rewind();
  try {
    // The experiment's arms scale the ζ the tissue had when the state was saved.
    SETTERS.zeta(replay, readoutOf(replay.readout()).zeta * factor);
  } catch (e) {
    replay.free();
    throw e;
  }
  if (t.live) t.sim.free();
  t.live = live;
  t.sim = replay;
  edited(null);
  const watch = /** @type {Replay} */ (replayOf(replay));
  return { ...watch, step: replay.step_count(), fingerprint: replay.fingerprint(), zeta: readoutOf(replay.readout()).zeta, factor };
}

// cpu / gpu (replay) → the same (live): the replay freed, the live tissue back as it was left.
// Returns its model parameters (null: no replay was shown).
function toLive() {
  const t = tissueOf();
  if (!t?.live) return null;
  t.sim.free();
  t.sim = t.live;
  t.live = null;
  edited(null);
  const r = readoutOf(t.sim.readout());
  return { zeta: r.zeta, chi: r.chi, gamma: r.gamma, step: r.step };
}

// Frees whatever the state holds: any state → none.
function drop() {
  const s = state;
  state = { kind: 'none' };
  if (s.kind === 'frames') s.playback.p.free();
  if (s.kind === 'cpu' || s.kind === 'gpu') {
    s.tissue.sim.free();
    s.tissue.live?.free();
  }
}

// What the page and the tests may ask of the simulation, beyond stepping. Each runs as a turn,
// the tissue level with the GPU engine first (handle, 'call').
export const CALLS = {
  // Steps n now and returns the milliseconds it took (null: the model failed, the page told).
  // On the GPU engine, if the device fails part way, the rest are taken on the CPU engine
  // from the last state handed over.
  /** @param {number} n */
  step: async (n) => {
    const t0 = performance.now();
    let left = n;
    for (let g = gpuState(); g && left > 0; g = gpuState()) {
      const k = await gpuAdvance(g, left, left);
      if (k === null) return null;
      left -= k;
    }
    if (gpuState()) await gpuDown();
    if (left > 0 && !takeSteps(sim(), left)) return null;
    const ms = performance.now() - t0;
    timed(n, ms);
    return ms;
  },
  // `auto`'s timed trial on the GPU engine in use (the tests drive it on a software adapter,
  // where `auto` does not try): ms per step of each engine; the tissue does not move.
  /** @param {number} steps */
  engine_trial: async (steps) => {
    const g = gpuState();
    if (!g) return null;
    return engineTrial(g.tissue.sim, g.device, steps);
  },
  // Destroys the GPU engine's device, as a driver reset would (the browser tests' forced loss).
  gpu_destroy: () => gpuState()?.device.engine.destroy_device(),
  // The CPU core's own milliseconds per step, without the readouts: the fastest of `batches`
  // batches of n steps of a copy of the tissue (the tests' wasm/native report). The tissue shown
  // does not move.
  /** @param {number} n @param {number} batches */
  core_ms_per_step: (n, batches) => {
    const copy = sim().core_copy();
    try {
      let best = Infinity;
      for (let b = 0; b < batches; b++) {
        const t0 = performance.now();
        copy.step(n);
        best = Math.min(best, (performance.now() - t0) / n);
      }
      return best;
    } finally {
      copy.free();
    }
  },
  /** @param {keyof SETTERS} name @param {number} value */
  set_param: (name, value) => edited(SETTERS[name](sim(), value)),
  /** @param {number} x @param {number} y @param {number} radius @param {number} multiplier */
  paint_substrate: (x, y, radius, multiplier) => edited(sim().paint_substrate(x, y, radius, multiplier)),
  /** @param {number} x @param {number} y */
  remove_cell_at: (x, y) => edited(sim().remove_cell_at(x, y)),
  /** @param {number} x @param {number} y */
  substrate_at: (x, y) => sim().substrate_at(x, y),
  /** @param {number} x @param {number} y */
  cell_at: (x, y) => sim().cell_at(x, y),
  n_cells: () => sim().n_cells(),
  box_size: () => sim().box_size(),
  fingerprint: () => sim().fingerprint(),
  phi_sum: () => sim().phi_sum(),
  /** @param {FieldKind} kind */
  field_values: (kind) => sim().field_values(kind),
  evaluate: () => sim().evaluate(),
  // The ±½ defects and spiral cores that the view of `kind` marks (counts), built now.
  /** @param {FieldKind} kind */
  marks: (kind) => {
    const s = sim();
    s.field_values(kind);
    return { defects: count(s.defects()), spiralCores: count(s.spiral_cores()) };
  },
  defects: () => defectsOf((state.kind === 'frames' ? state.playback.p : sim()).defects()),
  spiral_cores: () => spiralCoresOf((state.kind === 'frames' ? state.playback.p : sim()).spiral_cores()),
  stats: () => stats(),
  // The Download button: the readouts since the tissue was made (CSV), the current state as a
  // native frame file and a run.json that makes a run of it for `monolayer analyze`.
  download: () => {
    const t = tissueOf();
    if (!t) throw new Error("this takes data out of the live simulation, and a run's frames are shown (Reset returns to it)");
    const s = t.sim;
    return { csv: s.readouts_csv(), npz: s.frame_npz(), frameName: s.frame_name(), runJson: s.run_json(), step: s.step_count() };
  },
  readout_rows: () => sim().readout_rows(),
  // The live tissue's saved states ("What if?"): their steps, fingerprints when saved and sizes.
  saved_states: () => {
    const t = tissueOf();
    const s = t ? (t.live ?? t.sim) : null;
    return (s?.saved_states() ?? []).map((x) => {
      const out = { step: x.step, fingerprint: x.fingerprint, bytes: x.bytes };
      x.free();
      return out;
    });
  },
  // "What if?": a replay of the last hole with activity × factor, and back to the live tissue.
  /** @param {number} factor */
  what_if: (factor) => toReplay(factor),
  back_to_live: () => toLive(),
  // A run's frames: `files` (File objects the page was given) replace the live simulation.
  /** @param {File[]} files */
  open: (files) => openRun(files),
  /** @param {number} index */
  show: (index) => showFrame(index),
};
/** @typedef {typeof CALLS} Calls */
/** @typedef {keyof Calls} CallName */

const FRAME_NAME = /^frame_\d+\.npz$/;
// A run directory's other files (its checkpoints, lock, and the tables and plots of `analyze`):
// skipped without a word when a whole directory is opened.
const RUN_FILES = /^(checkpoint\.npz|last_good_state\.npz|\..*|.*\.(csv|png|svg|md|txt|webm))$/;

// cpu / gpu / frames → frames: opens the files of a run (its run.json and frame_*.npz; a
// directory's other files are ignored): every frame is read and checked on its own, so that a
// bad one is reported, naming the file, and skipped. Returns { frames: [{ name, step }], errors,
// seed, runVersion, hasRecord } or { error, errors } when nothing can be shown (the live
// simulation then carries on).
/** @param {File[]} files */
async function openRun(files) {
  /** @type {string[]} */
  const errors = [];
  const records = files.filter((f) => f.name === 'run.json');
  const frames = files.filter((f) => FRAME_NAME.test(f.name)).sort((a, b) => (a.name < b.name ? -1 : 1));
  for (const f of files) {
    if (!records.includes(f) && !frames.includes(f) && !RUN_FILES.test(f.name)) {
      errors.push(`${f.name}: not a frame (frame_<step>.npz) or run.json: ignored`);
    }
  }
  if (records.length > 1) errors.push(`${records.length} files named run.json: using the first`);
  let p;
  try {
    const Playback = core().WebPlayback;
    p = records.length ? new Playback('run.json', await records[0].text()) : new Playback('', '');
  } catch (e) {
    return { error: messageOf(e), errors };
  }
  if (!records.length) errors.push('no run.json: the frames are shown with the default parameters (R, ζ, Δt) at their own size');
  /** @type {RunFrame[]} */
  const good = [];
  for (const file of frames) {
    try {
      const step = p.check(file.name, new Uint8Array(await file.arrayBuffer()));
      if (good.some((g) => g.step === step)) errors.push(`${file.name}: step ${step} again: skipped`);
      else good.push({ name: file.name, step, file });
    } catch (e) {
      errors.push(messageOf(e));
    }
  }
  if (!good.length) {
    p.free();
    return { error: frames.length ? 'none of the frames could be read' : 'no frame_<step>.npz among the files', errors };
  }
  good.sort((a, b) => a.step - b.step);
  pace.playing = false;
  drop();
  state = { kind: 'frames', playback: { p, frames: good, index: -1 } };
  const first = await showFrame(0);
  return {
    frames: good.map(({ name, step }) => ({ name, step })), errors: first.error ? [...errors, first.error] : errors,
    seed: p.seed(), runVersion: p.run_version(), hasRecord: p.has_record(),
  };
}

// Shows frame `index` of the run opened: { step } or { error } (naming the file).
/** @param {number} index @returns {Promise<{ index: number, step: number, error?: string }>} */
async function showFrame(index) {
  if (state.kind !== 'frames') throw new Error("no run's frames are open");
  const playback = state.playback;
  const f = playback.frames[index];
  try {
    playback.p.show(f.name, new Uint8Array(await f.file.arrayBuffer()));
  } catch (e) {
    return { index, step: f.step, error: messageOf(e) };
  }
  playback.index = index;
  view.changed = true;
  return { index, step: f.step };
}

// any → none → cpu (→ gpu): a new tissue (the 'new' message), from a shipped state where one
// fits, else from random disks; then the engine that steps it.
/** @param {NewTissue} m */
async function newTissue(m) {
  await loadCore(m);
  drop();
  const { size, params: p, seed } = m;
  /** @type {[number, number, number, number, number, number, number]} */
  const args = [size.box, size.cells, size.relaxSteps, p.zeta, p.chi, p.gamma, seed];
  const c = core();
  /** @type {WebSim | null} */
  let s = null;
  /** @type {'snapshot' | 'disks'} */
  let startedFrom = 'snapshot';
  if (m.shipped) {
    try {
      stage('fetching the shipped state');
      const res = await fetch(m.shipped);
      if (!res.ok) throw new Error(`HTTP ${res.status}`);
      s = c.WebSim.from_snapshot(new Uint8Array(await res.arrayBuffer()), ...args);
    } catch (err) {
      // Not fatal: the same tissue comes from relaxing here, only later.
      console.warn(`relaxing live: the shipped state ${m.shipped} was not usable (${messageOf(err)})`);
    }
  }
  try {
    if (!s) {
      s = new c.WebSim(...args);
      startedFrom = 'disks';
    }
  } catch (err) {
    post({ type: 'fatal', message: `Could not start the simulation: ${messageOf(err)}` });
    return;
  }
  stage('choosing the engine');
  await chooseEngine({ sim: s, live: null, startedFrom, startedAt: s.step_count() }, m.engine ?? 'auto');
  view.changed = true;
  post({ type: 'ready', stats: stats() });
}

// Messages are handled one after the other, each after the last one's awaits (the core's
// instantiation, a relaxed state's download): a call or a second 'new' never meets a
// half-made simulation.
const inbox = { queue: Promise.resolve() };
scope.onmessage = (/** @type {MessageEvent<WorkerIn>} */ e) => {
  inbox.queue = inbox.queue.then(() => handle(e.data));
};

/** @param {WorkerIn} m */
async function handle(m) {
  try {
    if (m.type === 'new') {
      await inTurn(() => newTissue(m));
    } else if (m.type === 'engine') {
      // cpu / gpu → cpu (→ gpu): another engine for the same tissue, from the state it has now.
      await inTurn(async () => {
        if (!tissueOf()) return;
        await gpuDown();
        const t = tissueOf();
        if (!t) return;
        await chooseEngine(t, m.engine);
        pace.steps = pace.ms = 0;
        view.changed = true;
        post({ type: 'engine', stats: stats() });
      });
    } else if (m.type === 'play') {
      pace.playing = m.on;
    } else if (m.type === 'spf') {
      pace.spf = m.n;
    } else if (m.type === 'frame') {
      view.request = { field: m.field, dpr: m.dpr };
    } else if (m.type === 'call') {
      try {
        // Level with the GPU first: a call reads or edits the tissue as it is now.
        const value = await inTurn(async () => {
          await gpuDown();
          const fn = /** @type {(...a: unknown[]) => unknown} */ (CALLS[m.method]);
          return fn(...(m.args ?? []));
        });
        view.changed = true; // cheap to assume: a call may have edited the tissue
        post({ type: 'result', id: m.id, value });
      } catch (err) {
        if (err instanceof WebAssembly.RuntimeError) throw err;
        post({ type: 'result', id: m.id, error: messageOf(err) });
      }
    }
    schedule();
  } catch (err) {
    fatal(err);
  }
}
